"""One running device bound to the journal: accepted events in, every step out, resume.

Rules:
1. Events from outside go through :meth:`JournalledDevice.post`: the journal
   commits the inbox row first and only then posts the event to the Subject, so
   the device acts only on accepted (durable) events.
2. Every event the Subject processes, whoever posted it, becomes one step row
   with the snapshot it left. The rows come from a step listener
   (:meth:`Subject.on_step`), not from trace records, so journalling keeps the
   Subject's fast path. The step of an inbox event carries its ``seq``: the
   Subject processes its queue in order, so the next step whose event matches
   the oldest delivered inbox event (same name, the same data object or equal
   data) is that event. Events that match are interchangeable, so the
   attribution cannot change a replay.
3. On resume the device takes up its last journalled snapshot (``restore``),
   then takes its declared recovery transitions, then gets the accepted events
   it had not processed, in ``seq`` order; all before any new event.
4. Exactly once in the journal, at least once at the device: an event processed
   but not yet journalled when the process died is processed again on resume,
   and its API call may repeat. That is what recovery rules are for.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import Any

from statectl.errors import StatectlError
from statectl.journal.read import JournalReader
from statectl.journal.recovery import RecoveryRule
from statectl.journal.store import Journal, StepKind, Ticket
from statectl.journal.subjects import restore_subject
from statectl.runtime.subject import Subject

__all__ = ["JournalledDevice", "restore_subject"]

_RECOVERY = -1  # the seq slot of a recovery event: it has no inbox row


class JournalledDevice:
    """A Subject whose accepted events and steps go to a :class:`Journal`."""

    def __init__(
        self,
        subject: Subject,
        journal: Journal,
        *,
        source: str = "",
        wake: Callable[[], object] | None = None,
    ) -> None:
        self.subject = subject
        self.wake = wake  # tells the owner an accepted event is queued
        self.journal = journal
        self.name = subject.name
        self._expect: deque[tuple[int, str, Any]] = deque()
        self._lock = threading.Lock()
        self.recovered: tuple[str, ...] = ()  # recovery events taken on resume
        self.redelivered = 0  # accepted events processed on resume
        journal.register(self.name, subject.chart.name, source, dict(subject.data))
        self._unlisten = subject.on_step(self._on_step)

    # -- in ------------------------------------------------------------------------------

    def post(self, event: str, data: Any = None) -> Ticket:
        """Accept ``event``: it reaches the device once the journal has committed it."""
        if not isinstance(event, str):
            raise StatectlError(f"an event name must be a str (got {event!r})")
        return self.journal.accept(
            self.name, event, data, lambda seq: self._deliver(seq, event, data)
        )

    def _deliver(self, seq: int, event: str, data: Any) -> None:
        with self._lock:
            self._expect.append((seq, event, data))
            self.subject.post(event, data)
        if self.wake is not None:
            self.wake()

    # -- out -----------------------------------------------------------------------------

    def _on_step(self, event: str, data: Any, outcome: str) -> None:
        """Rule 2: journal the step the Subject just took, with its inbox ``seq`` if any."""
        inbox = 0
        expect = self._expect
        if expect:
            with self._lock:
                if expect:
                    seq, e, d = expect[0]
                    if e == event and (d is data or d == data):
                        expect.popleft()
                        inbox = seq
        snapshot = self.subject.snapshot
        assert snapshot is not None
        kind = StepKind.RECOVERY if inbox == _RECOVERY else StepKind.EVENT
        self.journal.record(
            self.name,
            kind,
            snapshot,
            time_=self.subject.clock.now(),
            event=event,
            data=data,
            inbox=inbox if inbox > 0 else None,
            outcome=outcome,
        )

    # -- coming up -----------------------------------------------------------------------

    def start(self) -> None:
        """Enter the initial configuration and journal it."""
        self.subject.start()
        self._record_now(StepKind.START)

    def resume(self, reader: JournalReader, rules: tuple[RecoveryRule, ...] = ()) -> bool:
        """Come back as the journal left this device; False (and a fresh start) if it never ran.

        Call before the owner processes anything; then drain the Subject.
        """
        last = reader.last_step(self.name)
        if last is None:
            self.start()
            pending = reader.pending(self.name)
        else:
            restore_subject(self.subject, last.snapshot)
            self._record_now(StepKind.RESTORE)
            pending = reader.pending(self.name)
            active = self.subject.configuration
            taken = []
            for rule in rules:
                if rule.state in active:
                    with self._lock:
                        self._expect.append((_RECOVERY, rule.event, rule.data))
                        self.subject.post(rule.event, rule.data)
                    taken.append(rule.event)
            self.recovered = tuple(taken)
        for row in pending:
            self._deliver(row.seq, row.event, row.data)
        self.redelivered = len(pending)
        return last is not None

    def _record_now(self, kind: StepKind) -> None:
        snapshot = self.subject.snapshot
        assert snapshot is not None
        self.journal.record(self.name, kind, snapshot, time_=self.subject.clock.now())

    def close(self) -> None:
        self._unlisten()
