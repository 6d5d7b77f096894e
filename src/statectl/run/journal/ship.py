"""Shipping a journal's committed rows into PostgreSQL, in order, exactly once.

Rules:
1. Only committed rows are shipped: the shipper reads the SQLite journal
   read-only (WAL lets it read beside the running writer) in one short read
   transaction per batch, so each batch is a committed prefix of the journal.
2. Exactly once: each batch is one PostgreSQL transaction that locks the
   source's row in ``statectl_sources`` (``FOR UPDATE``), reads its marks,
   inserts the rows after them (``COPY``) and moves the marks. A crash of the
   shipper or the server before the commit leaves neither rows nor marks; after
   it, both. The next batch starts from the marks in the database, never from
   memory, so a restarted shipper goes on where the last commit left off, and
   two shippers of one source take turns instead of doubling rows (the
   primary keys would refuse a double anyway).
3. A source is bound to its journal by its first step (``origin``): a journal
   set aside and started anew at the same path, or a shorter one, is refused
   (:class:`ShipRefused`) rather than shipped from the wrong place; ship it
   under another source name.
4. Never in a device's way: :class:`ShipThread` runs beside a live run on its
   own thread and connections; the journal's writer only sets an event after
   each commit. A server that is down or goes away is reported once and
   retried every ``retry`` seconds while the devices go on.
"""

from __future__ import annotations

import socket
import sqlite3
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from statectl.run.journal.check import connect_ro, sqlite_problem
from statectl.run.journal.format import JournalError
from statectl.run.journal.pg import (
    INBOX_COLUMNS,
    STEP_COLUMNS,
    _psycopg,
    connect_pg,
    display_url,
    ensure_schema,
    pg_problem,
)

if TYPE_CHECKING:
    import psycopg

__all__ = ["ShipRefused", "ShipResult", "ShipThread", "Shipper", "default_source"]

#: Rows per table per batch (one PostgreSQL transaction).
BATCH = 5000


class ShipRefused(JournalError):
    """The journal is not the one this source was shipped from (rule 3): retrying cannot help."""


@dataclass(frozen=True, slots=True)
class ShipResult:
    """Rows shipped by a call, and the marks the database holds after it."""

    inbox: int
    steps: int
    inbox_upto: int
    steps_upto: int


def default_source(journal: str | Path) -> str:
    """``host:/absolute/path``: unique per controller and journal without configuration."""
    return f"{socket.gethostname()}:{Path(journal).resolve()}"


