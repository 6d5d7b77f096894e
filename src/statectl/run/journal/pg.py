"""Journals in PostgreSQL: the shared schema, the URL of a source, a reader like JournalReader.

Rules:
1. Many controllers ship into one database. Every row carries its ``source`` (a
   name per source journal: ``host:path`` unless configured) and keeps the id it
   has in its journal, so ``(source, seq)`` and ``(source, id)`` are the keys.
2. ``statectl_sources`` holds, per source, how far it has been shipped
   (``inbox_upto``, ``steps_upto``) and the journal's first step (``origin``),
   so a different journal at the same path is refused instead of skipped.
   The shipper (journal/ship.py) moves the marks in the transaction that
   inserts the rows: the database never holds a row beyond its mark or misses
   one below it.
3. Values are stored as they are in SQLite (``wall`` in epoch seconds, JSON
   text in ``json`` columns, which keep the text as written) plus the derived
   ``at`` (timestamptz) and ``fault`` (the step is a monitor's fault event:
   its data has a ``detail``), which the indexes serve.
4. A URL names the database and, with ``?source=NAME``, one source in it
   (statectl takes that parameter off before connecting); without it a
   database holding one source reads that one. Passwords are never echoed:
   messages show :func:`display_url`.
5. psycopg (the ``postgres`` extra) is imported only when PostgreSQL is used.
"""

from __future__ import annotations

import urllib.parse
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from statectl.kernel.errors import require
from statectl.run.devices.urls import url_problem as url_syntax
from statectl.run.journal.format import JournalError
from statectl.run.journal.read import (
    DeviceRow,
    InboxRow,
    StepRow,
    _datamodel,
    _entering,
    _filters,
    _json,
    _step,
)

if TYPE_CHECKING:
    import psycopg

__all__ = [
    "SCHEMA",
    "PgJournalReader",
    "connect_pg",
    "display_url",
    "ensure_schema",
    "is_pg_url",
    "split_url",
    "url_problem",
]

#: The shared schema (docs/journal.md, "Shipping to PostgreSQL"). Idempotent.
SCHEMA = """
CREATE TABLE IF NOT EXISTS statectl_sources (
    source     text PRIMARY KEY,
    origin     text NOT NULL,
    inbox_upto bigint NOT NULL DEFAULT 0,
    steps_upto bigint NOT NULL DEFAULT 0,
    shipped_at timestamptz NOT NULL DEFAULT now()
);
CREATE TABLE IF NOT EXISTS statectl_devices (
    source text NOT NULL REFERENCES statectl_sources,
    name   text NOT NULL,
    chart  text NOT NULL,
    file   text NOT NULL,
    data   json NOT NULL,
    PRIMARY KEY (source, name)
);
CREATE TABLE IF NOT EXISTS statectl_inbox (
    source text NOT NULL,
    seq    bigint NOT NULL,
    device text NOT NULL,
    wall   double precision NOT NULL,
    at     timestamptz GENERATED ALWAYS AS (to_timestamp(wall)) STORED,
    event  text NOT NULL,
    data   json NOT NULL,
    PRIMARY KEY (source, seq)
);
CREATE TABLE IF NOT EXISTS statectl_steps (
    source   text NOT NULL,
    id       bigint NOT NULL,
    device   text NOT NULL,
    kind     text NOT NULL,
    inbox    bigint,
    wall     double precision NOT NULL,
    at       timestamptz GENERATED ALWAYS AS (to_timestamp(wall)) STORED,
    time     double precision NOT NULL,
    event    text,
    data     json NOT NULL,
    outcome  text NOT NULL,
    active   json NOT NULL,
    history  json NOT NULL,
    previous text,
    fault    boolean GENERATED ALWAYS AS ((data ->> 'detail') IS NOT NULL) STORED,
    PRIMARY KEY (source, id)
);
CREATE INDEX IF NOT EXISTS statectl_steps_device_at ON statectl_steps (device, at);
CREATE INDEX IF NOT EXISTS statectl_steps_fault_at ON statectl_steps (at) WHERE fault;
CREATE INDEX IF NOT EXISTS statectl_inbox_device_at ON statectl_inbox (device, at);
"""

INBOX_COLUMNS = ("source", "seq", "device", "wall", "event", "data")
STEP_COLUMNS = (
    "source", "id", "device", "kind", "inbox", "wall", "time", "event", "data", "outcome",
    "active", "history", "previous",
)  # fmt: skip
_STEP_SELECT = (
    "id, device, kind, inbox, wall, time, event, data::text, outcome, "
    "active::text, history::text, previous"
)


