"""Whether a journal file can be trusted, before anything reads, resumes from or appends to it.

Rules:
1. A journal is checked as a whole before any command uses it: ``--resume``, a run
   that appends to it, ``journal show|export|replay``. A journal that fails is
   refused with every problem found (up to a few per kind), so nothing is shown,
   exported or re-delivered from it.
2. What is checked, in order; each stage needs the one before it:
   the file (exists, is a file, not empty for a reader, starts with SQLite's
   header, as long as the header says); SQLite's own ``PRAGMA quick_check``;
   the schema (the four tables with their columns, ``meta`` version
   :data:`~statectl.journal.store.SCHEMA_VERSION`); the rows (known step kinds,
   column types, JSON where JSON belongs); the invariants between ``inbox`` and
   ``steps``: a step that names an accepted event names one the inbox holds, for
   the same device and event; no accepted event has two steps (applied twice);
   and per device no accepted event is without a step while a later one has
   one (steps missing).
3. A missing table is damage, never "a new journal": a journal whose ``steps``
   were deleted would otherwise resume as if nothing had run and re-deliver every
   accepted event to its device.
4. The checks run in SQLite (indexes, ``json_valid``), not row by row in Python,
   so checking a journal of a million events takes about a second.
"""

from __future__ import annotations

import datetime as dt
import errno
import os
import sqlite3
from collections.abc import Iterable
from pathlib import Path

from statectl.journal.store import SCHEMA_VERSION, JournalError, StepKind

__all__ = [
    "COLUMNS",
    "JournalDamaged",
    "check_journal",
    "connect_ro",
    "set_aside",
    "sqlite_problem",
]

#: The tables of a journal and their columns, in order (store._SCHEMA).
COLUMNS: dict[str, tuple[str, ...]] = {
    "meta": ("key", "value"),
    "devices": ("name", "chart", "source", "data"),
    "inbox": ("seq", "device", "wall", "event", "data"),
    "steps": (
        "id", "device", "kind", "inbox", "wall", "time", "event", "data", "outcome",
        "active", "history", "previous",
    ),
}  # fmt: skip

_HEADER = b"SQLite format 3\x00"
_SHOWN = 3  # rows named per problem


class JournalDamaged(JournalError):
    """A journal that cannot be trusted: ``problems`` says why, one line each."""

    def __init__(self, path: Path, problems: Iterable[str]) -> None:
        self.path = path
        self.problems = tuple(problems)
        super().__init__(f"journal {path} cannot be trusted: {'; '.join(self.problems)}")


def sqlite_problem(exc: BaseException) -> str:
    """What an SQLite or OS error means for a journal, in words a user can act on."""
    text = str(exc)
    low = text.lower()
    if "full" in low or getattr(exc, "errno", None) == errno.ENOSPC:
        return f"the disk is full ({text}); free space and try again"
    if "readonly" in low or "read-only" in low or getattr(exc, "errno", None) == errno.EROFS:
        return f"it is read-only ({text}); statectl needs to write it and the files beside it"
    if "not a database" in low or "malformed" in low or "corrupt" in low:
        return f"it is damaged ({text})"
    return text


def _file_problems(path: Path, *, reader: bool) -> list[str]:
    """Rule 2's first stage: the bytes on disk, before SQLite opens them."""
    if path.is_dir():
        return ["it is a directory, not a journal file"]
    try:
        size = path.stat().st_size
        with path.open("rb") as f:
            head = f.read(100)
    except OSError as exc:
        return [f"cannot read it ({exc.strerror or exc})"]
    if size == 0:
        return ["it is empty (0 bytes)"] if reader else []
    if not head.startswith(_HEADER):
        shown = head[:16].decode("ascii", "replace").strip()
        return [f"it is not a SQLite database (it starts with {shown!r})"]
    if len(head) < 100:
        return [f"it is truncated ({size} bytes, shorter than SQLite's 100-byte header)"]
    page = int.from_bytes(head[16:18], "big")
    page = 65536 if page == 1 else page
    pages = int.from_bytes(head[28:32], "big")
    valid = head[24:28] == head[92:96]  # the header's page count is current
    wal = path.with_name(path.name + "-wal")
    if wal.exists() and wal.stat().st_size:
        return []  # the log holds pages a checkpoint has not written yet: SQLite's check judges
    if valid and page and pages and size < page * pages:
        return [
            f"it is truncated ({size} bytes; its header says {pages} pages of {page} bytes, "
            f"{page * pages} bytes)"
        ]
    return []


