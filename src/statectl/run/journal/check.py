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
   :data:`~statectl.run.journal.store.SCHEMA_VERSION`); the rows (known step kinds,
   column types, JSON where JSON belongs); the invariants between ``inbox`` and
   ``steps``: a step that names an accepted event names one the inbox holds, for
   the same device and event; no accepted event has two steps (applied twice);
   and per device no accepted event is without a step while a later one has
   one (steps missing).
3. A missing table is damage, never "a new journal": a journal whose ``steps``
   were deleted would otherwise resume as if nothing had run and re-deliver every
   accepted event to its device.
4. The checks run in SQLite (indexes, ``json_valid``), not row by row in Python.
   A reader checks every row (``show``, ``export`` and ``replay`` read them all);
   a writer (``--resume``, appending) types only the rows resume reads, the last
   step of each device and the accepted events still to run, and catches a bad
   row elsewhere by the kinds and invariants: about 1 s per million events.
"""

from __future__ import annotations

import datetime as dt
import errno
import os
import shutil
import sqlite3
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from statectl.run.journal.format import _SCHEMA, SCHEMA_VERSION, JournalError, StepKind

__all__ = [
    "COLUMNS",
    "JournalDamaged",
    "check_journal",
    "connect_ro",
    "journal_files",
    "set_aside",
    "sqlite_problem",
]


def _columns() -> dict[str, tuple[str, ...]]:
    """The tables of a journal and their columns, in order: read from the schema itself."""
    db = sqlite3.connect(":memory:")
    try:
        db.executescript(_SCHEMA)
        names = [r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        return {t: tuple(r[1] for r in db.execute(f"PRAGMA table_info({t})")) for t in names}
    finally:
        db.close()


#: The tables of a journal and their columns, in order.
COLUMNS: dict[str, tuple[str, ...]] = _columns()

_HEADER = b"SQLite format 3\x00"
_SHOWN = 3  # rows named per problem


class JournalDamaged(JournalError):
    """A journal that cannot be trusted: ``problems`` says why, one line each."""

    def __init__(self, path: Path, problems: Iterable[str]) -> None:
        self.path = path
        self.problems = tuple(problems)
        super().__init__(f"journal {path} cannot be trusted: {'; '.join(self.problems)}")


def sqlite_problem(exc: BaseException, where: Path | None = None) -> str:
    """What an SQLite or OS error means for a journal, in words a user can act on.

    ``where``: the journal's directory; SQLite reports a full disk while opening
    (it cannot make the -shm file) as an I/O error, so its free space is looked at.
    """
    text = str(exc)
    low = text.lower()
    if "full" in low or getattr(exc, "errno", None) == errno.ENOSPC or _full(where):
        return f"the disk is full ({text}); free space and try again"
    if "readonly" in low or "read-only" in low or getattr(exc, "errno", None) == errno.EROFS:
        return f"it is read-only ({text}); statectl needs to write it and the files beside it"
    if "not a database" in low or "malformed" in low or "corrupt" in low:
        return f"it is damaged ({text})"
    return text


def _full(where: Path | None) -> bool:
    try:
        return where is not None and shutil.disk_usage(where).free < 65536
    except OSError:
        return False


def _file_problems(path: Path, *, reader: bool) -> list[str]:
    """Rule 2's first stage: the bytes on disk, before SQLite opens them."""
    if path.is_dir():
        return ["it is a directory, not a journal file"]
    if path.exists() and not path.is_file():  # opening a FIFO would wait for a writer
        return ["it is not a regular file (a FIFO, device or socket)"]
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


def _text(column: str, array: bool = False) -> str:
    """SQL true when ``column`` holds JSON text (an array, if ``array``)."""
    shape = f" AND json_type({column}) = 'array'" if array else ""
    return f"(typeof({column}) = 'text' AND json_valid({column}){shape})"


#: The steps :meth:`JournalledDevice.resume` reads: each device's last one.
_LAST_STEPS = "id IN (SELECT max(id) FROM steps GROUP BY device)"


def _pending(db: sqlite3.Connection) -> tuple[str, list[Any]]:
    """SQL (and its parameters) true for the accepted events resume reads: each
    device's after its last step.

    Per device through the indexes (a correlated subquery per inbox row would read
    them all): the devices come from inbox_device one at a time (a skip scan).
    """
    terms: list[str] = []
    args: list[Any] = []
    device = db.execute("SELECT min(device) FROM inbox").fetchone()[0]
    while device is not None:
        top = db.execute(
            "SELECT coalesce(max(inbox), 0) FROM steps WHERE device = ?", (device,)
        ).fetchone()[0]
        terms.append("(device = ? AND seq > ?)")
        args += [device, top]
        device = db.execute("SELECT min(device) FROM inbox WHERE device > ?", (device,)).fetchone()[
            0
        ]
    return " OR ".join(terms) or "0", args


