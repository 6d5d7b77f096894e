"""The journal's format: its SQLite schema, its enums and how values and snapshots are encoded.

Everything a reader needs to understand a journal file without the writer
thread: :mod:`statectl.run.journal.store` (writing), :mod:`statectl.run.journal.read`
and :mod:`statectl.run.journal.check` all build on this module."""

from __future__ import annotations

import enum
import json
import sqlite3
from pathlib import Path
from typing import Any

from statectl.kernel.errors import StatectlError
from statectl.kernel.semantics import Snapshot

SCHEMA_VERSION = 1


_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS devices (
    name TEXT PRIMARY KEY, chart TEXT NOT NULL, source TEXT NOT NULL, data TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS inbox (
    seq INTEGER PRIMARY KEY, device TEXT NOT NULL, wall REAL NOT NULL,
    event TEXT NOT NULL, data TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS steps (
    id INTEGER PRIMARY KEY, device TEXT NOT NULL, kind TEXT NOT NULL, inbox INTEGER,
    wall REAL NOT NULL, time REAL NOT NULL, event TEXT, data TEXT NOT NULL,
    outcome TEXT NOT NULL, active TEXT NOT NULL, history TEXT NOT NULL, previous TEXT
);
CREATE INDEX IF NOT EXISTS steps_device ON steps (device, id);
CREATE INDEX IF NOT EXISTS steps_inbox ON steps (device, inbox);
CREATE INDEX IF NOT EXISTS inbox_device ON inbox (device, seq);
"""


class JournalError(StatectlError):
    """The journal cannot be opened or written."""


class Sync(enum.Enum):
    """How far a commit goes before it counts: see the module's rule 4."""

    NORMAL = "normal"
    FULL = "full"


class Guarantee(enum.Enum):
    """When a device acts on an accepted event: see the module's rule 3 and docs/journal.md."""

    PROMPT = "prompt"  # at once; accepted (acknowledged) once its inbox row is committed
    DURABLE_FIRST = "durable-first"  # only after its inbox row is committed


class StepKind(enum.Enum):
    START = "start"  # the device entered its initial configuration
    RESTORE = "restore"  # the device took up its journalled snapshot on --resume
    RECOVERY = "recovery"  # a declared recovery transition after a restore
    EVENT = "event"  # an event processed (from the inbox or from inside the run)


_ENCODER = json.JSONEncoder(separators=(",", ":"), sort_keys=True, allow_nan=False)


def encode_data(value: Any) -> str:
    """Event data as compact JSON; data that JSON cannot hold is misuse.

    Most events carry no data: that is the posting hot path, so it skips the encoder.
    """
    if value is None:
        return "null"
    try:
        return _ENCODER.encode(value)
    except (TypeError, ValueError) as exc:
        raise StatectlError(
            f"journalled event data must be JSON (null, numbers, text, lists, mappings); "
            f"got {value!r} ({exc})"
        ) from None


_SNAPSHOTS: dict[Snapshot, tuple[str, str, str | None]] = {}


_SNAPSHOTS_MAX = 4096


def encode_snapshot(s: Snapshot) -> tuple[str, str, str | None]:
    """The ``active``, ``history`` and ``previous`` columns of a snapshot.

    A device goes round a few configurations, so the columns are remembered per
    snapshot: a step's row costs the owner a dictionary look-up, not two encodings.
    """
    columns = _SNAPSHOTS.get(s)
    if columns is None:
        history = [[state, list(saved)] for state, saved in s.history]
        columns = (json.dumps(sorted(s.active)), json.dumps(history), s.previous)
        if len(_SNAPSHOTS) >= _SNAPSHOTS_MAX:
            _SNAPSHOTS.clear()
        _SNAPSHOTS[s] = columns
    return columns


def decode_snapshot(active: str, history: str, previous: str | None) -> Snapshot:
    """The snapshot a step row holds; ``ValueError`` for columns no journal writes."""
    states, saved = json.loads(active), json.loads(history)
    if not (isinstance(states, list) and all(isinstance(x, str) for x in states)):
        raise ValueError(f"active states are not a list of state names: {active[:80]!r}")
    if not (
        isinstance(saved, list)
        and all(
            isinstance(h, list)
            and len(h) == 2
            and isinstance(h[0], str)
            and isinstance(h[1], list)
            and all(isinstance(x, str) for x in h[1])
            for h in saved
        )
    ):
        raise ValueError(f"history is not a list of [state, [states]]: {history[:80]!r}")
    if previous is not None and not isinstance(previous, str):
        raise ValueError(f"previous state is not a name: {previous!r}")
    return Snapshot(frozenset(states), tuple((h[0], tuple(h[1])) for h in saved), previous)


def connect_db(
    path: str | Path, *, sync: Sync = Sync.NORMAL, create: bool = True
) -> sqlite3.Connection:
    """Open ``path`` in WAL mode; the schema is made only in a database without tables.

    A database with some of the tables is damage, never a new journal: recreating
    a deleted ``steps`` table would make a resume re-deliver every accepted event.
    """
    p = Path(path)
    if not create and not p.exists():
        raise JournalError(f"no journal at {p}; run with --journal {p} first")
    db: sqlite3.Connection | None = None
    try:
        db = sqlite3.connect(str(p), isolation_level=None, check_same_thread=False)
        db.execute("PRAGMA busy_timeout=5000")
        db.execute("PRAGMA journal_mode=WAL")
        db.execute(f"PRAGMA synchronous={sync.value.upper()}")
        tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not tables:
            db.executescript(_SCHEMA)
            db.execute("INSERT OR IGNORE INTO meta VALUES ('version', ?)", (str(SCHEMA_VERSION),))
            return db
        missing = [t for t in ("meta", "devices", "inbox", "steps") if t not in tables]
        if missing:
            raise JournalError(
                f"journal {p} cannot be trusted: table {', '.join(missing)} is missing"
            )
        row = db.execute("SELECT value FROM meta WHERE key='version'").fetchone()
        if row is None or row[0] != str(SCHEMA_VERSION):
            found = "none" if row is None else repr(row[0])
            raise JournalError(
                f"journal {p}: schema version {found}, this statectl reads {SCHEMA_VERSION}"
            )
    except sqlite3.Error as exc:
        if db is not None:
            db.close()
        raise JournalError(f"cannot open journal {p}: {_problem(exc, p.parent)}") from None
    except JournalError:
        if db is not None:
            db.close()
        raise
    return db


def _problem(exc: BaseException, where: Path | None = None) -> str:
    from statectl.run.journal.check import sqlite_problem  # check.py imports this module

    return sqlite_problem(exc, where)
