"""The Subject: one running device, the owner of its configuration and its event queue.

Rules:
1. One owner processes a device's events, run-to-completion, in the order they
   were posted, one at a time. Any thread may :meth:`Subject.post` without
   blocking; the owner is whoever calls :meth:`Subject.run_until_idle` (or the
   worker thread of :meth:`Subject.start_worker`), never two at once.
2. What an event does is decided by :func:`statectl.kernel.semantics.step`, which is
   pure; the Subject's :class:`~statectl.run.runtime.engine.Engine` performs the
   decision on one path: the step compiled once into a
   :class:`~statectl.run.runtime.program.Program`, bound to the device's sinks, run by
   :meth:`~statectl.run.runtime.engine.Engine.perform` (watchers, the notifications in
   order, each to the one observer registered for its invoke number, records only
   for listeners).
3. An event that changes nothing is never lost silently. The reason is the
   kernel's :class:`~statectl.kernel.semantics.Outcome`: ``declared ignored`` (the state
   table says so), ``guard false`` (a transition existed but its guard did not
   hold), ``no transition``, or ``unknown event`` (said here, before stepping).
   Declared-ignored events are always just recorded; the others are recorded as
   ``EventIgnored`` under policy ``ignore`` and as ``EventRejected`` plus an
   :class:`~statectl.kernel.errors.UnhandledEventError` under policy ``error`` (raised
   from ``run_until_idle``; a worker hands it to its error callback and goes on).
4. A Subject is made of three parts: its :class:`~statectl.run.runtime.inbox.Inbox`
   (the queue), its :class:`~statectl.run.runtime.hooks.Hooks` (observers, listeners,
   watchers) and its engine; it adds who owns the device and when.
5. Work that must run on the owner (a monitor's poll) is queued with
   :meth:`Subject.call_soon`, so records are only ever emitted by the owner.
6. :meth:`Subject.dispatch` is the synchronous owner-side form of ``post`` +
   ``run_until_idle``: with nothing queued it processes the event at once. Instances
   of one chart share its compiled :class:`~statectl.kernel.semantics.Machine` and the
   programs of its steps.
7. :meth:`Subject.reissue` performs only the notifications of a step already
   taken, with the usual records and no state change: a restarted device's
   recovery ``redo`` gives it the device work of the step that entered its state.
"""

from __future__ import annotations

import sys
import threading
import traceback
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from statectl.front.observers import Observer
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Action, Chart, Notify
from statectl.kernel.semantics import Machine, Outcome, Snapshot, Step, compiled, initial_data
from statectl.run.runtime.clock import Clock, SimClock
from statectl.run.runtime.defer import attach_defer
from statectl.run.runtime.engine import Engine
from statectl.run.runtime.eventdata import check_event_data, declared_fields
from statectl.run.runtime.hooks import (
    ErrorHandler,
    Hooks,
    Listener,
    Policy,
    StateWatcher,
    StepListener,
    StepRecordListener,
)
from statectl.run.runtime.inbox import Inbox
from statectl.run.runtime.records import Record
from statectl.run.runtime.timers import attach_timers

__all__ = ["Subject"]


def _print_error(exc: BaseException) -> None:
    traceback.print_exception(exc, file=sys.stderr)