def is_pg_url(text: str) -> bool:
    """Whether a journal argument names PostgreSQL rather than a SQLite file."""
    return text.startswith(("postgresql://", "postgres://"))


def url_problem(url: str) -> str | None:
    """What makes ``url`` no URL at all (an unclosed ``[`` of an IPv6 host), or None; the
    text never holds the URL, which may hold a password."""
    problem = url_syntax(url)
    return None if problem is None else f"it is not a valid URL ({problem})"


def split_url(url: str) -> tuple[str, str | None]:
    """``(url for libpq, source)``: the ``source`` query parameter taken off (rule 4)."""
    problem = url_problem(url)
    if problem is not None:
        raise JournalError(f"{display_url(url)}: {problem}")
    parts = urllib.parse.urlsplit(url)
    query = urllib.parse.parse_qsl(parts.query, keep_blank_values=True)
    source = next((v for k, v in query if k == "source"), None)
    rest = urllib.parse.urlencode([(k, v) for k, v in query if k != "source"])
    return urllib.parse.urlunsplit(parts._replace(query=rest)), source


def display_url(url: str) -> str:
    """The URL without its password (rule 4): safe in a message or a log."""
    try:
        parts = urllib.parse.urlsplit(url)
        password = parts.password
    except ValueError:  # not a URL: show its scheme only, it may hold a password
        return f"{url.split('://', 1)[0]}://***"
    if password is None:
        return url
    netloc = parts.netloc.rsplit("@", 1)[1]
    user = parts.username or ""
    return urllib.parse.urlunsplit(parts._replace(netloc=f"{user}:***@{netloc}"))


def _psycopg() -> Any:
    return require("psycopg", "postgres", "PostgreSQL")


def connect_pg(url: str, *, timeout: float = 5.0) -> psycopg.Connection[Any]:
    """A connection to ``url`` (its ``source`` parameter taken off); JournalError if none."""
    pg = _psycopg()
    target, _ = split_url(url)
    try:
        conn: psycopg.Connection[Any] = pg.connect(
            target, connect_timeout=max(1, round(timeout)), application_name="statectl"
        )
    except pg.Error as exc:
        raise JournalError(f"cannot connect to {display_url(url)}: {_first_line(exc)}") from None
    return conn


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def pg_problem(exc: BaseException) -> str:
    """A psycopg error as one line for a message."""
    return _first_line(exc)


def ensure_schema(conn: psycopg.Connection[Any]) -> None:
    """Create the shared schema if missing; concurrent shippers take turns (advisory lock).

    An existing schema is left alone without DDL: ``CREATE INDEX IF NOT EXISTS``
    still locks its table, which would deadlock with other sources' inserts. The
    check after the lock runs in a transaction of its own, begun after the lock
    was granted, so it sees a schema another shipper has just committed.
    """
    if _has_schema(conn):
        return
    key = "hashtext('statectl-schema')"
    with conn.transaction():
        conn.execute(f"SELECT pg_advisory_lock({key})")
    try:
        with conn.transaction():
            if not _has_schema(conn):
                conn.execute(SCHEMA.encode())
    finally:
        with conn.transaction():
            conn.execute(f"SELECT pg_advisory_unlock({key})")


def _has_schema(conn: psycopg.Connection[Any]) -> bool:
    with conn.transaction():
        row = conn.execute("SELECT to_regclass('statectl_inbox_device_at') IS NOT NULL").fetchone()
    return bool(row is not None and row[0])


