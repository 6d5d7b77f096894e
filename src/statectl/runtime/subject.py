"""The Subject: one running device, the owner of its configuration and its event queue.

Rules:
1. One owner processes a device's events, run-to-completion, in the order they
   were posted, one at a time. Any thread may :meth:`Subject.post` without
   blocking; the owner is whoever calls :meth:`Subject.run_until_idle` (or the
   worker thread of :meth:`Subject.start_worker`), never two at once.
2. What an event does is decided by :func:`statectl.semantics.step`, which is
   pure; the Subject performs the decision: it commits the new snapshot, emits
   the records, and for each ``Notify`` calls the one observer registered for
   that invoke number (the paper's specific notification).
3. An event that changes nothing is never lost silently. The reason is one of
   ``declared ignored`` (the state table says so), ``guard false`` (a transition
   existed but its guard did not hold), ``no transition`` or ``unknown event``.
   Declared-ignored events are always just recorded; the others are recorded as
   ``EventIgnored`` under policy ``ignore`` and as ``EventRejected`` plus an
   :class:`~statectl.errors.UnhandledEventError` under policy ``error`` (raised
   from ``run_until_idle``; a worker hands it to its error callback and goes on).
4. Records are built only when someone listens; a record emitted while
   listeners run (a monitor starting on ``StateEntered``) is delivered after the
   current one, so every listener sees one order.
5. Work that must run on the owner (a monitor's poll) is queued with
   :meth:`Subject.call_soon`, so records are only ever emitted by the owner.
"""

from __future__ import annotations

import sys
import threading
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol, cast, runtime_checkable

from statectl.errors import StatectlError, UnhandledEventError
from statectl.expr import compile_expression
from statectl.model import Chart, Invoke, Notify
from statectl.observers import Notification, Observer
from statectl.runtime.clock import Clock, SimClock
from statectl.runtime.records import (
    ApiCall,
    EventIgnored,
    EventReceived,
    EventRejected,
    Finished,
    IgnoreReason,
    InvokeIssued,
    ObserverCalled,
    Record,
    Started,
    StateEntered,
    StateExited,
    TransitionTaken,
)
from statectl.semantics import Machine, Snapshot, Step, initial, step

__all__ = ["ApiLogging", "Listener", "Policy", "Subject"]

Policy = Literal["ignore", "error"]
Listener = Callable[[Record], None]
ErrorHandler = Callable[[BaseException], None]


@runtime_checkable
class ApiLogging(Protocol):
    """An observer that logs the device API calls it makes (every driver does)."""

    @property
    def api_log(self) -> Sequence[ApiCall]: ...


@dataclass(frozen=True, slots=True)
class _Item:
    """A queued event, or a callable to run on the owner (``event`` is then ``None``)."""

    event: str | None
    data: Any = None
    fn: Callable[[], object] | None = None


def _print_error(exc: BaseException) -> None:
    traceback.print_exception(exc, file=sys.stderr)


def _describe_invoke(i: Invoke) -> str:
    return f"#{i.number} {i.name} ({i.method}())"