def _row_checks(db: sqlite3.Connection, deep: bool) -> tuple[tuple[str, str, list[Any]], ...]:
    """(what is wrong, query of the offending rows' names, parameters): one text per row.

    ``deep`` (a reader's check) types every row and parses every JSON column: about
    2 s per million events. Otherwise (a writer's: resume, append) only the rows
    resume reads are typed; the kinds and the invariants cover every row.
    """
    steps, (inbox, args) = ("1", ("1", [])) if deep else (_LAST_STEPS, _pending(db))
    event = " OR i.event IS NOT s.event" if deep else ""
    return (
        (
            "unknown step kind",
            f"SELECT 'step ' || id || ' (' || quote(kind) || ')' FROM steps "
            f"WHERE kind NOT IN ({_KINDS}) OR typeof(kind) != 'text'",
            [],
        ),
        (
            "step columns of the wrong type",
            f"SELECT 'step ' || quote(id) FROM steps WHERE ({steps}) AND ("
            "typeof(id) != 'integer' OR typeof(device) != 'text' "
            "OR (inbox IS NOT NULL AND typeof(inbox) != 'integer') "
            f"OR NOT {_REAL.format('wall')} OR NOT {_REAL.format('time')} "
            "OR (event IS NOT NULL AND typeof(event) != 'text') "
            f"OR NOT {_text('data')} OR typeof(outcome) != 'text' "
            f"OR NOT {_text('active', True)} OR NOT {_text('history', True)} "
            "OR (previous IS NOT NULL AND typeof(previous) != 'text'))",
            [],
        ),
        (
            "accepted events with columns of the wrong type",
            f"SELECT '#' || quote(seq) FROM inbox WHERE ({inbox}) AND ("
            "typeof(seq) != 'integer' OR typeof(device) != 'text' "
            f"OR NOT {_REAL.format('wall')} OR typeof(event) != 'text' OR NOT {_text('data')})",
            args,
        ),
        (
            "device rows of the wrong type",
            "SELECT quote(name) FROM devices WHERE typeof(name) != 'text' "
            f"OR typeof(chart) != 'text' OR typeof(source) != 'text' OR NOT {_text('data')}",
            [],
        ),
        (
            "steps naming an accepted event the inbox does not hold for that device"
            + (" and event" if deep else ""),
            "SELECT 'step ' || s.id || ' (#' || s.inbox || ')' FROM steps s "
            "LEFT JOIN inbox i ON i.seq = s.inbox WHERE s.inbox IS NOT NULL "
            f"AND (i.seq IS NULL OR i.device IS NOT s.device{event})",
            [],
        ),
    )


#: Per device, from the index steps_inbox: the last accepted event it has a step for,
#: its steps of accepted events, and how many accepted events those are.
_APPLIED = (
    "SELECT device, max(inbox), count(*), count(DISTINCT inbox) FROM steps "
    "WHERE inbox IS NOT NULL GROUP BY device"
)
_ACCEPTED = "SELECT count(*) FROM inbox WHERE device = ? AND seq <= ?"
_TWICE = (
    "SELECT '#' || inbox || ' by steps ' || group_concat(id, ', ') FROM steps "
    "WHERE device = ? AND inbox IS NOT NULL GROUP BY inbox HAVING count(*) > 1"
)
_MISSING = (
    "SELECT '#' || i.seq || ' (' || i.device || ')' FROM inbox i "
    "WHERE i.device = ? AND i.seq < ? "
    "AND NOT EXISTS (SELECT 1 FROM steps s WHERE s.device = i.device AND s.inbox = i.seq)"
)


def _named(what: str, rows: list[str]) -> str:
    more = ", ..." if len(rows) > _SHOWN else ""
    return f"{what}: {', '.join(rows[:_SHOWN])}{more}"


def _row_problems(db: sqlite3.Connection, deep: bool) -> list[str]:
    problems = []
    for what, sql, args in _row_checks(db, deep):
        rows = [str(r[0]) for r in db.execute(f"{sql} LIMIT {_SHOWN + 1}", args)]
        if rows:
            problems.append(_named(what, rows))
    if problems:
        return problems
    # Every step's event is in the inbox (checked above), so per device: no event has
    # two steps iff the counts equal, and none below the last is missing iff the
    # inbox holds no more. The slower queries that name the rows run only then.
    twice: list[str] = []
    missing: list[str] = []
    for device, top, steps, distinct in db.execute(_APPLIED).fetchall():
        if steps != distinct:
            twice += [str(r[0]) for r in db.execute(f"{_TWICE} LIMIT {_SHOWN + 1}", (device,))]
        if db.execute(_ACCEPTED, (device, top)).fetchone()[0] != distinct:
            sql = f"{_MISSING} LIMIT {_SHOWN + 1}"
            missing += [str(r[0]) for r in db.execute(sql, (device, top))]
    if twice:
        problems.append(_named("accepted events applied more than once", twice))
    if missing:
        problems.append(
            _named(
                "accepted events without a step while a later one of their device has one "
                "(steps are missing)",
                missing,
            )
        )
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

    ``reader``: an empty file is refused (a writer takes it as a new journal), and
    every JSON column is parsed (rule 4).
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
        raise JournalError(
            f"journal {p}: cannot open it: {sqlite_problem(exc, p.parent)}"
        ) from None
    try:
        rows = [str(r[0]) for r in db.execute("PRAGMA quick_check(4)")]
        if rows != ["ok"]:
            found = "; ".join(x for r in rows for x in r.splitlines() if not x.startswith("***"))
            raise JournalDamaged(p, [f"SQLite finds it damaged: {found}"])
        problems = _schema_problems(db) or _row_problems(db, deep=reader)
    except sqlite3.OperationalError as exc:  # locked, I/O, out of memory: not the file's fault
        raise JournalError(
            f"journal {p}: cannot read it: {sqlite_problem(exc, p.parent)}"
        ) from None
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


def journal_files(path: str | Path) -> tuple[Path, ...]:
    """The journal file and the files SQLite may keep beside it (``-wal``, ``-shm``,
    ``-journal``): what holds the journal, to protect or to remove as one."""
    p = Path(path)
    return (p, *(p.with_name(p.name + s) for s in ("-wal", "-shm", "-journal")))


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