class Subject:
    """A device's chart running on a clock; observers get the notifications meant for them."""

    __slots__ = (
        "_alone",
        "_busy",
        "_closed",
        "_declared",
        "_engine",
        "_fast",
        "_hooks",
        "_inbox",
        "_serving",
        "_stopping",
        "_worker",
        "chart",
        "clock",
        "timers",
    )

    def __init__(
        self,
        chart: Chart,
        *,
        clock: Clock,
        name: str | None = None,
        policy: Policy = "ignore",
        data: Mapping[str, Any] | None = None,
    ) -> None:
        if policy != "ignore" and policy != "error":
            raise StatectlError(f"policy must be 'ignore' or 'error' (got {policy!r})")
        self.chart = chart
        self.clock = clock
        values = initial_data(chart, data) if chart.data else dict(data) if data else {}
        self._declared = declared_fields(chart)  # event -> declared data fields, or None
        self._hooks = Hooks(chart, name or chart.name)
        self._engine = Engine(compiled(chart), self._hooks, clock, policy, values)
        self._inbox = Inbox()
        self._fast = False  # dispatch may process at once: started, nothing queued, no loop
        self._alone = False  # started, no worker or owner loop, not closed (see _refresh)
        self._busy = False
        self._closed = False
        self._stopping = False
        self._serving = False
        self._worker: threading.Thread | None = None
        #: per-state timeouts (runtime/timers.py); a System routes them through its door
        self.timers = attach_timers(self)  # none for a chart without timeouts
        if any(s.defer for s in chart.states):
            attach_defer(self)  # deferred events (runtime/defer.py)

    # -- state -----------------------------------------------------------------------------

    @property
    def machine(self) -> Machine:
        """The compiled chart the device steps with (shared by the chart's devices)."""
        return self._engine.machine

    @machine.setter
    def machine(self, machine: Machine) -> None:
        """Step with another compiled machine of the chart (a cell's guards that read
        other devices: cell/explore/conditions.py)."""
        self._engine.use(machine)

    @property
    def policy(self) -> Policy:
        """What an unhandled event is: ``ignore`` (recorded) or ``error`` (raised too)."""
        return self._engine.policy

    @property
    def events_processed(self) -> int:
        """Events taken off the queue (or dispatched) and processed, handled or not."""
        return self._engine.events

    @property
    def invokes_issued(self) -> int:
        """Notifications issued (counted whether or not an observer was attached)."""
        return self._engine.invokes

    @property
    def name(self) -> str:
        """The device name every record and notification carries."""
        return self._engine.name

    @name.setter
    def name(self, value: str) -> None:
        self._engine.rename(value)

    @property
    def configuration(self) -> frozenset[str]:
        """The active states (empty before :meth:`start`)."""
        snapshot = self._engine.snapshot
        return snapshot.active if snapshot is not None else frozenset()

    @property
    def snapshot(self) -> Snapshot | None:
        return self._engine.snapshot

    @property
    def data(self) -> Mapping[str, Any]:
        return self._engine.data

    @property
    def started(self) -> bool:
        return self._engine.snapshot is not None

    @property
    def finished(self) -> bool:
        return self._engine.finished

    @property
    def queued(self) -> int:
        return len(self._inbox)

    @property
    def listening(self) -> bool:
        """Whether anyone receives records (build one only then)."""
        return self._engine.listening

    def _refresh(self) -> None:
        """Recompute whether :meth:`dispatch` may process an event at once, without the queue.

        ``_fast`` is also False while anything is queued: :meth:`post` appends, then
        clears it; this sets it, then looks at the queue, so whichever thread runs
        second, a queued item is never overtaken (one flag test on the hot path
        instead of a queue test before and after).
        """
        self._fast = self._alone = (
            self._engine.snapshot is not None
            and self._worker is None
            and not self._serving
            and not self._closed
        )
        if self._inbox:
            self._fast = False

    # -- wiring (runtime/hooks.py) ---------------------------------------------------------

    def attach(self, observer: Observer, invokes: Iterable[int] | None = None) -> None:
        """Register ``observer`` for these invoke numbers (default: every invoke of the chart)."""
        self._hooks.attach(observer, invokes)

    def observer_for(self, invoke: int) -> Observer | None:
        route = self._hooks.routes.get(invoke)
        return route.observer if route is not None else None

    def listen(self, callback: Listener) -> Callable[[], None]:
        """Receive every record from now on; returns a function that stops it."""
        return self._hooks.listen(callback)

    def listen_steps(self, callback: StepRecordListener) -> Callable[[], None]:
        """Receive one :class:`StepRecord` per event from now on; returns the undo.

        Cheaper than :meth:`listen` when the typed records are not all read: they are
        built only when ``record.records`` (or iterating the record) asks for them.
        """
        return self._hooks.listen_steps(callback)

    def on_step(self, callback: StepListener) -> Callable[[], None]:
        """Hear ``(event, data, outcome)`` on the owner after each event; returns the undo.

        Unlike :meth:`listen` it builds no records. The outcome is an
        :class:`~statectl.kernel.semantics.Outcome`: ``handled`` or why the event
        changed nothing.
        """
        return self._hooks.on_step(callback)

    def watch(self, states: Iterable[str], watcher: StateWatcher) -> Callable[[], None]:
        """Tell ``watcher`` when one of ``states`` is entered or exited; returns the undo.

        Only the steps that enter or exit a watched state call it. Watch before
        :meth:`start` to hear the initial states entered.
        """
        names = tuple(dict.fromkeys(states))
        unknown = [n for n in names if n not in self.machine.order]
        if unknown:
            raise StatectlError(f"{self.name}: no state {unknown} in chart {self.chart.name!r}")
        return self._hooks.add_watcher(names, watcher)

    def emit(self, record: Record) -> None:
        """Deliver ``record`` to the listeners, in order with the step's own records."""
        self._engine.emit(record)

    # -- posting (any thread) ----------------------------------------------------------------

    def post(
        self, event: str, data: Any = None, then: Callable[[Outcome], object] | None = None
    ) -> None:
        """Queue ``event`` for the owner; never blocks, safe from any thread.

        ``then(outcome)`` (pass it by name) is called on the owner right after the event
        ran, with its :class:`~statectl.kernel.semantics.Outcome`. (Not keyword-only:
        CPython 3.11 runs a call of a function with keyword-only parameters on its
        generic path, ~60 ns more per post or dispatch.)
        """
        if not isinstance(event, str):
            raise StatectlError(f"an event name must be a str (got {event!r})")
        if self._closed:
            raise StatectlError(f"{self.name} is closed; event {event!r} cannot be posted")
        if data is not None and self._declared is not None:
            check_event_data(self._declared, self._engine.name, event, data)
        inbox = self._inbox
        inbox.append((event, data, then))
        self._fast = False  # after the append: see _refresh()
        if inbox.wake is not None or inbox.hook is not None:
            inbox.told(self)

    def on_queued(self, hook: Callable[[Subject], object] | None) -> None:
        """Call ``hook(subject)`` after every post or call_soon (from the posting thread).

        A host that owns many devices (a :class:`~statectl.run.system.System`) learns
        which ones have work instead of asking them all; ``None`` removes it.
        """
        self._inbox.hook = hook

    def call_soon(self, fn: Callable[[], object]) -> None:
        """Run ``fn`` on the owner, in queue order with the events (monitors use this)."""
        if self._closed:
            return
        inbox = self._inbox
        inbox.append((None, None, fn))
        self._fast = False  # after the append: see _refresh()
        if inbox.wake is not None or inbox.hook is not None:
            inbox.told(self)

    def call_next(self, fn: Callable[[], object]) -> None:
        """On the owner: run ``fn`` before anything queued (a deferred event's release)."""
        self._inbox.appendleft((None, None, fn))  # nobody is told: the owner takes it
        self._fast = False

    # -- owning ------------------------------------------------------------------------------

    def start(self) -> None:
        """Enter the initial configuration (records ``Started`` and the entered states)."""
        if self._engine.snapshot is not None:
            raise StatectlError(f"{self.name} was started already")
        if self._worker is not None:
            self._check_owner()
        self._engine.begin()
        self._refresh()

    def restore(self, snapshot: Snapshot) -> None:
        """Take up ``snapshot`` (a journal's) instead of :meth:`start`; nothing is notified.

        Listeners get ``Started`` and a ``MicrostepTaken`` entering the active states in
        document order (no transition), and the monitors of active states run again.
        """
        if self._engine.snapshot is not None:
            raise StatectlError(f"{self.name} was started already; restore before start()")
        self._check_owner()
        unknown = sorted(snapshot.active - self.machine.order.keys())
        if unknown:
            raise StatectlError(f"{self.name}: states {unknown} are not in {self.chart.name!r}")
        self._engine.restore(snapshot)
        self._refresh()

    def reissue(self, actions: Step | Iterable[Action], data: Any = None) -> tuple[Notify, ...]:
        """Issue the notifications of a step again, changing no state; returns those issued.

        A device restarted in a state whose device work was cut short (a Motor
        Returning when the power went away) gets that work again: a recovery
        ``redo`` hands the step that entered the state. Only its ``Notify``
        actions are performed, each as a step performs it (an ``InvokeIssued``
        record, the observer's call, ``ObserverCalled``); the configuration,
        history and previous state stay as they are. Call it as the owner.
        """
        self._check_owner()
        if self._engine.snapshot is None:
            raise StatectlError(f"{self.name}: start() or restore() before reissue()")
        found = actions.actions if isinstance(actions, Step) else tuple(actions)
        notifies = tuple(a for a in found if isinstance(a, Notify))
        busy = self._busy
        self._busy = True  # an observer must post(), not process, as during a step
        try:
            self._engine.reissue(notifies, data)
        finally:
            self._busy = busy
        return notifies

    def run_until_idle(self) -> int:
        """Process queued events until the queue is empty; returns how many events ran."""
        if self._worker is not None:
            self._check_owner()
        engine = self._engine
        if engine.snapshot is None:
            raise StatectlError(f"{self.name}: call start() before processing events")
        if self._busy:
            raise StatectlError(
                f"{self.name}: run_until_idle() called while an event is being processed "
                "(from an observer or listener?); post() the event instead"
            )
        count = 0
        queue = self._inbox
        self._busy = True
        try:
            while queue and not self._stopping:
                event, data, fn = queue.popleft()
                if event is None:
                    if fn is not None:
                        fn()
                    continue
                count += 1
                if fn is None:
                    engine.perform(event, data)
                    continue
                self._process_then(event, data, fn)
        finally:
            self._busy = False
            if self._alone and not self._fast:  # _refresh() when only the queue changed
                self._fast = True
                if queue:
                    self._fast = False
        return count

    def _process_then(self, event: str, data: Any, then: Callable[[Outcome], object]) -> None:
        """Process ``event``, then ``then(outcome)``: what the step listeners heard (also
        when the step raised)."""
        heard: list[Outcome] = []

        def hear(_event: str, _data: Any, outcome: Outcome) -> None:
            heard.append(outcome)

        try:
            self._engine.perform(event, data, None, (hear, *self._hooks.steppers))
        finally:
            then(heard[0] if heard else Outcome.HANDLED)

    def dispatch(
        self, event: str, data: Any = None, then: Callable[[Outcome], object] | None = None
    ) -> int:
        """Process ``event`` now, on the calling thread as the owner, after anything queued.

        The synchronous form of :meth:`post` then :meth:`run_until_idle`: the same
        path, records, observer calls and errors; returns how many events ran.
        ``then(outcome)``: as for :meth:`post`, right after the event ran.
        """
        if data is not None and self._declared is not None:
            check_event_data(self._declared, self._engine.name, event, data)
        if self._fast and not self._busy and type(event) is str:  # _fast: nothing queued
            self._busy = True
            try:
                if then is None:
                    self._engine.perform(event, data)
                else:
                    self._process_then(event, data, then)
            finally:
                self._busy = False
            if self._inbox:  # posted meanwhile (an observer's completion)
                return 1 + self.run_until_idle()
            return 1
        self.post(event, data, then=then)
        return self.run_until_idle()

    def deliver(self, event: str, data: Any = None) -> None:
        """Process ``event`` now, on the owner, at this point of the queue (a timer's
        ``call_soon`` callback uses it); outside a run it is :meth:`dispatch`."""
        if not self._busy:
            self.dispatch(event, data)
            return
        self._engine.perform(event, data)

    def advance(self, seconds: float) -> int:
        """On a :class:`SimClock`: move time on, draining the queue after every timer."""
        if not isinstance(self.clock, SimClock):
            raise StatectlError("advance() needs a SimClock; a WallClock moves by itself")
        count = self.run_until_idle()
        self.clock.advance(seconds, settle=self.run_until_idle)
        return count + self.run_until_idle()

    def close(self) -> None:
        """Stop the owner, record ``Finished``; later posts are refused."""
        if self._closed:
            return
        self.stop()
        self._closed = True
        self._fast = self._alone = False
        self._engine.close()

    # -- an owner loop on a thread of its own ------------------------------------------------

    def serve_forever(self, on_error: ErrorHandler = _print_error) -> None:
        """Be the owner on this thread until :meth:`stop`; errors go to ``on_error``."""
        if self._engine.snapshot is None:
            self.start()
        wake = self._inbox.waker()
        self._serving = True
        self._fast = self._alone = False
        try:
            while not self._stopping:
                wake.wait()
                wake.clear()
                while self._inbox and not self._stopping:
                    try:
                        self.run_until_idle()
                    except Exception as exc:  # record + callback; a worker never dies of an event
                        on_error(exc)
        finally:
            self._serving = False
            self._stopping = False
            self._refresh()

    def start_worker(self, on_error: ErrorHandler = _print_error) -> threading.Thread:
        """Run :meth:`serve_forever` on a daemon thread, which becomes the owner."""
        if self._worker is not None:
            raise StatectlError(f"{self.name} has a worker already")
        self._inbox.waker()
        self._serving = True  # so a stop() before the thread runs is not lost
        self._fast = self._alone = False
        self._worker = threading.Thread(
            target=self.serve_forever, args=(on_error,), name=f"statectl-{self.name}", daemon=True
        )
        self._worker.start()
        return self._worker

    def stop(self, timeout: float | None = 1.0) -> None:
        """Stop the owner loop after the event in progress; queued events stay queued."""
        if self._serving:
            self._stopping = True
            self._inbox.waker().set()
        worker = self._worker
        if worker is not None and worker is not threading.current_thread():
            worker.join(timeout)
        self._worker = None
        self._refresh()

    def _check_owner(self) -> None:
        worker = self._worker
        if worker is not None and worker.is_alive() and worker is not threading.current_thread():
            raise StatectlError(
                f"{self.name} is owned by its worker thread; post() events instead of "
                "processing them here"
            )
