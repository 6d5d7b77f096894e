"""Wiring a Subject: observers for invoke numbers, record listeners, step listeners, watchers.

Each hook hears what it asked for and no more (:mod:`statectl.run.runtime.hooks`);
attaching one only records it, and drops what the plan path had worked out for
the old wiring, so a plan's calls are rebuilt for the new one when next taken.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from statectl.front.observers import Observer
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart, Invoke
from statectl.kernel.semantics import Machine
from statectl.run.runtime.hooks import ApiLogging, Listener, StateWatcher, StepListener
from statectl.run.runtime.worker import Worker

__all__ = ["Wiring"]


def _describe_invoke(i: Invoke) -> str:
    return f"#{i.number} {i.name} ({i.method}())"


class Wiring(Worker):
    """The Subject's wiring half; the slots it writes live here, the rest on the Subject."""

    __slots__ = ("_listeners", "_steppers", "_watchers")

    _listeners: tuple[Listener, ...]
    _steppers: tuple[StepListener, ...]
    _watchers: tuple[StateWatcher, ...]
    chart: Chart
    machine: Machine

    def attach(self, observer: Observer, invokes: Iterable[int] | None = None) -> None:
        """Register ``observer`` for these invoke numbers (default: every invoke of the chart)."""
        by_number = {i.number: i for i in self.chart.invokes}
        numbers = tuple(by_number) if invokes is None else tuple(invokes)
        available = ", ".join(_describe_invoke(i) for i in by_number.values()) or "none"
        unknown = [n for n in numbers if n not in by_number]
        if unknown:
            raise StatectlError(
                f"{self._name}: no invoke number {unknown} in chart {self.chart.name!r} "
                f"(available: {available})"
            )
        routes = self._routes
        taken = [n for n in numbers if n in routes and routes[n][0] is not observer]
        if taken:
            holders = ", ".join(f"#{n} by {type(routes[n][0]).__name__}" for n in taken)
            raise StatectlError(
                f"{self._name}: invoke numbers already claimed ({holders}); a notification "
                "goes to exactly one observer, so attach each number once"
            )
        logging = isinstance(observer, ApiLogging)
        for n in numbers:
            routes[n] = (observer, logging)
        self._calls = None

    def observer_for(self, invoke: int) -> Observer | None:
        route = self._routes.get(invoke)
        return route[0] if route is not None else None

    def listen(self, callback: Listener) -> Callable[[], None]:
        """Receive every record from now on; returns a function that stops it."""
        self._listeners = (*self._listeners, callback)

        def unlisten() -> None:
            listeners = self._listeners
            if callback in listeners:
                at = listeners.index(callback)
                self._listeners = listeners[:at] + listeners[at + 1 :]

        return unlisten

    def on_step(self, callback: StepListener) -> Callable[[], None]:
        """Hear ``(event, data, outcome)`` on the owner after each event; returns the undo.

        Unlike :meth:`listen` it builds no records (rule 4). The outcome is
        ``handled`` or the reason the event changed nothing.
        """
        self._steppers = (*self._steppers, callback)

        def off() -> None:
            self._steppers = tuple(c for c in self._steppers if c is not callback)

        return off

    def watch(self, states: Iterable[str], watcher: StateWatcher) -> Callable[[], None]:
        """Tell ``watcher`` when one of ``states`` is entered or exited; returns the undo.

        Only the plans that enter or exit a watched state pay for it (rule 4).
        Watch before :meth:`start` to hear the initial states entered.
        """
        names = tuple(dict.fromkeys(states))
        unknown = [n for n in names if n not in self.machine.order]
        if unknown:
            raise StatectlError(f"{self._name}: no state {unknown} in chart {self.chart.name!r}")
        for n in names:
            self._watch[n] = (*self._watch.get(n, ()), watcher)
        self._watchers = (*self._watchers, watcher)
        self._calls = None

        def off() -> None:
            for n in names:
                left = tuple(w for w in self._watch.get(n, ()) if w is not watcher)
                if left:
                    self._watch[n] = left
                else:
                    self._watch.pop(n, None)
            self._watchers = tuple(w for w in self._watchers if w is not watcher)
            self._calls = None

        return off

    @property
    def listening(self) -> bool:
        """Whether anyone receives records (build one only then)."""
        return bool(self._listeners or self._recorders)
