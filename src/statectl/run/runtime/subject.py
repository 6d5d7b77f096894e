"""The Subject: one running device, the owner of its configuration and its event queue.

Rules:
1. One owner processes a device's events, run-to-completion, in the order they
   were posted, one at a time. Any thread may :meth:`Subject.post` without
   blocking; the owner is whoever calls :meth:`Subject.run_until_idle` (or the
   worker thread of :meth:`Subject.start_worker`), never two at once.
2. What an event does is decided by :func:`statectl.kernel.semantics.step`, which is
   pure; the Subject performs the decision: it commits the new snapshot, emits
   the records, and for each ``Notify`` calls the one observer registered for
   that invoke number (the paper's specific notification).
3. An event that changes nothing is never lost silently. The reason is the
   kernel's :class:`~statectl.kernel.semantics.Unhandled`: ``declared ignored`` (the state
   table says so), ``guard false`` (a transition existed but its guard did not
   hold), ``no transition``, or ``unknown event`` (said here, before stepping).
   Declared-ignored events are always just recorded; the others are recorded as
   ``EventIgnored`` under policy ``ignore`` and as ``EventRejected`` plus an
   :class:`~statectl.kernel.errors.UnhandledEventError` under policy ``error`` (raised
   from ``run_until_idle``; a worker hands it to its error callback and goes on).
4. Records are built only when someone listens; a record emitted while
   listeners run is delivered after the current one, so every listener sees one
   order. Those who need less than records hook the step itself: a
   :class:`StateWatcher` (monitors) hears the states it watches entered and
   exited, a step listener (the journal) hears each event's outcome; neither
   builds a record.
5. Work that must run on the owner (a monitor's poll) is queued with
   :meth:`Subject.call_soon`, so records are only ever emitted by the owner.
6. One path, fast because it is the only one: every event (from
   :meth:`Subject.dispatch`, :meth:`Subject.run_until_idle` or a worker) goes
   through ``_process``, which takes the kernel's memoised plan for the current
   snapshot when there is one (commit its target, then perform its step: the
   watchers, the notifications in order, records only for listeners) and asks
   :func:`statectl.kernel.semantics.step` only for a step it has not planned yet. What
   the plan path calls for a plan is worked out once per plan and instance.
   :meth:`Subject.dispatch` is the synchronous owner-side form of ``post`` +
   ``run_until_idle``. Instances of one chart share its compiled
   :class:`~statectl.kernel.semantics.Machine`; a Subject allocates its worker's wake-up
   event and record queue only when they are first needed.
7. :meth:`Subject.reissue` performs only the notifications of a step already
   taken, with the usual records and no state change: a restarted device's
   recovery ``redo`` gives it the device work of the step that entered its state.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from statectl.front.observers import Observer
from statectl.kernel.errors import StatectlError
from statectl.kernel.expr import compile_expression
from statectl.kernel.model import Action, Chart, Notify
from statectl.kernel.semantics import Plan, Snapshot, Step, Unhandled, compiled, initial, step
from statectl.run.runtime.clock import Clock, SimClock
from statectl.run.runtime.defer import attach_defer
from statectl.run.runtime.eventdata import (
    apply_assignments,
    check_event_data,
    declared_fields,
    refuse_failure,
)
from statectl.run.runtime.hooks import (
    ApiLogging,
    Listener,
    Policy,
    StateWatcher,
    StepListener,
)
from statectl.run.runtime.perform import _EVENTS, _INVOKES, _Call
from statectl.run.runtime.recording import StepListener as StepRecordListener
from statectl.run.runtime.records import (
    EventReceived,
    Finished,
    MicrostepTaken,
    Record,
    Started,
    StepRecord,
    _Tail,
)
from statectl.run.runtime.timers import attach_timers
from statectl.run.runtime.wiring import Wiring

__all__ = ["ApiLogging", "Listener", "Policy", "StateWatcher", "StepListener", "Subject"]

#: The plan table of a Subject not started yet: empty, never written.
_NO_PLANS: dict[str, Plan] = {}

#: A queued event ``(name, data, then)`` (``then(outcome)`` once it ran, or None), or
#: ``(None, None, fn)`` to run ``fn`` on the owner.
_Item = tuple[str | None, Any, Callable[..., object] | None]


class Subject(Wiring):
    """A device's chart running on a clock; observers get the notifications meant for them."""

    __slots__ = (
        "_busy",
        "_closed",
        "_data",
        "_declared",
        "_name",
        "_queue",
        "_queued_hook",
        "_routes",
        "_snapshot",
        "_table",
        "_watch",
        "chart",
        "clock",
        "machine",
        "policy",
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
        self.machine = compiled(chart)
        self.clock = clock
        self._name = name or chart.name
        self.policy = policy
        if chart.data:
            self._data = self._initial_data(chart, data)
        else:
            self._data = dict(data) if data else {}
        self._declared = declared_fields(chart)  # event -> declared data fields, or None
        # invoke number -> (observer, it keeps an api_log: checked once at attach)
        self._routes: dict[int, tuple[Observer, bool]] = {}
        # plan -> (invokes it counts, callable, argument): what the plan path calls for it;
        # made as plans are first taken, dropped by attach and rename
        self._calls: dict[Plan, _Call] | None = None
        self._listeners: tuple[Listener, ...] = ()
        self._recorders: tuple[StepRecordListener, ...] = ()  # listen_steps (recording.py)
        self._recording: list[tuple[int, Record]] | None = None
        self._cursor = 0
        self._handing = False
        self._later: list[StepRecord] | None = None
        self._steppers: tuple[StepListener, ...] = ()
        self._watch: dict[str, tuple[StateWatcher, ...]] = {}  # state -> its watchers
        self._watchers: tuple[StateWatcher, ...] = ()
        self._pending: deque[Record] | None = None
        self._emitting = False
        self._queue: deque[_Item] = deque()
        self._queued_hook: Callable[[Subject], object] | None = None
        self._wake: threading.Event | None = None
        self._snapshot: Snapshot | None = None
        self._table: dict[str, Plan] = _NO_PLANS  # plans of the current snapshot
        self._fast = False  # dispatch may process at once: started, nothing queued, no loop
        self._busy = False
        self._finished = False
        self._closed = False
        self._stopping = False
        self._serving = False
        self._worker: threading.Thread | None = None
        self._counts = 0  # events processed + invokes issued << _INVOKES, one add per event
        if any(s.timeout is not None for s in chart.states):
            attach_timers(self)  # per-state timeouts (runtime/timers.py)
        if any(s.defer for s in chart.states):
            attach_defer(self)  # deferred events (runtime/defer.py)

    @staticmethod
    def _initial_data(chart: Chart, given: Mapping[str, Any] | None) -> dict[str, Any]:
        """The chart's data items in order, each evaluated over the earlier ones."""
        data = dict(given or {})
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

    @property
    def events_processed(self) -> int:
        """Events taken off the queue (or dispatched) and processed, handled or not."""
        return self._counts & _EVENTS

    @events_processed.setter
    def events_processed(self, value: int) -> None:
        self._counts = (self._counts & ~_EVENTS) | value

    @property
    def invokes_issued(self) -> int:
        """Notifications issued (counted whether or not an observer was attached)."""
        return self._counts >> _INVOKES

    @invokes_issued.setter
    def invokes_issued(self, value: int) -> None:
        self._counts = (self._counts & _EVENTS) | (value << _INVOKES)

    @property
    def name(self) -> str:
        """The device name every record and notification carries."""
        return self._name

    @name.setter
    def name(self, value: str) -> None:
        self._name = value
        self._calls = None

    def _refresh(self) -> None:
        """Recompute whether :meth:`dispatch` may process an event at once, without the queue.

        ``_fast`` is also False while anything is queued: :meth:`post` appends, then
        clears it; this sets it, then looks at the queue, so whichever thread runs
        second, a queued item is never overtaken (one flag test on the hot path
        instead of a queue test before and after).
        """
        self._fast = (
            self._snapshot is not None
            and self._worker is None
            and not self._serving
            and not self._closed
        )
        if self._queue:
            self._fast = False

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

    def post(
        self, event: str, data: Any = None, *, then: Callable[[str], object] | None = None
    ) -> None:
        """Queue ``event`` for the owner; never blocks, safe from any thread.

        ``then(outcome)`` is called on the owner right after the event ran, with
        ``"handled"`` or the :class:`~statectl.kernel.semantics.Unhandled` reason.
        """
        if not isinstance(event, str):
            raise StatectlError(f"an event name must be a str (got {event!r})")
        if self._closed:
            raise StatectlError(f"{self.name} is closed; event {event!r} cannot be posted")
        if data is not None and self._declared is not None:
            check_event_data(self._declared, self._name, event, data)
        self._queue.append((event, data, then))
        self._fast = False  # after the append: see _refresh()
        wake = self._wake
        if wake is not None:
            wake.set()
        hook = self._queued_hook
        if hook is not None:
            hook(self)

    def on_queued(self, hook: Callable[[Subject], object] | None) -> None:
        """Call ``hook(subject)`` after every post or call_soon (from the posting thread).

        A host that owns many devices (a :class:`~statectl.run.system.System`) learns
        which ones have work instead of asking them all; ``None`` removes it.
        """
        self._queued_hook = hook

    def call_soon(self, fn: Callable[[], object]) -> None:
        """Run ``fn`` on the owner, in queue order with the events (monitors use this)."""
        if self._closed:
            return
        self._queue.append((None, None, fn))
        self._fast = False  # after the append: see _refresh()
        wake = self._wake
        if wake is not None:
            wake.set()
        hook = self._queued_hook
        if hook is not None:
            hook(self)

    # -- owning (one thread; the worker loop is in runtime/worker.py) ------------------------

    def start(self) -> None:
        """Enter the initial configuration (records ``Started`` and the entered states)."""
        if self._snapshot is not None:
            raise StatectlError(f"{self.name} was started already")
        if self._worker is not None:
            self._check_owner()
        machine = self.machine
        if not self._listeners and not self._recorders and not self._watch:
            entry = machine.quiet_start
            if entry is None:
                first = initial(machine, self._data)
                entry = machine.quiet(first)
            if entry is not None:  # nothing to notify or record: take up the target
                self._snapshot, self._table = entry
                self._refresh()
                return
        first = initial(machine, self._data)
        now = self.clock.now()
        listening = self.listening
        if listening:
            self.emit(Started(self.name, now))
        self._commit(first.target)
        self._perform(first, None, now, listening)

    def restore(self, snapshot: Snapshot) -> None:
        """Take up ``snapshot`` (a journal's) instead of :meth:`start`; nothing is notified.

        Listeners get ``Started`` and a ``MicrostepTaken`` entering the active states in
        document order (no transition), and the monitors of active states run again.
        """
        if self._snapshot is not None:
            raise StatectlError(f"{self.name} was started already; restore before start()")
        self._check_owner()
        order = self.machine.order
        unknown = sorted(snapshot.active - order.keys())
        if unknown:
            raise StatectlError(f"{self.name}: states {unknown} are not in {self.chart.name!r}")
        self._commit(self.machine.intern(snapshot))
        now = self.clock.now()
        active = tuple(sorted(snapshot.active, key=order.__getitem__))
        if self.listening:
            self.emit(Started(self.name, now))
            self.emit(MicrostepTaken(self.name, now, None, (), (), active))
        for state in active:
            for w in self._watch.get(state, ()):
                w.entered(state)

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
        if self._snapshot is None:
            raise StatectlError(f"{self.name}: start() or restore() before reissue()")
        found = actions.actions if isinstance(actions, Step) else tuple(actions)
        notifies = tuple(a for a in found if isinstance(a, Notify))
        now = self.clock.now()
        listening = self.listening
        busy = self._busy
        self._busy = True  # an observer must post(), not process, as during a step
        try:
            for action in notifies:
                self._notify(action, data, now, listening)
        finally:
            self._busy = busy
        return notifies

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
        queue = self._queue
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
                    self._process(event, data)
                else:
                    self._process_then(event, data, fn)
        finally:
            self._busy = False
            if not self._fast:
                self._refresh()
        return count

    def dispatch(self, event: str, data: Any = None) -> int:
        """Process ``event`` now, on the calling thread as the owner, after anything queued.

        The synchronous form of :meth:`post` then :meth:`run_until_idle`: the same
        path, records, observer calls and errors; returns how many events ran.
        """
        if data is not None and self._declared is not None:
            check_event_data(self._declared, self._name, event, data)
        if self._fast and not self._busy and type(event) is str:  # _fast: nothing queued
            self._busy = True
            try:
                self._process(event, data)
            finally:
                self._busy = False
            if self._queue:  # posted meanwhile (an observer's completion): run-to-completion
                return 1 + self.run_until_idle()
            return 1
        self.post(event, data)
        return self.run_until_idle()

    def deliver(self, event: str, data: Any = None) -> None:
        """Process ``event`` now, on the owner, at this point of the queue (a timer's
        ``call_soon`` callback uses it); outside a run it is :meth:`dispatch`."""
        if not self._busy:
            self.dispatch(event, data)
            return
        self._process(event, data)

    def call_next(self, fn: Callable[[], object]) -> None:
        """On the owner: run ``fn`` before anything queued (a deferred event's release)."""
        self._queue.appendleft((None, None, fn))
        self._fast = False

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
        self._fast = False
        if not self._finished:
            self._finished = True
            for w in self._watchers:
                w.finished()
            if self.listening:
                self.emit(Finished(self.name, self.clock.now()))

    # -- one event -------------------------------------------------------------------------

    def _commit(self, target: Snapshot) -> None:
        self._snapshot = target
        self._table = self.machine.plans(target)
        self._refresh()

    def _process(self, event: str, data: Any) -> None:
        """The one path of an event (rule 6): the plan if there is one, else the kernel."""
        plan = self._table.get(event)
        if plan is None:
            self._process_slow(event, data)
            return
        if not plan.handled:
            reason = plan.unhandled
            if (
                self._listeners
                or reason is None
                or (self.policy == "error" and reason is not Unhandled.DECLARED_IGNORED)
            ):
                self._process_slow(event, data, plan)  # records, and the rejection's error
            else:
                self._counts += 1
                for callback in self._steppers:
                    callback(event, data, reason)
                if self._recorders:
                    now = self.clock.now()
                    self._hand(StepRecord(self._name, now, event, data, None, (), _Tail(reason)))
            return
        if self._listeners:  # the records as they happen, from the plan's step
            if self._recorders:
                self._process_slow(event, data, plan)
                return
            self._counts += 1
            now = self.clock.now()
            self.emit(EventReceived(self._name, now, event, data))
            self._snapshot = plan.target
            self._table = plan.table
            try:
                self._perform(plan.step, data, now, True)
            finally:  # taken, even when an observer raised: the journal must hear it
                for callback in self._steppers:
                    callback(event, data, "handled")
            return
        self._snapshot = plan.target
        self._table = plan.table
        calls = self._calls
        entry = calls.get(plan) if calls is not None else None
        if entry is None:
            entry = self._call_for(plan)
        try:
            if self._recorders:  # one step record for the step listeners (recording.py)
                self._record_plan(event, data, plan, entry)
            else:
                self._counts += entry[0]
                if data is None:
                    call = entry[1]
                    if call is not None:
                        call(entry[2])
                else:
                    run = entry[3]
                    if run is not None:
                        run(data)
                if plan.final and not self._finished:
                    self._finish(0.0, False)
        finally:  # taken, even when an observer raised: the journal must hear it
            for callback in self._steppers:
                callback(event, data, "handled")

    def _process_then(self, event: str, data: Any, then: Callable[[str], object]) -> None:
        """:meth:`_process`, then ``then(outcome)``: the outcome a step listener would hear."""
        heard: list[str] = []

        def hear(_event: str, _data: Any, outcome: str) -> None:
            heard.append(outcome)

        self._steppers = (hear, *self._steppers)
        try:
            self._process(event, data)
        finally:
            self._steppers = tuple(c for c in self._steppers if c is not hear)
            then(heard[0] if heard else "handled")

    def _process_slow(self, event: str, data: Any, plan: Plan | None = None) -> None:
        """The full path: records for listeners, reasons named; the kernel asked only
        when there is no ``plan`` to take the step from."""
        snapshot = self._snapshot
        assert snapshot is not None
        self._counts += 1
        now = self.clock.now()
        listening = bool(self._listeners)
        if listening:
            self.emit(EventReceived(self.name, now, event, data))
        if plan is None and event not in self.machine.event_names:
            self._unhandled(event, data, Unhandled.UNKNOWN_EVENT, now, snapshot)
            return
        if plan is not None and (plan.handled or plan.step.unhandled is not None):
            decision = plan.step
        else:
            decision = step(self.machine, snapshot, event, self._data, data)
        if decision.unhandled is not None:
            if decision.failure is not None:
                refuse_failure(self, event, data, decision.failure, now)
            self._unhandled(event, data, decision.unhandled, now, snapshot)
            return
        updates = apply_assignments(self, decision, event, data) if self._data else None
        if updates:
            self._data.update(updates)
        self._commit(plan.target if plan is not None else decision.target)
        try:
            if listening or not self._recorders:
                self._perform(decision, data, now, listening)
            else:  # only step listeners: one step record (recording.py)
                self._record_step(event, data, decision, now)
        finally:  # taken, even when an observer raised: the journal must hear it
            for callback in self._steppers:
                callback(event, data, "handled")
