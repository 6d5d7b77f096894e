"""What can hook a running device, as types: listeners, step listeners, watchers, loggers.

Each hook hears less than the one before it and costs less (docs/runtime.md, "One
path, and hooks that cost nothing when unused"): a record listener gets every typed
record, a step listener each event's outcome, a :class:`StateWatcher` only the states
it watches. None of them builds a record it did not ask for.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any, Literal, Protocol, cast, runtime_checkable

from statectl.front.observers import Observer
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart, InvokeNumber
from statectl.kernel.semantics import Outcome
from statectl.run.runtime.records import ApiCall, Record, StepRecord

__all__ = [
    "ApiLogging",
    "ErrorHandler",
    "Hooks",
    "Listener",
    "Policy",
    "Route",
    "StateWatcher",
    "StepListener",
    "StepRecordListener",
    "api_calls_since",
    "api_count",
]

Policy = Literal["ignore", "error"]
Listener = Callable[[Record], None]
#: ``(event, data, outcome)`` after an event ran; the outcome is an
#: :class:`~statectl.kernel.semantics.Outcome` (a ``str`` enum: ``"handled"`` or the reason).
StepListener = Callable[[str, Any, Outcome], None]
#: Hears one :class:`StepRecord` per event (and one per record made outside an event).
StepRecordListener = Callable[[StepRecord], None]
ErrorHandler = Callable[[BaseException], None]


class StateWatcher(Protocol):
    """Hears the states it watches entered and exited, and the end of the run; no records.

    A monitor is one: it polls its device only while its state is active. Calls
    come on the owner, inside the step, in the order a trace would show them.
    """

    def entered(self, state: str) -> None: ...
    def exited(self, state: str) -> None: ...
    def finished(self) -> None: ...


@runtime_checkable
class ApiLogging(Protocol):
    """An observer that logs the device API calls it makes (every driver does)."""

    @property
    def api_log(self) -> Sequence[ApiCall]: ...


def api_count(observer: object) -> int:
    """How many API calls ``observer`` (an :class:`ApiLogging`) has made so far."""
    made = getattr(observer, "api_calls", None)
    return made if type(made) is int else len(cast(ApiLogging, observer).api_log)


def api_calls_since(observer: object, before: int) -> Sequence[ApiCall]:
    """The API calls made since :func:`api_count` said ``before``.

    A driver that keeps only its recent calls counts them all in ``api_calls``
    (devices/protocol.py rule 4), so the new ones are the log's last ones.
    """
    since = getattr(observer, "api_since", None)
    if since is not None:  # the driver says it (devices/base.py)
        calls: Sequence[ApiCall] = since(before)
        return calls
    log = cast(ApiLogging, observer).api_log
    made = getattr(observer, "api_calls", None)
    if type(made) is not int:
        return log[before:]
    new = made - before
    return log[max(0, len(log) - new) :] if new > 0 else ()


class Route:
    """The one observer of an invoke number, and whether it logs its API calls."""

    __slots__ = ("logging", "observer")

    def __init__(self, observer: Observer) -> None:
        self.observer = observer
        self.logging = isinstance(observer, ApiLogging)


def _describe_invoke(i: InvokeNumber) -> str:
    return f"#{i.number} {i.name} ({i.method}())"


def _without(hooks: tuple[Any, ...], hook: object) -> tuple[Any, ...]:
    return tuple(h for h in hooks if h is not hook)


class Hooks:
    """Everything wired to one device: observers per invoke number and the sinks of its
    steps. Attaching only records the hook; every change of what a step calls drops the
    programs the engine bound to them (:attr:`bound`), so it binds them again."""

    __slots__ = (
        "bound",
        "chart",
        "device",
        "listeners",
        "recorders",
        "routes",
        "steppers",
        "watch",
        "watchers",
    )

    def __init__(self, chart: Chart, device: str) -> None:
        self.chart = chart
        self.device = device
        self.routes: dict[int, Route] = {}
        self.listeners: tuple[Listener, ...] = ()
        self.recorders: tuple[StepRecordListener, ...] = ()
        self.steppers: tuple[StepListener, ...] = ()
        self.watch: dict[str, tuple[StateWatcher, ...]] = {}  # state -> its watchers
        self.watchers: tuple[StateWatcher, ...] = ()
        #: the engine's programs bound to these hooks (runtime/engine.py), per plan or
        #: program; dropped whenever what a step calls changes
        self.bound: dict[object, Any] = {}

    def changed(self) -> None:
        """What a step calls has changed: bound programs are stale."""
        self.bound.clear()

    def attach(self, observer: Observer, invokes: Iterable[int] | None = None) -> None:
        """Route these invoke numbers (default: every invoke of the chart) to ``observer``."""
        by_number = {i.number: i for i in self.chart.invokes}
        numbers = tuple(by_number) if invokes is None else tuple(invokes)
        available = ", ".join(_describe_invoke(i) for i in by_number.values()) or "none"
        unknown = [n for n in numbers if n not in by_number]
        if unknown:
            raise StatectlError(
                f"{self.device}: no invoke number {unknown} in chart {self.chart.name!r} "
                f"(available: {available})"
            )
        routes = self.routes
        taken = [n for n in numbers if n in routes and routes[n].observer is not observer]
        if taken:
            holders = ", ".join(f"#{n} by {type(routes[n].observer).__name__}" for n in taken)
            raise StatectlError(
                f"{self.device}: invoke numbers already claimed ({holders}); a notification "
                "goes to exactly one observer, so attach each number once"
            )
        route = Route(observer)
        for n in numbers:
            routes[n] = route
        self.changed()

    def listen(self, callback: Listener) -> Callable[[], None]:
        self.listeners = (*self.listeners, callback)
        self.changed()

        def off() -> None:
            listeners = self.listeners
            if callback in listeners:
                at = listeners.index(callback)
                self.listeners = listeners[:at] + listeners[at + 1 :]
                self.changed()

        return off

    def listen_steps(self, callback: StepRecordListener) -> Callable[[], None]:
        self.recorders = (*self.recorders, callback)
        self.changed()

        def off() -> None:
            self.recorders = _without(self.recorders, callback)
            self.changed()

        return off

    def on_step(self, callback: StepListener) -> Callable[[], None]:
        self.steppers = (*self.steppers, callback)

        def off() -> None:
            self.steppers = _without(self.steppers, callback)

        return off

    def add_watcher(self, states: Iterable[str], watcher: StateWatcher) -> Callable[[], None]:
        names = tuple(dict.fromkeys(states))
        for n in names:
            self.watch[n] = (*self.watch.get(n, ()), watcher)
        self.watchers = (*self.watchers, watcher)
        self.changed()

        def off() -> None:
            for n in names:
                left = _without(self.watch.get(n, ()), watcher)
                if left:
                    self.watch[n] = left
                else:
                    self.watch.pop(n, None)
            self.watchers = _without(self.watchers, watcher)
            self.changed()

        return off