class PgJournalReader:
    """Read one source's journal from PostgreSQL, with :class:`JournalReader`'s methods."""

    def __init__(self, url: str, *, source: str | None = None) -> None:
        """Connect; ``source`` (else the URL's ``?source=``, else the only one) is read.

        Raises :class:`JournalError` when the server cannot be reached, holds no
        shipped journal, or holds several and none is named.
        """
        psycopg = _psycopg()
        named = split_url(url)[1]
        self.path = display_url(url)
        self._conn = connect_pg(url)
        self._n = 0
        try:
            names = [r[0] for r in self._conn.execute("SELECT source FROM statectl_sources")]
        except psycopg.errors.UndefinedTable:
            self._conn.close()
            raise JournalError(
                f"{self.path} holds no shipped journal (no statectl_sources table); "
                "ship one with: statectl journal ship DB --to URL"
            ) from None
        except psycopg.Error as exc:
            self._conn.close()
            raise JournalError(f"{self.path}: {_first_line(exc)}") from None
        want = source if source is not None else named
        if want is None:
            if len(names) != 1:
                self._conn.close()
                raise JournalError(
                    f"{self.path} holds {len(names)} shipped journals; name one with "
                    f"?source=NAME in the URL: {', '.join(sorted(names)) or 'none'}"
                )
            want = names[0]
        elif want not in names:
            self._conn.close()
            raise JournalError(
                f"{self.path} has no source {want!r}; it has: {', '.join(sorted(names)) or 'none'}"
            )
        self.source = want

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> PgJournalReader:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def _rows(self, sql: str, args: list[Any]) -> Iterator[tuple[Any, ...]]:
        """Rows streamed through a server-side cursor; a server error becomes JournalError."""
        psycopg = _psycopg()
        self._n += 1
        try:
            with self._conn.cursor(name=f"statectl_{self._n}") as cur:
                cur.itersize = 2000
                cur.execute(sql, [self.source, *args])
                yield from cur
        except psycopg.Error as exc:
            raise JournalError(f"{self.path}: {_first_line(exc)}") from None

    def _one(self, sql: str, args: list[Any]) -> tuple[Any, ...] | None:
        psycopg = _psycopg()
        try:
            row: tuple[Any, ...] | None = self._conn.execute(sql, [self.source, *args]).fetchone()
        except psycopg.Error as exc:
            raise JournalError(f"{self.path}: {_first_line(exc)}") from None
        return row

    def devices(self) -> tuple[DeviceRow, ...]:
        rows = self._rows(
            "SELECT name, chart, file, data::text FROM statectl_devices WHERE source = %s "
            "ORDER BY name",
            [],
        )
        return tuple(DeviceRow(n, c, f, _datamodel(d, f"device {n}")) for n, c, f, d in rows)

    def device(self, name: str) -> DeviceRow | None:
        return next((d for d in self.devices() if d.name == name), None)

    def steps(
        self,
        device: str | None = None,
        since: float | None = None,
        until: float | None = None,
        after: int | None = None,
        upto: int | None = None,
    ) -> Iterator[StepRow]:
        clauses, args = _filters("%s", device, since, until, after, upto)
        where = "".join(f" AND {c}" for c in clauses)
        sql = f"SELECT {_STEP_SELECT} FROM statectl_steps WHERE source = %s{where} ORDER BY id"
        for row in self._rows(sql, args):
            yield _step(row)

    def inbox(
        self, device: str | None = None, since: float | None = None, until: float | None = None
    ) -> Iterator[InboxRow]:
        clauses, args = _filters("%s", device, since, until)
        where = "".join(f" AND {c}" for c in clauses)
        sql = (
            "SELECT seq, device, wall, event, data::text FROM statectl_inbox "
            f"WHERE source = %s{where} ORDER BY seq"
        )
        for seq, dev, wall, event, data in self._rows(sql, args):
            yield InboxRow(seq, dev, wall, event, _json(data, f"accepted event #{seq}"))

    def entering_step(
        self, device: str, state: str, upto: int | None = None
    ) -> tuple[StepRow, StepRow] | None:
        """As :meth:`JournalReader.entering_step` (journal/read.py rule 4)."""
        return _entering(reversed(list(self.steps(device, upto=upto))), state)

    def last_step(self, device: str) -> StepRow | None:
        row = self._one(
            f"SELECT {_STEP_SELECT} FROM statectl_steps WHERE source = %s AND device = %s "
            "ORDER BY id DESC LIMIT 1",
            [device],
        )
        return _step(row) if row is not None else None

    def last_id(self) -> int:
        row = self._one("SELECT coalesce(max(id), 0) FROM statectl_steps WHERE source = %s", [])
        return int(row[0]) if row else 0

    def processed(self, device: str) -> int:
        row = self._one(
            "SELECT coalesce(max(inbox), 0) FROM statectl_steps WHERE source = %s AND device = %s",
            [device],
        )
        return int(row[0]) if row else 0

    def pending(self, device: str) -> tuple[InboxRow, ...]:
        done = self.processed(device)
        return tuple(r for r in self.inbox(device) if r.seq > done)

    def counts(self) -> dict[str, int]:
        inbox = self._one("SELECT count(*) FROM statectl_inbox WHERE source = %s", [])
        steps = self._one("SELECT count(*) FROM statectl_steps WHERE source = %s", [])
        return {"inbox": int(inbox[0] if inbox else 0), "steps": int(steps[0] if steps else 0)}
