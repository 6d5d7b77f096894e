"""Performing a step the kernel decided: watchers, notifications, records, in one order.

The :class:`~statectl.run.runtime.subject.Subject` decides *which* step to take (a
memoised plan, or the kernel's answer); this mixin performs it, as rules 2-4 of
the Subject say: per microstep the states exited, the transitions taken and the
states entered (records for listeners, calls for watchers), then the microstep's
notifications, each to the one observer attached for its invoke number. What the
plan path calls for a plan without data is worked out once here (:meth:`_call_for`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import Any, cast

from statectl.front.observers import Notification, Observer
from statectl.kernel.errors import UnhandledEventError
from statectl.kernel.model import Chart, Notify
from statectl.kernel.semantics import Plan, Snapshot, Step, Unhandled
from statectl.run.runtime.clock import Clock
from statectl.run.runtime.hooks import ApiLogging, Listener, Policy, StateWatcher, StepListener
from statectl.run.runtime.records import (
    ApiCall,
    Builder,
    EventIgnored,
    EventRejected,
    Finished,
    IgnoreReason,
    InvokeIssued,
    MicrostepTaken,
    ObserverCalled,
    Record,
    StepRecord,
    _Made,
    _Tail,
    taken,
    update_api,
)

__all__ = ["Performer"]

#: A step's calls for a recorded run (runtime/recording.py): ``(watcher method, or None
#: for a notification; state or Notify; typed records before it)``, and the count in all.
Recorded = tuple[tuple[tuple[Callable[[Any], object] | None, Any, int], ...], int]
#: A plan whose step record is known before it runs (no watcher, at most one notification,
#: to an observer that logs no API calls): what its observer did, and the typed records
#: before that notification (the cursor while it runs).
Static = tuple[tuple[_Made, ...], int]
#: What the plan path calls for a plan: (counted first, callable or None, argument) without
#: event data; with data, the callable given the data, or None (counted first as well);
#: the plan's calls for a step listener (:func:`recorded`), and the plan's record
#: builder once a step listener has read its typed records (see :class:`Builder`).
_Call = tuple[
    int,
    Callable[[Any], object] | None,
    Any,
    Callable[[Any], object] | None,
    Recorded,
    Static | None,
    Builder,
]
#: A plan's watcher calls and notifications in order (see ``Performer._program``).
_Program = tuple[tuple[Callable[[str], object] | None, Any], ...]
#: ``Subject._counts`` holds both counters: events in the low bits, invokes above them.
_INVOKES = 48
_EVENTS = (1 << _INVOKES) - 1
_ONE_INVOKE = 1 << _INVOKES


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


#: Makes a notification from its fields without the named tuple's Python constructor.
_NEW = tuple.__new__


def _nobody(note: Notification) -> None:
    """The call for a notification no observer is attached for: it is only counted."""


def _with_data(call: Callable[[Notification], object], note: Notification) -> Callable[[Any], None]:
    """The call of a plan's one notification for an event with data: ``note`` with the
    data, to the observer routed now.

    The notification is made with ``tuple.__new__`` from ``note``'s other fields: what
    the named tuple's own constructor does after a Python call of its own, which took
    half the time of a data event's step.
    """
    new, kind, fields = _NEW, Notification, tuple(note)[:-1]

    def notify(data: Any) -> None:
        call(new(kind, (*fields, data)))

    return notify


class Performer:
    """The Subject's performing half; the slots it writes live here, the rest on the Subject."""

    __slots__ = ("_calls", "_counts", "_emitting", "_finished", "_pending")

    chart: Chart
    clock: Clock
    policy: Policy
    _name: str
    _routes: dict[int, tuple[Observer, bool]]
    _calls: dict[Plan, _Call] | None
    _listeners: tuple[Listener, ...]
    _recorders: tuple[Callable[[StepRecord], None], ...]
    _steppers: tuple[StepListener, ...]
    _watch: dict[str, tuple[StateWatcher, ...]]
    _watchers: tuple[StateWatcher, ...]
    _pending: deque[Record] | None
    _emitting: bool
    _counts: int
    _finished: bool

    def emit(self, record: Record) -> None:
        """Deliver ``record`` to every listener (:mod:`statectl.run.runtime.recording`)."""
        raise NotImplementedError

    def _call_for(self, plan: Plan) -> _Call:
        """What the plan path calls for ``plan``, worked out once per plan and instance.

        Without event data: ``counts`` are added and ``call(arg)`` made; a single
        notification is prebuilt for the observer routed now (attach and rename drop
        these). With data: ``with_data(data)`` is called, which counts the invokes it
        issues. A plan that enters or exits a watched state, or issues several
        notifications, runs a *program*: the watcher calls and notifications of its step
        in the order :meth:`_perform` makes them, resolved once instead of per event.
        """
        calls = self._calls
        if calls is None:
            calls = self._calls = {}
        watch = self._watch
        head: tuple[int, Callable[[Any], object] | None, Any, Callable[[Any], object] | None]
        watched = bool(watch) and any(s in watch for s in (*plan.exited, *plan.entered))
        if not watched and not plan.notifies:
            head = (1, None, None, None)
        elif not watched and len(plan.notifies) == 1:
            action = plan.notifies[0][1]
            route = self._routes.get(action.invoke)
            note = Notification(
                self._name, action.invoke, action.name, action.method, action.event, None
            )
            call = route[0].update if route is not None else _nobody
            head = (1 + _ONE_INVOKE, call, note, _with_data(call, note))
        else:  # watchers hear it between notifications; several notifications in order
            run = partial(self._run, self._program(plan))
            head = (1, run, None, run)
        rec = recorded(plan.step, watch, self._name)
        entry: _Call = (*head, rec, self._static(rec), Builder())
        calls[plan] = entry
        return entry

    def _static(self, rec: Recorded) -> Static | None:
        """The plan's step record without running it (see :data:`Static`), when it can be."""
        items, end = rec
        if not items:
            return (), end
        if len(items) > 1 or items[0][0] is not None:
            return None
        _, note, at = items[0]
        route = self._routes.get(note.invoke)
        if route is None:
            return (None,), at
        return ((update_api(route[0], note.invoke),), at) if not route[1] else None

    def _program(self, plan: Plan) -> _Program:
        """The calls of ``plan``'s step in order: ``(watcher method, state)`` for the
        watched states exited and entered, ``(None, notify)`` for each notification."""
        watch = self._watch
        program: list[tuple[Callable[[str], object] | None, Any]] = []
        for micro in plan.step.microsteps:
            for s in micro.exited:
                program.extend((w.exited, s) for w in watch.get(s, ()))
            for s in micro.entered:
                program.extend((w.entered, s) for w in watch.get(s, ()))
            program.extend((None, a) for a in micro.actions if isinstance(a, Notify))
        return tuple(program)

    def _run(self, program: _Program, data: Any) -> None:
        """Run a plan's program: each notification counted, routed when it is due."""
        for fn, arg in program:
            if fn is not None:
                fn(arg)
                continue
            self._counts += _ONE_INVOKE
            route = self._routes.get(arg.invoke)
            if route is not None:
                note = (self._name, arg.invoke, arg.name, arg.method, arg.event, data)
                route[0].update(_NEW(Notification, note))

    def _unhandled(
        self, event: str, data: Any, reason: IgnoreReason, now: float, snap: Snapshot
    ) -> None:
        for callback in self._steppers:
            callback(event, data, reason)
        ignore = self.policy == "ignore" or reason is Unhandled.DECLARED_IGNORED
        if self._listeners:
            kind = EventIgnored if ignore else EventRejected
            self.emit(kind(self._name, now, event, reason))
        elif self._recorders:  # only step listeners: one step record (recording.py)
            tail = _Tail(reason, not ignore)
            self._hand(StepRecord(self._name, now, event, data, None, (), tail))
        if ignore:
            return
        active = ", ".join(sorted(snap.active))
        raise UnhandledEventError(
            f"{self._name}: event {event!r} is not handled in [{active}] ({reason}); "
            "add a transition or declare it ignored in the state table, or use policy 'ignore'"
        )

    def _perform(self, decision: Step, data: Any, now: float, listening: bool) -> None:
        name = self._name
        watch = self._watch
        for micro in decision.microsteps:
            if listening:
                took = taken(micro)
                self.emit(MicrostepTaken(name, now, micro.event, micro.exited, took, micro.entered))
            if watch:  # after the microstep's record (rule 3 of records.py)
                for s in micro.exited:
                    for w in watch.get(s, ()):
                        w.exited(s)
                for s in micro.entered:
                    for w in watch.get(s, ()):
                        w.entered(s)
            for action in micro.actions:
                if isinstance(action, Notify):
                    self._notify(action, data, now, listening)
        if decision.final and not self._finished:
            self._finish(now, listening)

    def _hand(self, step: StepRecord) -> None:
        """Give ``step`` to the step listeners (:mod:`statectl.run.runtime.recording`)."""
        raise NotImplementedError

    def _finish(self, now: float, listening: bool) -> None:
        self._finished = True
        for w in self._watchers:
            w.finished()
        if listening:
            self.emit(Finished(self._name, now))

    def _notify(self, action: Notify, data: Any, now: float, listening: bool) -> None:
        self._counts += _ONE_INVOKE
        a, name = action, self._name
        if listening:
            self.emit(InvokeIssued(name, now, a.invoke, a.name, a.method, a.event))
        route = self._routes.get(a.invoke)
        if route is None:
            return
        observer, logging = route
        note = _NEW(Notification, (name, a.invoke, a.name, a.method, a.event, data))
        if not listening:
            observer.update(note)
        elif not logging:
            observer.update(note)
            self.emit(ObserverCalled(name, now, a.method, update_api(observer, a.invoke)))
        else:
            before = api_count(observer)
            observer.update(note)
            for call in api_calls_since(observer, before):
                self.emit(ObserverCalled(name, now, a.method, str(call)))


def recorded(step: Step, watch: Mapping[str, tuple[StateWatcher, ...]], device: str) -> Recorded:
    """A step's watcher calls and notifications in order, each with the typed records
    before it (one per microstep, one per ``InvokeIssued``, itself included), and the
    count after the last of them. A notification comes as the :class:`Notification`
    without data ``device`` sends."""
    items: list[tuple[Callable[[Any], object] | None, Any, int]] = []
    at = 1  # EventReceived
    for micro in step.microsteps:
        at += 1  # MicrostepTaken; the watchers hear it after that record
        for s in micro.exited:
            items.extend((w.exited, s, at) for w in watch.get(s, ()))
        for s in micro.entered:
            items.extend((w.entered, s, at) for w in watch.get(s, ()))
        for a in micro.actions:
            if isinstance(a, Notify):
                at += 1
                note = Notification(device, a.invoke, a.name, a.method, a.event, None)
                items.append((None, note, at))
    return tuple(items), at