class Shipper:
    """Ships one journal as one source; not thread-safe (one thread owns it)."""

    def __init__(
        self, journal: str | Path, url: str, *, source: str | None = None, batch: int = BATCH
    ) -> None:
        self.journal = Path(journal)
        self.url = url
        self.where = display_url(url)
        self.source = source or default_source(journal)
        self.batch = batch
        self._db: sqlite3.Connection | None = None
        self._pg: psycopg.Connection[Any] | None = None
        self._devices: tuple[tuple[Any, ...], ...] | None = None  # the last shipped

    def close(self) -> None:
        for conn in (self._db, self._pg):
            if conn is not None:
                conn.close()
        self._db = self._pg = None

    def _sqlite(self) -> sqlite3.Connection:
        if self._db is None:
            if not self.journal.exists():
                raise JournalError(f"no journal at {self.journal}")
            try:
                self._db = connect_ro(self.journal)
            except sqlite3.Error as exc:
                raise JournalError(f"journal {self.journal}: {sqlite_problem(exc)}") from None
            self._db.isolation_level = None
        return self._db

    def _postgres(self) -> psycopg.Connection[Any]:
        if self._pg is None or self._pg.closed:
            conn = connect_pg(self.url)
            try:
                ensure_schema(conn)
            except _psycopg().Error as exc:
                conn.close()
                raise JournalError(f"{self.where}: {pg_problem(exc)}") from None
            self._pg, self._devices = conn, None
        return self._pg

    def _read(
        self, inbox_upto: int, steps_upto: int
    ) -> tuple[str | None, int, list[tuple[Any, ...]], list[tuple[Any, ...]], tuple[Any, ...]]:
        """One committed snapshot: origin, last step id, rows after the marks, devices."""
        db = self._sqlite()
        try:
            db.execute("BEGIN")
            try:
                first = db.execute(
                    "SELECT id, wall, device, kind FROM steps ORDER BY id LIMIT 1"
                ).fetchone()
                last = db.execute("SELECT coalesce(max(id), 0) FROM steps").fetchone()[0]
                inbox = db.execute(
                    "SELECT seq, device, wall, event, data FROM inbox WHERE seq > ? "
                    "ORDER BY seq LIMIT ?",
                    (inbox_upto, self.batch),
                ).fetchall()
                steps = db.execute(
                    "SELECT id, device, kind, inbox, wall, time, event, data, outcome, active, "
                    "history, previous FROM steps WHERE id > ? ORDER BY id LIMIT ?",
                    (steps_upto, self.batch),
                ).fetchall()
                devices = tuple(db.execute("SELECT name, chart, source, data FROM devices"))
            finally:
                db.execute("COMMIT")
        except sqlite3.Error as exc:
            self.close()
            raise JournalError(f"journal {self.journal}: {sqlite_problem(exc)}") from None
        origin = None if first is None else f"{first[0]} {first[1]!r} {first[2]} {first[3]}"
        return origin, int(last), inbox, steps, devices

    def ship_batch(self) -> ShipResult:
        """Ship at most one batch per table in one transaction (rule 2)."""
        psycopg = _psycopg()
        conn = self._postgres()
        try:
            with conn.transaction():
                marks = self._marks(conn)
                if marks is None:  # nothing journalled yet: no source to bind
                    return ShipResult(0, 0, 0, 0)
                origin, inbox_upto, steps_upto = marks
                got, last, inbox, steps, devices = self._read(inbox_upto, steps_upto)
                if got != origin or last < steps_upto:
                    raise ShipRefused(
                        f"{self.where}: source {self.source!r} was shipped from another journal "
                        f"(its first step was {origin}; {self.journal} begins with {got} and ends "
                        f"at step {last}); ship this journal under another name: --source NAME"
                    )
                with conn.cursor() as cur:
                    if devices != self._devices:
                        cur.executemany(
                            "INSERT INTO statectl_devices VALUES (%s, %s, %s, %s, %s) "
                            "ON CONFLICT (source, name) DO UPDATE SET chart = EXCLUDED.chart, "
                            "file = EXCLUDED.file, data = EXCLUDED.data",
                            [(self.source, *d) for d in devices],
                        )
                    self._copy(cur, "statectl_inbox", INBOX_COLUMNS, inbox)
                    self._copy(cur, "statectl_steps", STEP_COLUMNS, steps)
                    inbox_upto = inbox[-1][0] if inbox else inbox_upto
                    steps_upto = steps[-1][0] if steps else steps_upto
                    cur.execute(
                        "UPDATE statectl_sources SET inbox_upto = %s, steps_upto = %s, "
                        "shipped_at = now() WHERE source = %s",
                        (inbox_upto, steps_upto, self.source),
                    )
        except psycopg.Error as exc:
            self.close()  # the next call connects afresh and reads the marks again
            raise JournalError(f"shipping to {self.where}: {pg_problem(exc)}") from None
        self._devices = devices
        return ShipResult(len(inbox), len(steps), inbox_upto, steps_upto)

    def _marks(self, conn: psycopg.Connection[Any]) -> tuple[str, int, int] | None:
        """The source's (origin, inbox_upto, steps_upto), locked; a new source is made here."""
        select = (
            "SELECT origin, inbox_upto, steps_upto FROM statectl_sources "
            "WHERE source = %s FOR UPDATE"
        )
        row = conn.execute(select, (self.source,)).fetchone()
        if row is None:
            origin, *_ = self._read(0, 0)
            if origin is None:
                return None
            conn.execute(
                "INSERT INTO statectl_sources (source, origin) VALUES (%s, %s) "
                "ON CONFLICT (source) DO NOTHING",
                (self.source, origin),
            )
            row = conn.execute(select, (self.source,)).fetchone()
            assert row is not None  # inserted or already there, and locked
        return str(row[0]), int(row[1]), int(row[2])

    def _copy(
        self, cur: psycopg.Cursor[Any], table: str, columns: tuple[str, ...], rows: list[Any]
    ) -> None:
        if not rows:
            return
        with cur.copy(f"COPY {table} ({', '.join(columns)}) FROM STDIN") as copy:
            source = self.source
            for row in rows:
                copy.write_row((source, *row))

    def ship_all(self, stop: Callable[[], bool] = lambda: False) -> ShipResult:
        """Ship batches until caught up with what is committed (or ``stop()``)."""
        inbox = steps = 0
        while True:
            r = self.ship_batch()
            inbox, steps = inbox + r.inbox, steps + r.steps
            if (r.inbox < self.batch and r.steps < self.batch) or stop():
                return ShipResult(inbox, steps, r.inbox_upto, r.steps_upto)


class ShipThread:
    """Ships continuously beside a running node (rule 4); ``wake()`` after each commit."""

    def __init__(
        self,
        shipper: Shipper,
        *,
        interval: float = 0.5,
        retry: float = 5.0,
        report: Callable[[str], object] = print,
    ) -> None:
        self.shipper = shipper
        self.interval = interval
        self.retry = retry
        self.report = report
        self.shipped = 0
        self.failure: str | None = None  # the problem reported, while it lasts
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._drain_until = 0.0
        self._thread = threading.Thread(target=self._run, name="statectl-ship", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def wake(self) -> None:
        """Called by the journal's writer after each commit: only sets an event."""
        self._wake.set()

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(self.interval)
            self._wake.clear()
            if self._stop.is_set():
                break
            if not self._round(self._stop.is_set):
                self.shipper.close()
                return
        if self.failure is None and self._drain_until > time.monotonic():
            self._round(lambda: time.monotonic() > self._drain_until)
        self.shipper.close()

    def _round(self, stop: Callable[[], bool]) -> bool:
        """One catch-up; False when shipping must stop (a refusal)."""
        try:
            r = self.shipper.ship_all(stop)
        except ShipRefused as exc:
            self.report(f"{exc}; shipping stopped, the devices go on")
            return False
        except JournalError as exc:
            if str(exc) != self.failure:
                self.report(f"{exc}; retrying every {self.retry:g} s, the devices go on")
                self.failure = str(exc)
            self._stop.wait(self.retry)
            return True
        if self.failure is not None:
            self.report(f"shipping to {self.shipper.where} resumed")
            self.failure = None
        self.shipped += r.inbox + r.steps
        return True

    def stop(self, drain: float = 5.0) -> None:
        """Stop; first ship what is committed, for about ``drain`` seconds at most.

        The shipper's own thread does it (its SQLite connection is its own); a
        thread stuck on the network is left behind (a daemon) rather than waited for.
        """
        self._drain_until = time.monotonic() + drain
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(drain + 1.0)
