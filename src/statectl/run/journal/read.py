"""Reading a journal: rows by device and time, JSON Lines export, deterministic replay.

Rules:
1. Readers never write; they open the database read-only beside a running writer
   (WAL lets both work at once) and see what is committed.
2. Filters are the device name and a wall-clock window ``since <= wall < until``
   (seconds since the epoch); rows come in the order they were written.
3. Replay runs the recorded events against the model on a :class:`SimClock`:
   each device starts fresh, time follows the
   journalled device clock (shifted so that no restart goes back in time), and
   each event and recovery step is posted and processed (an accepted event
   applied by two steps is refused: it ran twice), except a recovery
   ``redo`` step (:data:`REDO`): it re-issued device calls and changed no state,
   so it is not posted, nor is a ``refused`` step (:data:`REFUSED`, a command the
   System's door refused) or an ``acknowledged`` one (:data:`ACKNOWLEDGED`, an
   operator acknowledged an alarm). The
   snapshot the model reaches must equal the journalled one after every step
   (for a redo: the one before it), and a ``restore`` must find the device where
   the run before it left it; every difference is reported as a
   :class:`Mismatch`. No driver is attached, so a replay never moves hardware.
4. The step that entered a state (:meth:`JournalReader.entering_step`) is found
   by walking a device's steps back from the newest while the state is active:
   restores, redo steps and steps that did not leave the state are passed over;
   the entering step is the handled event step (from the inbox, or a recovery
   event) whose predecessor's snapshot did not have the state active. A start
   in the state, or a journal that begins inside it, has none.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TextIO

from statectl.kernel.model import Chart
from statectl.kernel.semantics import Outcome, Snapshot
from statectl.run.journal.check import check_journal, connect_ro, sqlite_problem
from statectl.run.journal.format import JournalError, StepKind, decode_snapshot
from statectl.run.journal.subjects import restore_subject
from statectl.run.runtime.clock import SimClock
from statectl.run.runtime.hooks import Listener
from statectl.run.runtime.subject import Subject

__all__ = [
    "ACKNOWLEDGED",
    "REDO",
    "REFUSED",
    "DeviceRow",
    "InboxRow",
    "JournalReader",
    "JournalSource",
    "Mismatch",
    "ReplayResult",
    "StepRow",
    "export_jsonl",
    "replay",
]


#: The outcome of a recovery step that re-issued device calls and changed no state.
REDO = "redo"
#: The outcome of a command the System's door refused (``refused: ORIGIN``): nothing ran.
REFUSED = "refused"
#: The outcome of an alarm's acknowledgement (``acknowledged: ORIGIN``): nothing ran.
ACKNOWLEDGED = "acknowledged"


@dataclass(frozen=True, slots=True)
class DeviceRow:
    name: str
    chart: str
    source: str
    data: Any


@dataclass(frozen=True, slots=True)
class InboxRow:
    """An accepted event."""

    seq: int
    device: str
    wall: float
    event: str
    data: Any


@dataclass(frozen=True, slots=True)
class StepRow:
    """A step a device took, with the snapshot it left."""

    id: int
    device: str
    kind: StepKind
    inbox: int | None
    wall: float
    time: float
    event: str | None
    data: Any
    outcome: str
    snapshot: Snapshot

    def to_json(self) -> dict[str, Any]:
        return {
            "type": "step",
            "id": self.id,
            "device": self.device,
            "kind": self.kind.value,
            "inbox": self.inbox,
            "wall": self.wall,
            "time": self.time,
            "event": self.event,
            "data": self.data,
            "outcome": self.outcome,
            "active": sorted(self.snapshot.active),
            "previous": self.snapshot.previous,
            "history": {k: list(v) for k, v in self.snapshot.history},
        }


def _step(row: tuple[Any, ...]) -> StepRow:
    rid, device, kind, inbox, wall, t, event, data, outcome, active, history, previous = row
    try:
        return StepRow(
            rid, device, StepKind(kind), inbox, wall, t, event, json.loads(data), outcome,
            decode_snapshot(active, history, previous),
        )  # fmt: skip
    except (ValueError, TypeError, IndexError, KeyError) as exc:
        raise JournalError(f"step {rid} cannot be read ({type(exc).__name__}: {exc})") from None


def _json(text: Any, what: str) -> Any:
    try:
        return json.loads(text)
    except (ValueError, TypeError) as exc:
        raise JournalError(f"{what} cannot be read: its data is not JSON ({exc})") from None


def _datamodel(text: Any, what: str) -> dict[str, Any] | None:
    """A ``devices`` row's datamodel: a JSON object or null, as journals write it."""
    data = _json(text, what)
    if data is not None and not isinstance(data, dict):
        raise JournalError(
            f"{what} cannot be read: its data is not a JSON object or null ({text!r:.80})"
        )
    return data


