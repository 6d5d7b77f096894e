"""The engine: one path that performs every step of a device.

Rules:
1. :meth:`Engine.perform` is the only code that performs a step: an event's, the
   start's, a recovery's reissue. For an event it takes the
   :class:`~statectl.run.runtime.program.Program` of the kernel's memoised plan for the
   current snapshot and event when there is one (steps with no guard, or guards that
   read only the snapshot), else it asks :func:`statectl.kernel.semantics.step` and
   applies the step's assignments before anything is committed. A start the kernel
   says only moves (``Machine.quiet_start``: nothing to notify) with nothing hooked
   only takes up its target.
2. A program is bound once to the device's sinks (:class:`Bound`, kept per plan until
   the wiring changes): each effect becomes the calls of the sinks that hear it, in
   order (an ``Enter`` calls the state's watchers: a monitor, a timer; a notification
   its one observer). How records are made depends on who listens (the bound's mode):
   ``UNHEARD`` makes none; ``RECORDS`` (a :meth:`listen` listener) emits each typed
   record as it happens; ``STEPS`` (only :meth:`listen_steps` listeners) keeps what
   each observer did and hands one :class:`StepRecord` per event, whose typed records
   are built from the program when read.
3. After the step, its step listeners (the journal, deferred events) hear the
   :class:`~statectl.kernel.semantics.Outcome`: after the step when it was handled, even
   when an observer raised (the transition was committed first), and before its record
   when it changed nothing. An unhandled event under policy ``error`` (all but declared
   ignores) and a guard that raised are refused with an error after their records.
4. A record emitted while listeners run is delivered after the current one; one made
   during a step for step listeners (a monitor starting) takes its place in the step.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from functools import partial
from typing import Any

import msgspec

from statectl.front.observers import Notification
from statectl.kernel.errors import UnhandledEventError
from statectl.kernel.model import Notify
from statectl.kernel.semantics import Machine, Outcome, PlanTable, Snapshot, Step, initial, step
from statectl.kernel.semantics.eventview import GuardError, GuardFailure
from statectl.run.runtime.clock import Clock
from statectl.run.runtime.eventdata import AssignError, assignments_of
from statectl.run.runtime.hooks import (
    Hooks,
    Policy,
    Route,
    StepListener,
    api_calls_since,
    api_count,
)
from statectl.run.runtime.program import Enter, Exit, Program, Transit, program_of, unstepped
from statectl.run.runtime.records import (
    EventIgnored,
    EventReceived,
    EventRejected,
    Finished,
    InvokeIssued,
    MicrostepTaken,
    ObserverCalled,
    Record,
    Started,
    StepRecord,
    _Made,
    _Tail,
    update_api,
)

__all__ = ["RECORDS", "STEPS", "UNHEARD", "Bound", "Engine"]

#: How a step is heard (rule 2): by nobody, as typed records, as one step record.
UNHEARD, RECORDS, STEPS = 0, 1, 2
HANDLED = Outcome.HANDLED
DECLARED_IGNORED = Outcome.DECLARED_IGNORED
#: Makes a notification from its fields without the named tuple's Python constructor.
_NEW = tuple.__new__
#: A sink's call and its argument: a watcher's method and a state, a notification's call
#: and the notification (without data: the event's is put in when there is some).
Call = tuple[Callable[[Any], object], Any]
#: Records made during a step for step listeners before any was (a list only then).
_NONE_YET: list[tuple[int, Record]] = []
#: Bound programs kept per device before they are all bound again.
_BOUND_MAX = 4096


class Bound(msgspec.Struct, frozen=True, eq=False):
    """A program bound to one device's sinks (rule 2).

    ``calls`` run in order; in mode ``STEPS``, ``made`` is what the observers do when it
    is known before the step runs (one observer that logs no API calls, no watcher),
    else ``None``; ``cursor`` is where a record made meanwhile goes when nothing says
    otherwise and ``end`` the typed records before ``Finished`` (``ObserverCalled`` of
    unknown count apart). A frozen struct: each device binds each step it takes once,
    and a frozen dataclass took 1.5 us of the ~4 us that costs (a struct: 0.2 us).
    """

    program: Program
    mode: int
    calls: tuple[Call, ...] = ()
    made: tuple[_Made, ...] | None = None
    cursor: int = 1
    end: int = 1
    quiet: bool = False  # an event that changed nothing, unheard, refused with no error


class Engine:
    """Performs a device's steps on its sinks (rules 1-4); owned by one Subject."""

    __slots__ = (
        "_bound",
        "_cursor",
        "_emitting",
        "_extras",
        "_final",
        "_handing",
        "_later",
        "_made",
        "_now",
        "_pending",
        "_shift",
        "clock",
        "data",
        "events",
        "finished",
        "hooks",
        "invokes",
        "machine",
        "name",
        "policy",
        "snapshot",
        "table",
    )

    # set as a heard step begins (in :meth:`perform`): the clock then; for step listeners
    # (STEPS) what each observer did, the typed records before one made now, the
    # ObserverCalled records so far, and whether the step ended the run
    _now: float
    _made: list[_Made]
    _cursor: int
    _shift: int
    _final: bool

    def __init__(
        self, machine: Machine, hooks: Hooks, clock: Clock, policy: Policy, data: dict[str, Any]
    ) -> None:
        self.machine = machine
        self.hooks = hooks
        self.clock = clock
        self.policy = policy
        self.name = hooks.device
        self.data = data
        self.snapshot: Snapshot | None = None
        self.table: PlanTable = {}
        self.events = 0  # events processed, handled or not
        self.invokes = 0  # notifications issued, observer attached or not
        self.finished = False
        self._bound: dict[object, Bound] = hooks.bound  # per plan (or program): its binding
        self._extras: list[tuple[int, Record]] | None = None  # STEPS: records made meanwhile
        self._pending: deque[Record] | None = None
        self._emitting = False
        self._handing = False
        self._later: list[StepRecord] | None = None

    def use(self, machine: Machine) -> None:
        """Step with ``machine`` from now on: what was bound for the old one is dropped."""
        self.machine = machine
        self._bound.clear()
        if self.snapshot is not None:
            self.snapshot = machine.intern(self.snapshot)
            self.table = machine.plans(self.snapshot)

    def rename(self, name: str) -> None:
        self.name = self.hooks.device = name
        self._bound.clear()

    @property
    def listening(self) -> bool:
        """Whether anyone receives records (build one only then)."""
        hooks = self.hooks
        return bool(hooks.listeners or hooks.recorders)

    # -- choosing the step (rule 1) --------------------------------------------------------

    def _mode(self) -> int:
        hooks = self.hooks
        return RECORDS if hooks.listeners else STEPS if hooks.recorders else UNHEARD

    def _decide(self, event: str, data: Any) -> Bound:
        """The step of ``event`` not bound yet: its plan's, or the kernel's answer.

        Bindings are kept per plan and per program of a handled step the kernel
        memoised (over data, per outcome of its guards), never for one made fresh."""
        bound = self._bound
        if len(bound) >= _BOUND_MAX:
            bound.clear()
        mode = self._mode()
        plan = self.table.get(event)
        if plan is not None and (plan.handled or plan.unhandled is not None):
            found = bound[plan] = self._bind(program_of(plan.step, plan.table), mode)
            return found
        snapshot = self.snapshot
        assert snapshot is not None
        machine = self.machine
        if event not in machine.event_names:
            return self._bind(unstepped(event, snapshot, self.table), mode)
        decision = step(machine, snapshot, event, self.data, data)
        if not decision.handled:
            return self._bind(program_of(decision, self.table), mode)
        if self.data:
            self._assign(decision, event, data)
        program = program_of(decision, machine.plans(decision.target))
        kept = bound.get(program)
        if kept is None:
            kept = bound[program] = self._bind(program, mode)
        return kept

    def _assign(self, decision: Step, event: str, data: Any) -> None:
        """The step's assignments, before anything is committed; one that fails refuses it."""
        try:
            updates = assignments_of(decision, self.data, event, data, self.name)
        except AssignError:
            if self.hooks.listeners:
                self.emit(EventReceived(self.name, self.clock.now(), event, data))
            raise
        if updates:
            self.data.update(updates)

    # -- binding (rule 2) ------------------------------------------------------------------

    def _bind(self, program: Program, mode: int) -> Bound:
        """``program``'s effects as the calls of this device's sinks, in order."""
        hooks = self.hooks
        if program.outcome is not HANDLED:  # changed nothing: nothing to call
            return Bound(program, mode, quiet=not mode and self._ignored(program))
        if not mode and not program.invokes and not hooks.watch:
            return Bound(program, mode)  # nothing to call: the target is taken up
        if mode == STEPS:
            known = self._known(program)
            if known is not None:
                return known
        watch, routes = hooks.watch, hooks.routes
        calls: list[Call] = []
        at = 1  # the typed records before the next effect's: EventReceived
        for effect in program.effects:
            if isinstance(effect, Transit):
                at += 1
                if mode == RECORDS:
                    calls.append((self._transit, effect))
            elif isinstance(effect, (Exit, Enter)):
                for w in watch.get(effect.state, ()):
                    fn: Callable[[Any], object] = w.entered if type(effect) is Enter else w.exited
                    calls.append(
                        (partial(self._watched, at, fn) if mode == STEPS else fn, effect.state)
                    )
            else:
                at += 1
                route = routes.get(effect.invoke)
                note = self._note(effect)
                if mode == RECORDS:
                    calls.append((partial(self._heard, route), note))
                elif mode == STEPS:
                    calls.append((partial(self._noted, at, route), note))
                elif route is not None:
                    calls.append((route.observer.update, note))
        return Bound(program, mode, tuple(calls), None, 1, at)

    def _known(self, program: Program) -> Bound | None:
        """For step listeners, a step whose record is known before it runs: no watcher
        and at most one notification, to an observer that logs no API calls (or none).
        It runs as unheard; what its observer did is known (:func:`update_api`)."""
        watch, routes = self.hooks.watch, self.hooks.routes
        at = cursor = 1
        made: list[_Made] = []
        calls: list[Call] = []
        for effect in program.effects:
            if isinstance(effect, Transit):
                at += 1
            elif isinstance(effect, (Exit, Enter)):
                if effect.state in watch:
                    return None
            else:
                route = routes.get(effect.invoke)
                if made or (route is not None and route.logging):
                    return None
                at += 1
                cursor = at
                if route is None:
                    made.append(None)
                else:
                    made.append(update_api(route.observer, effect.invoke))
                    calls.append((route.observer.update, self._note(effect)))
        end = at + sum(m is not None for m in made)
        return Bound(program, STEPS, tuple(calls), tuple(made), cursor if made else at, end)

    def _note(self, notify: Notify) -> Notification:
        """The notification ``notify`` sends, without data (the event's is put in)."""
        fields = (self.name, notify.invoke, notify.name, notify.method, notify.event, None)
        return _NEW(Notification, fields)

    # -- performing (the one path) ---------------------------------------------------------

    def perform(
        self,
        event: str | None,
        data: Any,
        bound: Bound | None = None,
        steppers: tuple[StepListener, ...] | None = None,
    ) -> Outcome:
        """Perform ``event``'s step, or the ``bound`` program given (the start, a reissue:
        ``event`` None); returns its outcome. The owner's, one step at a time.

        The step's target is committed, its calls run in order, a final step finishes
        the run, then ``steppers`` (default: the device's step listeners) hear the
        outcome (rule 3)."""
        if bound is None:  # an event: its plan's bound program, else the kernel's
            self.events += 1
            bound = self._bound.get(self.table.get(event))  # type: ignore[arg-type]
            if bound is None:  # event is a str here: only the start and reissue give None
                bound = self._decide(event, data)  # type: ignore[arg-type]
        if steppers is None:
            steppers = self.hooks.steppers
        program = bound.program
        if program.outcome is not HANDLED:
            if bound.quiet and not steppers:  # nobody to tell, nothing to raise
                return program.outcome
            return self._refuse(bound, event, data, steppers)
        mode = bound.mode
        if mode:  # heard: EventReceived for listeners, a step record's start for step ones
            now = self._now = self.clock.now()
            if mode == STEPS:
                self._extras = _NONE_YET  # emit() makes a list if anything is recorded now
                self._cursor = bound.cursor
                self._shift = 0
                self._final = False
                if bound.made is None:
                    self._made = []
            elif event is not None:
                self.emit(EventReceived(self.name, now, event, data))
        self.snapshot = program.target
        self.table = program.table
        if program.invokes:  # (each empty loop or zero add skipped saves ~15 ns a step)
            self.invokes += program.invokes
        calls = bound.calls
        try:
            if not calls:
                pass
            elif data is None:
                for fn, arg in calls:
                    fn(arg)
            else:  # each notification with the event's data
                for fn, arg in calls:
                    if type(arg) is Notification:
                        arg = _NEW(Notification, (arg[0], arg[1], arg[2], arg[3], arg[4], data))
                    fn(arg)
            if program.final and not self.finished:
                self._finish(bound)
        except BaseException:
            if mode == STEPS:  # its typed records end where it failed
                self._hand_step(bound, event, data, True)
            raise
        else:
            if mode == STEPS:
                self._hand_step(bound, event, data, False)
        finally:  # taken, even when an observer raised: the journal must hear it
            if steppers:
                for callback in steppers:
                    callback(event, data, HANDLED)  # type: ignore[arg-type]
        return HANDLED

    def _refuse(
        self, bound: Bound, event: str | None, data: Any, steppers: tuple[StepListener, ...]
    ) -> Outcome:
        """An event that changed nothing: its listeners, its record, its error (rule 3)."""
        program, mode = bound.program, bound.mode
        reason = program.outcome
        failure: GuardFailure | None = program.step.failure if program.step else None
        ignore = self._ignored(program)
        assert event is not None and self.snapshot is not None
        if mode:
            self._now = self.clock.now()
            if mode == RECORDS:
                self.emit(EventReceived(self.name, self._now, event, data))
        for callback in steppers:
            callback(event, data, reason)
        if mode == RECORDS:
            kind = EventIgnored if ignore else EventRejected
            self.emit(kind(self.name, self._now, event, reason))
        elif mode == STEPS:
            tail = _Tail(reason, not ignore)
            self._hand(StepRecord(self.name, self._now, event, data, None, (), tail))
        if failure is not None:
            raise GuardError(failure.message(self.name))
        if not ignore:
            active = ", ".join(sorted(self.snapshot.active))
            raise UnhandledEventError(
                f"{self.name}: event {event!r} is not handled in [{active}] ({reason}); "
                "add a transition or declare it ignored in the state table, or use policy "
                "'ignore'"
            )
        return reason

    def _ignored(self, program: Program) -> bool:
        """Whether ``program``, which changed nothing, raises no error: no guard raised,
        and the policy is ``ignore`` or the state table declares the event ignored."""
        raised = program.step is not None and program.step.failure is not None
        return not raised and (self.policy == "ignore" or program.outcome is DECLARED_IGNORED)

    def _finish(self, bound: Bound) -> None:
        """The step reached a final state: the run is over (watchers stop, ``Finished``)."""
        self.finished = True
        if bound.mode == STEPS:
            self._final = True
            self._cursor = bound.end + self._shift
        for w in self.hooks.watchers:
            w.finished()
        if bound.mode == RECORDS:
            self.emit(Finished(self.name, self._now))

    def _transit(self, t: Transit) -> None:
        self.emit(MicrostepTaken(self.name, self._now, t.event, t.exited, t.taken, t.entered))

    def _watched(self, at: int, fn: Callable[[str], object], state: str) -> None:
        """STEPS: a watcher's call, a record it makes placed after the ``at``-th."""
        self._cursor = at + self._shift
        fn(state)

    def _heard(self, route: Route | None, note: Notification) -> None:
        """RECORDS: a notification issued, its observer's call and API calls recorded."""
        name, now = self.name, self._now
        self.emit(InvokeIssued(name, now, note.invoke, note.name, note.method, note.event))
        if route is None:
            return
        observer = route.observer
        if not route.logging:
            observer.update(note)
            self.emit(ObserverCalled(name, now, note.method, update_api(observer, note.invoke)))
            return
        before = api_count(observer)
        observer.update(note)
        for call in api_calls_since(observer, before):
            self.emit(ObserverCalled(name, now, note.method, str(call)))

    def _noted(self, at: int, route: Route | None, note: Notification) -> None:
        """STEPS: a notification issued; what its observer did is kept for the record."""
        self._cursor = at + self._shift
        if route is None:
            self._made.append(None)
            return
        observer = route.observer
        if route.logging:
            before = api_count(observer)
            observer.update(note)
            calls = tuple(api_calls_since(observer, before))
            self._made.append(calls)
            self._shift += len(calls)
        else:
            observer.update(note)
            self._made.append(update_api(observer, note.invoke))
            self._shift += 1

    def _hand_step(self, bound: Bound, event: str | None, data: Any, failed: bool) -> None:
        """STEPS: the step's one record, its typed records ending where it ``failed``.
        (No keyword-only parameter: CPython 3.11 calls such a function the slow way.)"""
        extras = self._extras
        self._extras = None
        final = self._final
        tail = None
        if extras or final or failed:
            tail = _Tail(None, False, final, self._cursor if failed else None, extras or ())
        made = bound.made if bound.made is not None else self._made
        program = bound.program
        record = StepRecord(
            self.name, self._now, event, data, program.step, made, tail, None, program.records
        )
        self._hand(record)  # a step listener's own step goes after the one being given now

    # -- delivering records (rule 4) -------------------------------------------------------

    def emit(self, record: Record) -> None:
        """Deliver ``record``: into the step being recorded, else to every listener, after
        any record being delivered now (a listener that emits is heard after it)."""
        extras = self._extras
        if extras is not None:  # made during a step for step listeners: kept in its place
            if extras is _NONE_YET:
                extras = self._extras = []
            extras.append((self._cursor, record))
            return
        hooks = self.hooks
        if hooks.recorders:
            self._hand(StepRecord.of(record))
        if not hooks.listeners:
            return
        if self._emitting:  # a listener emitted: delivered after the current record
            pending = self._pending
            if pending is None:
                pending = self._pending = deque()
            pending.append(record)
            return
        self._emitting = True
        try:
            for callback in hooks.listeners:
                callback(record)
            pending = self._pending
            while pending:
                r = pending.popleft()
                for callback in hooks.listeners:
                    callback(r)
        except BaseException:
            if self._pending:
                self._pending.clear()
            raise
        finally:
            self._emitting = False

    def _hand(self, step: StepRecord) -> None:
        """Give ``step`` to the step listeners, after any being given now."""
        if self._handing:
            later = self._later
            if later is None:
                later = self._later = []
            later.append(step)
            return
        self._handing = True
        try:
            for callback in self.hooks.recorders:
                callback(step)
            if self._later:
                self._hand_later()
        except BaseException:
            if self._later:
                self._later.clear()
            raise
        finally:
            self._handing = False

    def _hand_later(self) -> None:
        """Give the step records that step listeners made while one was being given."""
        later = self._later
        while later:
            step = later.pop(0)
            for callback in self.hooks.recorders:
                callback(step)

    # -- starting, restoring, reissuing, closing -------------------------------------------

    def begin(self) -> None:
        """Enter the initial configuration: ``Started``, then the initial step performed."""
        machine = self.machine
        hooks = self.hooks
        quiet = machine.quiet_start
        if quiet is not None and not (hooks.listeners or hooks.recorders or hooks.watch):
            self.snapshot, self.table = quiet  # the kernel says it only moves there
            return
        first = initial(machine, self.data)
        program = program_of(first, machine.plans(first.target))
        if quiet is None:
            machine.quiet(first)  # the kernel keeps whether a start only moves (quiet_start)
        heard = self.listening
        if heard:
            self.emit(Started(self.name, self.clock.now()))
        self.perform(None, None, self._bind(program, RECORDS if heard else UNHEARD), ())

    def restore(self, snapshot: Snapshot) -> None:
        """Take up ``snapshot``: ``Started``, its states entered in document order (no
        transition) for listeners, and the watchers of its states told."""
        machine = self.machine
        snapshot = machine.intern(snapshot)
        self.snapshot = snapshot
        self.table = machine.plans(snapshot)
        now = self.clock.now()
        order = machine.order
        active = tuple(sorted(snapshot.active, key=order.__getitem__))
        if self.listening:
            self.emit(Started(self.name, now))
            self.emit(MicrostepTaken(self.name, now, None, (), (), active))
        watch = self.hooks.watch
        for state in active:
            for w in watch.get(state, ()):
                w.entered(state)

    def reissue(self, notifies: tuple[Notify, ...], data: Any) -> None:
        """Perform only ``notifies``, changing no state (a recovery's redo)."""
        assert self.snapshot is not None
        program = Program(
            None, None, HANDLED, self.snapshot, self.table, notifies, len(notifies), False
        )
        mode = RECORDS if self.listening else UNHEARD
        self.perform(None, data, self._bind(program, mode), ())

    def close(self) -> None:
        """The run is over: the watchers stop, listeners get ``Finished``."""
        if self.finished:
            return
        self.finished = True
        for w in self.hooks.watchers:
            w.finished()
        if self.listening:
            self.emit(Finished(self.name, self.clock.now()))
