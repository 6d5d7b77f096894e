"""One running device bound to the journal: accepted events in, every step out, resume.

Rules:
1. Events from outside go through :meth:`JournalledDevice.post`, which queues
   the inbox row and returns its ticket. Under ``Guarantee.PROMPT`` it posts the
   event to the Subject at once, in the same critical section, so a device's
   events reach it in ``seq`` order and its step row is queued after its inbox
   row; the inbox row is held (it does not wake the writer) until the next row
   is queued, normally that step, or someone asks the ticket. Under
   ``Guarantee.DURABLE_FIRST`` the journal commits the inbox row first and only
   then posts the event, so the device acts only on accepted (durable) events.
2. Every event the Subject processes, whoever posted it, becomes one step row
   with the snapshot it left. The rows come from a step listener
   (:meth:`Subject.on_step`), not from trace records, so journalling keeps the
   Subject's fast path. The step of an inbox event carries its ``seq``: the
   Subject processes its queue in order, so the next step whose event matches
   the oldest delivered inbox event (same name, the same data object or equal
   data) is that event. Events that match are interchangeable, so the
   attribution cannot change a replay.
3. On resume the device takes up its last journalled snapshot (``restore``),
   then takes its declared recovery rules, in the table's order, then gets the
   accepted events it had not processed, in ``seq`` order; all before any new
   event. An event rule posts its event. A redo rule finds the journalled step
   that entered its state (:meth:`JournalReader.entering_step`), recomputes it
   purely from the snapshot before it with :func:`statectl.kernel.semantics.step` (the
   datamodel from the ``devices`` row), checks that it enters the state, and
   has the Subject issue only that step's notifications again
   (:meth:`Subject.reissue`, on the owner, in queue order), journalled as a
   ``recovery`` step with outcome ``redo`` and the redone event. Without an
   entering step (the device started in the state, or the journal begins after
   it) the rule is skipped and :attr:`JournalledDevice.recovered` says so.
   The ``restore`` step is committed before any of that: a journal that cannot
   be written (a full disk) fails the resume before anything reaches the device.
4. Exactly once in the journal, at least once at the device: an accepted event
   processed but without a committed step when the process died is processed
   again on resume, and its API call may repeat. Under ``PROMPT`` an event
   processed before its inbox row was committed is not in the journal at all
   (it was never acknowledged); the device resumes from the last committed
   step. That is what recovery rules are for.
5. A step that sends events on (``sends``, a cell's links) is journalled with
   their inbox rows in one commit (the store's rule 6), so a crash loses both
   or neither; the events then reach their devices as accepted events do (rule
   1), with the target devices' locks held so each device still gets its events
   in ``seq`` order.
6. The device's ``devices`` row (chart, file, datamodel: what ``journal replay``
   runs) is written when it starts or resumes, not when it is bound: a resume
   refused because the journal was written by another chart (:meth:`misfit`:
   its last snapshot names states this chart lacks) leaves the journal as it was.
7. A command the System's door refused (its commands policy) is journalled by
   :meth:`JournalledDevice.refused` as an ``event`` step with no inbox row and the
   outcome ``refused: ORIGIN``, with the snapshot it left unchanged; the System calls it
   as the owner, so the row follows the device's steps. Replay passes over it.
8. An operator's acknowledgement of an alarm (an OPC UA ``Acknowledge``) is journalled
   the same way by :meth:`JournalledDevice.acknowledged`: an ``event`` step named after
   the fault, with the comment as its data and the outcome ``acknowledged: ORIGIN``;
   the snapshot is unchanged and replay passes over it.
"""

from __future__ import annotations

import contextlib
import threading
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Notify
from statectl.kernel.semantics import Outcome, Step, step
from statectl.run.journal.assigned import replay_assigned_data
from statectl.run.journal.device_file import RecoveryRule
from statectl.run.journal.format import Guarantee, JournalError, StepKind, encode_data
from statectl.run.journal.read import ACKNOWLEDGED, REDO, REFUSED, JournalReader, StepRow
from statectl.run.journal.store import Journal, Send, Ticket
from statectl.run.journal.subjects import restore_subject
from statectl.run.runtime.eventdata import check_posted
from statectl.run.runtime.subject import Subject