def _filters(
    mark: str,
    device: str | None,
    since: float | None,
    until: float | None,
    after: int | None = None,
    upto: int | None = None,
) -> tuple[list[str], list[Any]]:
    """Rule 2's filters and the step id bounds as SQL conditions, ``mark`` standing for each
    value (``?`` in SQLite, ``%s`` in PostgreSQL), and their values: every reader's window."""
    given = [
        (clause, value)
        for clause, value in (
            ("device = ", device),
            ("wall >= ", since),
            ("wall < ", until),
            ("id > ", after),
            ("id <= ", upto),
        )
        if value is not None
    ]
    return [clause + mark for clause, _ in given], [value for _, value in given]


def _where(clauses: list[str]) -> str:
    return (" WHERE " + " AND ".join(clauses)) if clauses else ""


def _entering(newest_first: Iterable[StepRow], state: str) -> tuple[StepRow, StepRow] | None:
    """Rule 4 over one device's steps, newest first: every journal's ``entering_step``."""
    later: StepRow | None = None
    for row in newest_first:
        if state not in row.snapshot.active:
            if later is None or later.outcome != Outcome.HANDLED or later.event is None:
                return None  # not active at the newest step, or entered by a restore
            if later.kind in (StepKind.EVENT, StepKind.RECOVERY):
                return row, later
            return None
        if row.kind is StepKind.START:
            return None  # the device started in the state
        later = row
    return None  # the journal begins inside the state


class JournalSource(Protocol):
    """What show, export and replay read: a journal file or a shipped one (journal/pg.py)."""

    def devices(self) -> tuple[DeviceRow, ...]: ...

    def steps(
        self,
        device: str | None = None,
        since: float | None = None,
        until: float | None = None,
        after: int | None = None,
        upto: int | None = None,
    ) -> Iterator[StepRow]: ...

    def inbox(
        self, device: str | None = None, since: float | None = None, until: float | None = None
    ) -> Iterator[InboxRow]: ...

    def close(self) -> None: ...

    def __enter__(self) -> JournalSource: ...

    def __exit__(self, *_: object) -> None: ...


class JournalReader:
    """Read-only access to a journal file."""

    def __init__(self, path: str | Path, *, check: bool = True) -> None:
        """Open ``path`` read-only; ``check``: refuse a journal that cannot be trusted first.

        Raises :class:`JournalError` (no journal, cannot open) or its
        :class:`~statectl.run.journal.check.JournalDamaged` (journal/check.py).
        """
        p = Path(path)
        if check:
            check_journal(p)
        elif not p.exists():
            raise JournalError(f"no journal at {p}")
        try:
            self._db = connect_ro(p)
            self._db.execute("SELECT 1 FROM steps LIMIT 1")
        except sqlite3.Error as exc:
            raise JournalError(f"journal {p}: cannot read it: {sqlite_problem(exc)}") from None
        self.path = p

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> JournalReader:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def devices(self) -> tuple[DeviceRow, ...]:
        rows = self._db.execute("SELECT name, chart, source, data FROM devices ORDER BY name")
        return tuple(DeviceRow(n, c, s, _datamodel(d, f"device {n}")) for n, c, s, d in rows)

    def device(self, name: str) -> DeviceRow | None:
        """The ``devices`` row of ``name`` (its chart, file and datamodel), if it ran."""
        row = self._db.execute(
            "SELECT name, chart, source, data FROM devices WHERE name = ?", (name,)
        ).fetchone()
        if row is None:
            return None
        return DeviceRow(row[0], row[1], row[2], _datamodel(row[3], f"device {row[0]}"))

    def entering_step(
        self, device: str, state: str, upto: int | None = None
    ) -> tuple[StepRow, StepRow] | None:
        """``(before, entering)``: the step that entered ``state`` and the one before it.

        Walks back from the newest step (or ``upto``) per rule 4; ``None`` when
        ``state`` is not active there, or nothing journalled entered it.
        """
        sql = "SELECT * FROM steps WHERE device = ?"
        args: list[Any] = [device]
        if upto is not None:
            sql += " AND id <= ?"
            args.append(upto)
        rows = self._db.execute(sql + " ORDER BY id DESC", args)
        return _entering((_step(raw) for raw in rows), state)

    def steps(
        self,
        device: str | None = None,
        since: float | None = None,
        until: float | None = None,
        after: int | None = None,
        upto: int | None = None,
    ) -> Iterator[StepRow]:
        """Step rows in order; ``after``/``upto`` bound the row id."""
        clauses, args = _filters("?", device, since, until, after, upto)
        for row in self._db.execute(f"SELECT * FROM steps{_where(clauses)} ORDER BY id", args):
            yield _step(row)

    def inbox(
        self, device: str | None = None, since: float | None = None, until: float | None = None
    ) -> Iterator[InboxRow]:
        clauses, args = _filters("?", device, since, until)
        for seq, dev, wall, event, data in self._db.execute(
            f"SELECT * FROM inbox{_where(clauses)} ORDER BY seq", args
        ):
            yield InboxRow(seq, dev, wall, event, _json(data, f"accepted event #{seq}"))

    def last_step(self, device: str) -> StepRow | None:
        row = self._db.execute(
            "SELECT * FROM steps WHERE device = ? ORDER BY id DESC LIMIT 1", (device,)
        ).fetchone()
        return _step(row) if row is not None else None

    def last_id(self) -> int:
        return int(self._db.execute("SELECT coalesce(max(id), 0) FROM steps").fetchone()[0])

    def processed(self, device: str) -> int:
        """The highest inbox ``seq`` the device has a step for (0: none)."""
        row = self._db.execute(
            "SELECT coalesce(max(inbox), 0) FROM steps WHERE device = ?", (device,)
        ).fetchone()
        return int(row[0])

    def pending(self, device: str) -> tuple[InboxRow, ...]:
        """Accepted events of ``device`` it has not processed, in order."""
        done = self.processed(device)
        rows = self._db.execute(
            "SELECT * FROM inbox WHERE device = ? AND seq > ? ORDER BY seq", (device, done)
        )
        return tuple(
            InboxRow(s, d, w, e, _json(x, f"accepted event #{s}")) for s, d, w, e, x in rows
        )

    def counts(self) -> dict[str, int]:
        inbox = self._db.execute("SELECT count(*) FROM inbox").fetchone()[0]
        steps = self._db.execute("SELECT count(*) FROM steps").fetchone()[0]
        return {"inbox": int(inbox), "steps": int(steps)}