def _schema_problems(db: sqlite3.Connection) -> list[str]:
    problems = []
    for table, columns in COLUMNS.items():
        found = tuple(r[1] for r in db.execute(f"PRAGMA table_info({table})"))
        if not found:
            problems.append(f"table {table} is missing")
        elif found != columns:
            problems.append(
                f"table {table} has columns ({', '.join(found)}), expected ({', '.join(columns)})"
            )
    if problems:
        return problems
    rows = db.execute("SELECT value FROM meta WHERE key = 'version'").fetchall()
    if not rows:
        return ["it has no schema version (meta 'version')"]
    if rows[0][0] != str(SCHEMA_VERSION):
        return [
            f"its schema version is {rows[0][0]!r}; this statectl reads version "
            f"{SCHEMA_VERSION} (a newer statectl wrote it: use that one)"
        ]
    return []


_KINDS = ", ".join(f"'{k.value}'" for k in StepKind)
_REAL = "typeof({0}) IN ('real', 'integer')"
_JSON = "(typeof({0}) = 'text' AND json_valid({0}))"
_ARRAY = "(typeof({0}) = 'text' AND json_valid({0}) AND json_type({0}) = 'array')"

#: (what is wrong, query of the offending rows' names); each query returns one text per row.
_ROW_CHECKS: tuple[tuple[str, str], ...] = (
    (
        "unknown step kind",
        f"SELECT 'step ' || id || ' (' || quote(kind) || ')' FROM steps "
        f"WHERE kind NOT IN ({_KINDS}) OR typeof(kind) != 'text'",
    ),
    (
        "step columns of the wrong type",
        "SELECT 'step ' || quote(id) FROM steps WHERE typeof(id) != 'integer' "
        "OR typeof(device) != 'text' OR (inbox IS NOT NULL AND typeof(inbox) != 'integer') "
        f"OR NOT {_REAL.format('wall')} OR NOT {_REAL.format('time')} "
        "OR (event IS NOT NULL AND typeof(event) != 'text') "
        f"OR NOT {_JSON.format('data')} OR typeof(outcome) != 'text' "
        f"OR NOT {_ARRAY.format('active')} OR NOT {_ARRAY.format('history')} "
        "OR (previous IS NOT NULL AND typeof(previous) != 'text')",
    ),
    (
        "accepted events with columns of the wrong type",
        "SELECT '#' || quote(seq) FROM inbox WHERE typeof(seq) != 'integer' "
        f"OR typeof(device) != 'text' OR NOT {_REAL.format('wall')} "
        f"OR typeof(event) != 'text' OR NOT {_JSON.format('data')}",
    ),
    (
        "device rows of the wrong type",
        "SELECT quote(name) FROM devices WHERE typeof(name) != 'text' "
        f"OR typeof(chart) != 'text' OR typeof(source) != 'text' OR NOT {_JSON.format('data')}",
    ),
    (
        "steps naming an accepted event the inbox does not hold for that device and event",
        "SELECT 'step ' || s.id || ' (#' || s.inbox || ')' FROM steps s "
        "LEFT JOIN inbox i ON i.seq = s.inbox WHERE s.inbox IS NOT NULL "
        "AND (i.seq IS NULL OR i.device IS NOT s.device OR i.event IS NOT s.event)",
    ),
    (
        "accepted events applied more than once",
        "SELECT '#' || inbox || ' by steps ' || group_concat(id, ', ') FROM steps "
        "WHERE inbox IS NOT NULL GROUP BY inbox HAVING count(*) > 1",
    ),
    (
        "accepted events without a step while a later one of their device has one "
        "(steps are missing)",
        "SELECT '#' || i.seq || ' (' || i.device || ')' FROM inbox i "
        "WHERE i.seq < (SELECT max(s.inbox) FROM steps s WHERE s.device = i.device) "
        "AND NOT EXISTS (SELECT 1 FROM steps s WHERE s.device = i.device AND s.inbox = i.seq)",
    ),
)