class Subject:
    """A device's chart running on a clock; observers get the notifications meant for them."""

    def __init__(
        self,
        chart: Chart,
        *,
        clock: Clock,
        name: str | None = None,
        policy: Policy = "ignore",
        data: Mapping[str, Any] | None = None,
    ) -> None:
        if policy not in ("ignore", "error"):
            raise StatectlError(f"policy must be 'ignore' or 'error' (got {policy!r})")
        self.chart = chart
        self.machine = Machine(chart)
        self.clock = clock
        self.name = name or chart.name
        self.policy: Policy = policy
        self._data: dict[str, Any] = self._initial_data(chart, data or {})
        self._known = frozenset(chart.event_names)
        self._invokes: dict[int, Invoke] = {i.number: i for i in chart.invokes}
        self._routes: dict[int, Observer] = {}
        self._logging: dict[int, bool] = {}  # observer keeps an api_log (checked once)
        self._listeners: list[Listener] = []
        self._pending: deque[Record] = deque()
        self._emitting = False
        self._queue: deque[_Item] = deque()
        self._wake = threading.Event()
        self._snapshot: Snapshot | None = None
        self._busy = False
        self._finished = False
        self._closed = False
        self._stopping = False
        self._serving = False
        self._worker: threading.Thread | None = None
        self.events_processed = 0
        self.invokes_issued = 0

    @staticmethod
    def _initial_data(chart: Chart, given: Mapping[str, Any]) -> dict[str, Any]:
        """The chart's data items in order, each evaluated over the earlier ones."""
        data = dict(given)
        for item in chart.data:
            if item.name in data:
                continue
            value = None
            if item.expr:
                expr, diags = compile_expression(item.expr, item.origin)
                if expr is None:
                    raise StatectlError("; ".join(str(d) for d in diags))
                value = expr.evaluate(data)
            data[item.name] = value
        return data

    # -- wiring ----------------------------------------------------------------------------

    def attach(self, observer: Observer, invokes: Iterable[int] | None = None) -> None:
        """Register ``observer`` for these invoke numbers (default: every invoke of the chart)."""
        numbers = tuple(self._invokes) if invokes is None else tuple(invokes)
        available = ", ".join(_describe_invoke(i) for i in self._invokes.values()) or "none"
        unknown = [n for n in numbers if n not in self._invokes]
        if unknown:
            raise StatectlError(
                f"{self.name}: no invoke number {unknown} in chart {self.chart.name!r} "
                f"(available: {available})"
            )
        taken = [n for n in numbers if n in self._routes and self._routes[n] is not observer]
        if taken:
            holders = ", ".join(f"#{n} by {type(self._routes[n]).__name__}" for n in taken)
            raise StatectlError(
                f"{self.name}: invoke numbers already claimed ({holders}); a notification "
                "goes to exactly one observer, so attach each number once"
            )
        logging = isinstance(observer, ApiLogging)
        for n in numbers:
            self._routes[n] = observer
            self._logging[n] = logging

    def observer_for(self, invoke: int) -> Observer | None:
        return self._routes.get(invoke)

    def listen(self, callback: Listener) -> Callable[[], None]:
        """Receive every record from now on; returns a function that stops it."""
        self._listeners.append(callback)

        def unlisten() -> None:
            if callback in self._listeners:
                self._listeners.remove(callback)

        return unlisten

    def emit(self, record: Record) -> None:
        """Deliver ``record`` to every listener, after any record being delivered now."""
        self._pending.append(record)
        if self._emitting:
            return
        self._emitting = True
        try:
            while self._pending:
                r = self._pending.popleft()
                for callback in tuple(self._listeners):
                    callback(r)
        except BaseException:
            self._pending.clear()
            raise
        finally:
            self._emitting = False

    # -- state -----------------------------------------------------------------------------

    @property
    def configuration(self) -> frozenset[str]:
        """The active states (empty before :meth:`start`)."""
        return self._snapshot.active if self._snapshot is not None else frozenset()

    @property
    def snapshot(self) -> Snapshot | None:
        return self._snapshot

    @property
    def data(self) -> Mapping[str, Any]:
        return self._data

    @property
    def started(self) -> bool:
        return self._snapshot is not None

    @property
    def finished(self) -> bool:
        return self._finished

    @property
    def queued(self) -> int:
        return len(self._queue)

    # -- posting (any thread) ----------------------------------------------------------------

    def post(self, event: str, data: Any = None) -> None:
        """Queue ``event`` for the owner; never blocks, safe from any thread."""
        if not isinstance(event, str):
            raise StatectlError(f"an event name must be a str (got {event!r})")
        if self._closed:
            raise StatectlError(f"{self.name} is closed; event {event!r} cannot be posted")
        self._queue.append(_Item(event, data))
        self._wake.set()

    def call_soon(self, fn: Callable[[], object]) -> None:
        """Run ``fn`` on the owner, in queue order with the events (monitors use this)."""
        if self._closed:
            return
        self._queue.append(_Item(None, None, fn))
        self._wake.set()

    # -- owning (one thread) -----------------------------------------------------------------

    def start(self) -> None:
        """Enter the initial configuration (records ``Started`` and the entered states)."""
        if self._snapshot is not None:
            raise StatectlError(f"{self.name} was started already")
        self._check_owner()
        now = self.clock.now()
        listening = bool(self._listeners)
        if listening:
            self.emit(Started(self.name, now))
        first = initial(self.machine, self._data)
        self._snapshot = first.target
        self._perform(first, None, now, listening)

    def run_until_idle(self) -> int:
        """Process queued events until the queue is empty; returns how many events ran."""
        self._check_owner()
        if self._snapshot is None:
            raise StatectlError(f"{self.name}: call start() before processing events")
        if self._busy:
            raise StatectlError(
                f"{self.name}: run_until_idle() called while an event is being processed "
                "(from an observer or listener?); post() the event instead"
            )
        count = 0
        self._busy = True
        try:
            while self._queue and not self._stopping:
                item = self._queue.popleft()
                if item.fn is not None:
                    item.fn()
                    continue
                assert item.event is not None
                count += 1
                self._process(item.event, item.data)
        finally:
            self._busy = False
        return count

    def advance(self, seconds: float) -> int:
        """On a :class:`SimClock`: move time on, draining the queue after every timer."""
        if not isinstance(self.clock, SimClock):
            raise StatectlError("advance() needs a SimClock; a WallClock moves by itself")
        count = self.run_until_idle()
        self.clock.advance(seconds, settle=self.run_until_idle)
        return count + self.run_until_idle()

    def serve_forever(self, on_error: ErrorHandler = _print_error) -> None:
        """Be the owner on this thread until :meth:`stop`; errors go to ``on_error``."""
        if self._snapshot is None:
            self.start()
        self._serving = True
        try:
            while not self._stopping:
                self._wake.wait()
                self._wake.clear()
                while self._queue and not self._stopping:
                    try:
                        self.run_until_idle()
                    except Exception as exc:  # record + callback; a worker never dies of an event
                        on_error(exc)
        finally:
            self._serving = False
            self._stopping = False

    def start_worker(self, on_error: ErrorHandler = _print_error) -> threading.Thread:
        """Run :meth:`serve_forever` on a daemon thread, which becomes the owner."""
        if self._worker is not None:
            raise StatectlError(f"{self.name} has a worker already")
        self._serving = True  # so a stop() before the thread runs is not lost
        self._worker = threading.Thread(
            target=self.serve_forever, args=(on_error,), name=f"statectl-{self.name}", daemon=True
        )
        self._worker.start()
        return self._worker

    def stop(self, timeout: float | None = 1.0) -> None:
        """Stop the owner loop after the event in progress; queued events stay queued."""
        if self._serving:
            self._stopping = True
            self._wake.set()
        worker = self._worker
        if worker is not None and worker is not threading.current_thread():
            worker.join(timeout)
        self._worker = None

    def close(self) -> None:
        """Stop the owner, record ``Finished``; later posts are refused."""
        if self._closed:
            return
        self.stop()
        self._closed = True
        if not self._finished:
            self._finished = True
            if self._listeners:
                self.emit(Finished(self.name, self.clock.now()))

    def _check_owner(self) -> None:
        worker = self._worker
        if worker is not None and worker.is_alive() and worker is not threading.current_thread():
            raise StatectlError(
                f"{self.name} is owned by its worker thread; post() events instead of "
                "processing them here"
            )

    # -- one event -------------------------------------------------------------------------

    def _process(self, event: str, data: Any) -> None:
        snapshot = self._snapshot
        assert snapshot is not None
        self.events_processed += 1
        now = self.clock.now()
        listening = bool(self._listeners)
        if listening:
            self.emit(EventReceived(self.name, now, event, data))
        if event not in self._known:
            self._unhandled(event, "unknown event", now, snapshot)
            return
        decision = step(self.machine, snapshot, event, self._data, data)
        if not decision.handled:
            if decision.ignored:
                reason: IgnoreReason = "declared ignored"
            elif any(
                self.machine.candidates(s, event)
                for s in snapshot.active
                if self.machine.is_atomic(s)
            ):
                reason = "guard false"
            else:
                reason = "no transition"
            self._unhandled(event, reason, now, snapshot)
            return
        self._snapshot = decision.target
        self._perform(decision, data, now, listening)

    def _unhandled(self, event: str, reason: IgnoreReason, now: float, snap: Snapshot) -> None:
        if self.policy == "ignore" or reason == "declared ignored":
            if self._listeners:
                self.emit(EventIgnored(self.name, now, event, reason))
            return
        active = ", ".join(sorted(snap.active))
        if self._listeners:
            self.emit(EventRejected(self.name, now, event, reason))
        raise UnhandledEventError(
            f"{self.name}: event {event!r} is not handled in [{active}] ({reason}); "
            "add a transition or declare it ignored in the state table, or use policy 'ignore'"
        )

    def _perform(self, decision: Step, data: Any, now: float, listening: bool) -> None:
        name = self.name
        for micro in decision.microsteps:
            if listening:
                for s in micro.exited:
                    self.emit(StateExited(name, now, s))
                for t in micro.transitions:
                    self.emit(
                        TransitionTaken(name, now, micro.event, (t.source,), t.targets, t.label)
                    )
                for s in micro.entered:
                    self.emit(StateEntered(name, now, s))
            for action in micro.actions:
                if isinstance(action, Notify):
                    self._notify(action, data, now, listening)
        if decision.final and not self._finished:
            self._finished = True
            if listening:
                self.emit(Finished(name, now))

    def _notify(self, action: Notify, data: Any, now: float, listening: bool) -> None:
        self.invokes_issued += 1
        if listening:
            a = action
            self.emit(InvokeIssued(self.name, now, a.invoke, a.name, a.method, a.event))
        observer = self._routes.get(action.invoke)
        if observer is None:
            return
        log = cast(ApiLogging, observer).api_log if self._logging[action.invoke] else None
        before = len(log) if log is not None else 0
        observer.update(
            Notification(self.name, action.invoke, action.name, action.method, action.event, data)
        )
        if listening:
            if log is None:
                api = f"{type(observer).__name__}.update(#{action.invoke})"
                self.emit(ObserverCalled(self.name, now, action.method, api))
            else:
                for call in log[before:]:
                    self.emit(ObserverCalled(self.name, now, action.method, str(call)))