def export_jsonl(
    reader: JournalSource,
    out: TextIO,
    *,
    device: str | None = None,
    since: float | None = None,
    until: float | None = None,
) -> int:
    """Write accepted events and steps as JSON Lines, inbox first; returns the line count."""
    n = 0
    for r in reader.inbox(device, since, until):
        line = {"type": "accepted", "seq": r.seq, "device": r.device, "wall": r.wall}
        line |= {"event": r.event, "data": r.data}
        out.write(json.dumps(line, sort_keys=True) + "\n")
        n += 1
    for s in reader.steps(device, since, until):
        out.write(json.dumps(s.to_json(), sort_keys=True) + "\n")
        n += 1
    return n


@dataclass(frozen=True, slots=True)
class Mismatch:
    """A step whose journalled snapshot differs from the model's."""

    step: int
    device: str
    expected: tuple[str, ...]  # journalled active states
    replayed: tuple[str, ...]

    def __str__(self) -> str:
        return (
            f"step {self.step} ({self.device}): journal says [{', '.join(self.expected)}], "
            f"the model reaches [{', '.join(self.replayed)}]"
        )


@dataclass(frozen=True, slots=True)
class ReplayResult:
    final: Mapping[str, Snapshot]
    steps: int
    mismatches: tuple[Mismatch, ...]

    @property
    def ok(self) -> bool:
        return not self.mismatches


def replay(
    reader: JournalSource,
    charts: Mapping[str, Chart],
    *,
    device: str | None = None,
    upto: int | None = None,
    listener: Listener | None = None,
) -> ReplayResult:
    """Replay the journal (up to step ``upto``) on a SimClock; see the module's rule 3."""
    clock = SimClock()
    subjects: dict[str, Subject] = {}
    data = {d.name: d.data for d in reader.devices()}
    mismatches: list[Mismatch] = []
    base = 0.0  # device clocks restart with each run; replay time never goes back
    count = 0
    applied: dict[int, int] = {}  # inbox seq -> the step that applied it
    for row in reader.steps(device, upto=upto):
        if row.inbox is not None:
            first = applied.setdefault(row.inbox, row.id)
            if first != row.id:
                raise JournalError(
                    f"accepted event #{row.inbox} ({row.device}: {row.event}) was applied "
                    f"twice, by steps {first} and {row.id}: the journal cannot be trusted"
                )
        if row.kind in (StepKind.START, StepKind.RESTORE) and row.time + base < clock.now():
            base = clock.now() - row.time
        clock.run_until(max(clock.now(), row.time + base))
        subject = subjects.get(row.device)
        if subject is None or row.kind is StepKind.START:
            chart = charts.get(row.device)
            if chart is None:
                raise JournalError(
                    f"replay needs the chart of device {row.device!r}; "
                    f"have: {', '.join(sorted(charts)) or 'none'}"
                )
            subject = Subject(chart, clock=clock, name=row.device, data=data.get(row.device))
            if listener is not None:
                subject.listen(listener)
            if row.kind is StepKind.START:
                subject.start()
            else:  # the window starts mid-run: take the journal's word for the first state
                restore_subject(subject, row.snapshot)
            subjects[row.device] = subject
        refused = row.outcome.partition(":")[0] in (REFUSED, ACKNOWLEDGED)  # nothing ran
        if (row.kind is StepKind.EVENT and not refused) or (
            row.kind is StepKind.RECOVERY and row.outcome != REDO
        ):
            assert row.event is not None
            subject.post(row.event, row.data)
            subject.run_until_idle()
        count += 1
        got = subject.snapshot
        if got is None or got.active != row.snapshot.active or got != row.snapshot:
            mismatches.append(
                Mismatch(
                    row.id,
                    row.device,
                    tuple(sorted(row.snapshot.active)),
                    tuple(sorted(got.active)) if got is not None else (),
                )
            )
    final = {name: s.snapshot for name, s in subjects.items() if s.snapshot is not None}
    return ReplayResult(final, count, tuple(mismatches))