def _row_problems(db: sqlite3.Connection) -> list[str]:
    problems = []
    for what, sql in _ROW_CHECKS:
        rows = [str(r[0]) for r in db.execute(f"{sql} LIMIT {_SHOWN + 1}")]
        if rows:
            more = ", ..." if len(rows) > _SHOWN else ""
            problems.append(f"{what}: {', '.join(rows[:_SHOWN])}{more}")
    return problems


def connect_ro(path: Path) -> sqlite3.Connection:
    """A read-only connection; on a read-only file system without a write-ahead log, immutable."""
    uri = path.resolve().as_uri()
    wal = path.with_name(path.name + "-wal")
    if not os.access(path.parent, os.W_OK) and not wal.exists():
        # SQLite cannot make the -shm file beside it; nothing can write there either
        return sqlite3.connect(f"{uri}?immutable=1", uri=True)
    db = sqlite3.connect(f"{uri}?mode=ro", uri=True)
    db.execute("PRAGMA busy_timeout=5000")
    return db


def check_journal(path: str | Path, *, reader: bool = True) -> None:
    """Raise :class:`JournalDamaged` with every problem found (rule 2); return if trusted.

    ``reader``: an empty file is refused (a writer takes it as a new journal).
    A file that does not exist raises :class:`JournalError` (not damage: nothing is there).
    """
    p = Path(path)
    if not p.exists():
        raise JournalError(f"no journal at {p}")
    problems = _file_problems(p, reader=reader)
    if problems or p.stat().st_size == 0:
        if problems:
            raise JournalDamaged(p, problems)
        return
    wal = p.with_name(p.name + "-wal")
    if not os.access(p.parent, os.W_OK) and wal.exists() and wal.stat().st_size:
        raise JournalError(
            f"journal {p}: it is on a read-only file system with an unmerged write-ahead log "
            f"({wal.name}); copy both files somewhere writable and read the copy"
        )
    sides = [p.with_name(p.name + s) for s in ("-wal", "-shm") if not Path(f"{p}{s}").exists()]
    try:
        db = connect_ro(p)
    except sqlite3.Error as exc:
        _remove_empty(sides)
        raise JournalError(f"journal {p}: cannot open it: {sqlite_problem(exc)}") from None
    try:
        rows = [str(r[0]) for r in db.execute("PRAGMA quick_check(4)")]
        if rows != ["ok"]:
            found = "; ".join(x for r in rows for x in r.splitlines() if not x.startswith("***"))
            raise JournalDamaged(p, [f"SQLite finds it damaged: {found}"])
        problems = _schema_problems(db) or _row_problems(db)
    except sqlite3.OperationalError as exc:  # locked, I/O, out of memory: not the file's fault
        raise JournalError(f"journal {p}: cannot read it: {sqlite_problem(exc)}") from None
    except sqlite3.DatabaseError as exc:  # not a database, malformed
        raise JournalDamaged(p, [sqlite_problem(exc)]) from None
    except JournalDamaged:
        db.close()
        _remove_empty(sides)
        raise
    finally:
        db.close()
    if problems:
        _remove_empty(sides)
        raise JournalDamaged(p, problems)


def _remove_empty(sides: list[Path]) -> None:
    """Remove the -wal/-shm files opening a refused journal made, if its log stayed empty.

    Only for a journal refused as damaged: nothing writes it, and nothing is left beside it.
    """
    wal = [s for s in sides if s.name.endswith("-wal")]
    if any(w.exists() and w.stat().st_size for w in wal):
        return
    for side in sides:
        side.unlink(missing_ok=True)


def set_aside(path: str | Path, now: dt.datetime | None = None) -> Path:
    """Rename a journal (and its -wal/-shm files) with a UTC timestamp suffix; the new name.

    The write-ahead log keeps SQLite's naming beside the new name, so the copy set
    aside opens as it was.
    """
    p = Path(path)
    stamp = (now or dt.datetime.now(dt.UTC)).strftime("%Y%m%dT%H%M%SZ")
    target = p.with_name(f"{p.name}.{stamp}")
    n = 1
    while target.exists():
        n += 1
        target = p.with_name(f"{p.name}.{stamp}-{n}")
    try:
        p.rename(target)
        for suffix in ("-wal", "-shm"):
            side = p.with_name(p.name + suffix)
            if side.exists():
                side.rename(target.with_name(target.name + suffix))
    except OSError as exc:
        raise JournalError(
            f"cannot set journal {p} aside: {sqlite_problem(exc)}; move it away yourself"
        ) from None
    return target