__all__ = ["JournalledDevice"]

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
        # Posters append (under _lock, so seq order is queue order); only the owner
        # pops, in _on_step, without the lock: deque appends and pops are atomic, and
        # a poster never waits for the owner's step.
        self._expect: deque[tuple[int, str, Any]] = deque()
        self._lock = threading.Lock()
        #: The events each step sends on (a cell's links), asked after the step (rule 5).
        self.sends: Callable[[], Sequence[tuple[JournalledDevice, str]]] | None = None
        #: What resume's recovery rules did: event names, "redo Error()" for a redo,
        #: "redo S: nothing to redo" for a redo rule skipped (rule 3).
        self.recovered: tuple[str, ...] = ()
        self.redelivered = 0  # accepted events processed on resume
        self.source = source  # registered at start or resume (rule 6), not before
        self._unlisten = subject.on_step(self._on_step)

    # -- in ------------------------------------------------------------------------------

    def post(
        self,
        event: str,
        data: Any = None,
        *,
        note: tuple[str, str] | None = None,
        then: Callable[[Outcome], object] | None = None,
    ) -> Ticket:
        """Accept ``event`` (rule 1); the ticket turns durable once its inbox row is committed.

        ``note``: a ``meta`` row committed with the inbox row (``Journal.accept``);
        ``then(outcome)``: on the owner once the device ran it (``Subject.post``).
        """
        if not isinstance(event, str):
            raise StatectlError(f"an event name must be a str (got {event!r})")
        check_posted(self.subject, event, data)  # refused before the journal accepts it
        journal = self.journal
        if journal.guarantee is Guarantee.DURABLE_FIRST:
            return journal.accept(
                self.name, event, data, lambda seq: self._deliver(seq, event, data, then), note=note
            )
        with self._lock:  # seq order is this device's queue order: resume relies on it
            ticket = journal.accept(self.name, event, data, hold=True, note=note)
            self._expect.append((ticket.seq, event, data))
            self.subject.post(event, data, then=then)
        if self.wake is not None:
            self.wake()
        return ticket

    def _deliver(
        self, seq: int, event: str, data: Any, then: Callable[[Outcome], object] | None = None
    ) -> None:
        with self._lock:
            self._expect.append((seq, event, data))
            self.subject.post(event, data, then=then)
        if self.wake is not None:
            self.wake()

    # -- out -----------------------------------------------------------------------------

    def _on_step(self, event: str, data: Any, outcome: str) -> None:
        """Rule 2: journal the step the Subject just took, with its inbox ``seq`` if any."""
        inbox = 0
        expect = self._expect
        if expect:
            seq, e, d = expect[0]
            if e == event and (d is data or d == data):
                expect.popleft()
                inbox = seq
        snapshot = self.subject.snapshot
        assert snapshot is not None
        kind = StepKind.RECOVERY if inbox == _RECOVERY else StepKind.EVENT
        sends = self.sends() if self.sends is not None else ()
        targets = self._lock_targets(sends) if sends else ()  # rule 5
        hand_over = bool(sends) and self.journal.guarantee is Guarantee.PROMPT
        try:
            seqs = self.journal.record(
                self.name,
                kind,
                snapshot,
                time_=self.subject.clock.now(),
                event=event,
                data=data,
                inbox=inbox if inbox > 0 else None,
                outcome=outcome,
                sends=self._sends(sends) if sends else (),
            )
            if hand_over:  # under DURABLE_FIRST the writer delivers them after the commit
                for (d, e), seq in zip(sends, seqs, strict=True):
                    d._expect.append((seq, e, None))
                    d.subject.post(e)
        finally:
            for d in targets:
                d._lock.release()
        for d in targets if hand_over else ():
            if d.wake is not None:
                d.wake()

    @staticmethod
    def _lock_targets(sends: Sequence[tuple[JournalledDevice, str]]) -> list[JournalledDevice]:
        """Rule 5: hold the target devices' locks, in one order for every thread (by name),
        so each gets the events sent to it in ``seq`` order; posters take one lock each."""
        targets = [d for _, d in sorted({d.name: d for d, _ in sends}.items())]
        for d in targets:
            d._lock.acquire()
        return targets

    def _sends(self, sends: Sequence[tuple[JournalledDevice, str]]) -> list[Send]:
        """The journal's Send records; under DURABLE_FIRST each delivers after the commit."""
        prompt = self.journal.guarantee is Guarantee.PROMPT
        return [Send(d.name, e, None, None if prompt else d._delivery(e)) for d, e in sends]

    def _delivery(self, event: str) -> Callable[[int], object]:
        return lambda seq: self._deliver(seq, event, None)

    # -- coming up -----------------------------------------------------------------------

    def _register(self) -> None:
        """Note the device's chart and file (rule 6): only once it starts or resumes."""
        s = self.subject
        self.journal.register(self.name, s.chart.name, self.source, dict(s.data))

    def misfit(self, reader: JournalReader) -> str | None:
        """Why the device's last journalled snapshot is not one of its chart (rule 6)."""
        last = reader.last_step(self.name)
        if last is None:
            return None
        known = self.subject.machine.order
        snap = last.snapshot
        named = set(snap.active) | {s for _, states in snap.history for s in states}
        named |= {h for h, _ in snap.history}
        if snap.previous is not None:
            named.add(snap.previous)
        unknown = sorted(named - known.keys())
        if not unknown:
            return None
        row = reader.device(self.name)
        written = f" ({row.source})" if row is not None and row.source else ""
        return (
            f"{self.name} was journalled with a chart{written} that has state(s) "
            f"{', '.join(unknown)}, which {self.source or self.subject.chart.name} does not"
        )

    def start(self) -> None:
        """Enter the initial configuration and journal it."""
        self._register()
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
            self._register()
            restore_subject(self.subject, last.snapshot)
            replay_assigned_data(self.subject, reader, last.id)  # journal/assigned.py
            self._record_now(StepKind.RESTORE)
            # the journal can be written (not full, not read-only) before anything reaches
            # the device again: a recovery event or a redelivered one
            self.journal.flush()
            pending = reader.pending(self.name)
            active = self.subject.configuration
            taken = []
            for rule in rules:
                if rule.state not in active:
                    continue
                if rule.redo:
                    taken.append(self._redo(reader, rule.state, last.id))
                    continue
                with self._lock:
                    self._expect.append((_RECOVERY, rule.event, rule.data))
                    self.subject.post(rule.event, rule.data)
                taken.append(rule.event)
            self.recovered = tuple(taken)
        for row in pending:
            self._deliver(row.seq, row.event, row.data)
        self.redelivered = len(pending)
        return last is not None

    def _redo(self, reader: JournalReader, state: str, upto: int) -> str:
        """Rule 3's redo: queue the entering step's notifications; what ``recovered`` says."""
        found = reader.entering_step(self.name, state, upto)
        if found is None:
            return f"redo {state}: nothing to redo"
        before, entering = found
        assert entering.event is not None  # entering_step returns handled event steps
        row = reader.device(self.name)
        datamodel = row.data if row is not None and isinstance(row.data, dict) else {}
        decision = step(
            self.subject.machine, before.snapshot, entering.event, datamodel, entering.data
        )
        if state not in decision.entered:
            return f"redo {state}: step {entering.id} ({entering.event}) does not enter it"
        notifies = tuple(a for a in decision.actions if isinstance(a, Notify))
        if not notifies:
            return f"redo {state}: nothing to redo"
        self.subject.call_soon(lambda: self._reissue(state, decision, entering))
        return "redo " + ", ".join(f"{a.method}()" for a in notifies)

    def _reissue(self, state: str, decision: Step, entering: StepRow) -> None:
        """On the owner: issue the entering step's notifications again and journal it.

        An earlier rule's event may have left ``state`` meanwhile: then there is
        nothing to redo.
        """
        if state not in self.subject.configuration:
            return
        self.subject.reissue(decision, entering.data)
        snapshot = self.subject.snapshot
        assert snapshot is not None
        self.journal.record(
            self.name,
            StepKind.RECOVERY,
            snapshot,
            time_=self.subject.clock.now(),
            event=entering.event,
            data=entering.data,
            outcome=REDO,
        )

    def refused(self, event: str, data: Any, origin: str) -> None:
        """Rule 7: journal a command refused at the door; a journal that cannot take the
        row any more fails elsewhere, and the command is refused all the same."""
        self._aside(event, data, f"{REFUSED}: {origin}")

    def acknowledged(self, fault: str, comment: str, origin: str) -> None:
        """Rule 8: journal an alarm's acknowledgement, on the owner (after the fault's step)."""
        self._aside(fault, {"comment": comment} if comment else None, f"{ACKNOWLEDGED}: {origin}")

    def _aside(self, event: str, data: Any, outcome: str) -> None:
        """A step row that ran nothing (rules 7 and 8), with the snapshot as it is."""
        snapshot = self.subject.snapshot
        if snapshot is None:  # not started: no state to journal it with
            return
        try:
            encode_data(data)
        except StatectlError:
            data = None  # the refusal is kept, data that JSON cannot hold is not
        with contextlib.suppress(JournalError):
            self.journal.record(
                self.name, StepKind.EVENT, snapshot, time_=self.subject.clock.now(),
                event=event, data=data, outcome=outcome,
            )  # fmt: skip

    def _record_now(self, kind: StepKind) -> None:
        snapshot = self.subject.snapshot
        assert snapshot is not None
        self.journal.record(self.name, kind, snapshot, time_=self.subject.clock.now())

    def close(self) -> None:
        self._unlisten()
