"""Step records: one object per event for the listeners that asked for records.

A :meth:`Recording.listen_steps` listener gets a
:class:`~statectl.run.runtime.records.StepRecord` per event instead of ~6 typed records:
when nobody listens the old way (:meth:`~statectl.run.runtime.subject.Subject.listen`),
the Subject performs the step as it does unheard and keeps only what the typed
records would need later: the kernel's step, the API calls each notification made,
and anything recorded meanwhile (a monitor starting) with its place among them.
The typed records are built when the listener asks for them. With an old-way
listener attached as well, records are built as they happen and a step listener
gets each as a step record of its own (:meth:`StepRecord.of`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

from statectl.front.observers import Notification
from statectl.kernel.semantics import Plan, Step
from statectl.run.runtime.perform import (
    _NEW,
    _ONE_INVOKE,
    Performer,
    Recorded,
    _Call,
    api_calls_since,
    api_count,
    recorded,
)
from statectl.run.runtime.records import Builder, Record, StepRecord, _Made, _Tail, update_api

__all__ = ["Recording", "StepListener"]

#: Hears one :class:`StepRecord` per event (and one per record made outside an event).
StepListener = Callable[[StepRecord], None]


#: A recorded step before anything was recorded meanwhile (a list is made only then).
_NONE_YET: list[tuple[int, Record]] = []


class Recording(Performer):
    """The Subject's step-record half; the slots it writes live here, the rest on the Subject."""

    __slots__ = ("_cursor", "_handing", "_later", "_recorders", "_recording")

    _recorders: tuple[StepListener, ...]
    _recording: list[tuple[int, Record]] | None  # records made during the step being recorded
    _cursor: int  # typed records the step being recorded has made so far
    _handing: bool
    _later: list[StepRecord] | None

    def listen_steps(self, callback: StepListener) -> Callable[[], None]:
        """Receive one :class:`StepRecord` per event from now on; returns the undo.

        Cheaper than :meth:`listen` when the typed records are not all read: they are
        built only when ``record.records`` (or iterating the record) asks for them.
        """
        self._recorders = (*self._recorders, callback)

        def off() -> None:
            self._recorders = tuple(c for c in self._recorders if c is not callback)

        return off

    def emit(self, record: Record) -> None:
        """Deliver ``record``: into the step being recorded, else to every listener, after
        any record being delivered now (a listener that emits is heard after it)."""
        extras = self._recording
        if extras is not None:  # made during a recorded step: kept in its place
            if extras is _NONE_YET:
                extras = self._recording = []
            extras.append((self._cursor, record))
            return
        if self._recorders:
            self._hand(StepRecord.of(record))
        if not self._listeners:
            return
        if self._emitting:  # a listener emitted: delivered after the current record
            pending = self._pending
            if pending is None:
                pending = self._pending = deque()
            pending.append(record)
            return
        self._emitting = True
        try:
            for callback in self._listeners:
                callback(record)
            pending = self._pending
            while pending:
                r = pending.popleft()
                for callback in self._listeners:
                    callback(r)
        except BaseException:
            if self._pending:
                self._pending.clear()
            raise
        finally:
            self._emitting = False

    def _hand_later(self) -> None:
        """Hand the step records that listeners made while one was being handed."""
        later = self._later
        while later:
            self._hand(later.pop(0))

    def _hand(self, step: StepRecord) -> None:
        """Give ``step`` to the step listeners, after any being given now."""
        if self._handing:
            later = self._later
            if later is None:
                later = self._later = []
            later.append(step)
            return
        self._handing = True
        done = False
        try:
            for callback in self._recorders:
                callback(step)
            later = self._later
            while later:
                step = later.pop(0)
                for callback in self._recorders:
                    callback(step)
            done = True
        finally:
            self._handing = False
            if not done and self._later:
                self._later.clear()

    def _record_plan(self, event: str, data: Any, plan: Plan, entry: _Call) -> None:
        """A planned step for step listeners: the plan path's own calls, then one record.

        When the plan's record is known before it runs (:data:`Static`), the step is
        performed exactly as unheard and the record is made from what was known;
        otherwise :meth:`_record_step` runs it call by call.
        """
        now = self.clock.now()
        static = entry[5]
        if static is None:
            self._counts += 1
            self._record_step(event, data, plan.step, now, entry[4], entry[6])
            return
        made, at = static
        self._recording = _NONE_YET  # emit() makes the list if anything is recorded meanwhile
        self._cursor = at
        final = False
        try:
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
                final = True
                self._finished = True
                self._cursor = entry[4][1] + sum(m is not None for m in made)
                for w in self._watchers:
                    w.finished()
        except BaseException:  # the records made until then end at the cursor
            extras = self._recording
            self._recording = None
            failed = _Tail(None, False, final, self._cursor, extras or ())
            self._hand(
                StepRecord(self._name, now, event, data, plan.step, made, failed, None, entry[6])
            )
            raise
        extras = self._recording
        self._recording = None
        tail = _Tail(None, False, final, None, extras) if extras or final else None
        record = StepRecord(self._name, now, event, data, plan.step, made, tail, None, entry[6])
        recorders = self._recorders
        if len(recorders) != 1 or self._handing:
            self._hand(record)
            return
        self._handing = True  # _hand(), for the usual one listener
        try:
            recorders[0](record)
        except BaseException:
            if self._later:
                self._later.clear()
            raise
        finally:
            self._handing = False
        if self._later:
            self._hand_later()

    def _record_step(
        self,
        event: str,
        data: Any,
        decision: Step,
        now: float,
        program: Recorded | None = None,
        builder: Builder | None = None,
    ) -> None:
        """Perform a committed step as unheard, and hand step listeners one record of it.

        ``program`` (the plan's, else worked out here) lists the watcher calls and the
        notifications in the order of :meth:`_perform`, each with the number of typed
        records before it; a record made meanwhile (a monitor's ``MonitorStarted``)
        takes that place among them. Each observer's API calls add to the count.
        """
        items, end = program if program is not None else recorded(decision, self._watch, self._name)
        made: list[_Made] = []
        self._recording = _NONE_YET  # emit() makes the list if anything is recorded meanwhile
        self._cursor = 1  # EventReceived
        shift = 0  # ObserverCalled records so far
        final = False
        failed = True
        try:
            for fn, arg, at in items:
                self._cursor = at + shift
                if fn is not None:
                    fn(arg)
                    continue
                self._counts += _ONE_INVOKE
                route = self._routes.get(arg.invoke)
                if route is None:
                    made.append(None)
                    continue
                observer, logging = route
                if data is not None:  # arg is the notification without data
                    arg = _NEW(Notification, (*arg[:-1], data))  # see perform._with_data
                if logging:
                    before = api_count(observer)
                    observer.update(arg)
                    calls = tuple(api_calls_since(observer, before))
                    made.append(calls)
                    shift += len(calls)
                else:
                    observer.update(arg)
                    made.append(update_api(observer, arg.invoke))
                    shift += 1
            if decision.final and not self._finished:
                final = True
                self._finished = True
                self._cursor = end + shift
                for w in self._watchers:
                    w.finished()
            failed = False
        finally:
            extras = self._recording
            self._recording = None
            tail = None
            if extras or final or failed:  # a failed step's records end at the cursor
                tail = _Tail(None, False, final, self._cursor if failed else None, extras or ())
            self._hand(
                StepRecord(self._name, now, event, data, decision, made, tail, None, builder)
            )
