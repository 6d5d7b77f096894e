"""The journal on disk: SQLite in WAL mode, written by one thread with group commit.

Rules:
1. Two tables hold a run. ``inbox`` is every event accepted from outside (an
   operator, a script, the dashboard), numbered by ``seq``. ``steps`` is every
   event a device processed, in order, whatever posted it (inbox, a driver's
   completion, a monitor's fault, a recovery), with the snapshot it left: the
   active states, history and previous state. ``start``, ``restore`` and
   ``recovery`` steps mark how a device came up.
2. Nothing that posts waits for the disk. :meth:`Journal.accept` and
   :meth:`Journal.record` append to an in-memory queue and return at once; one
   writer thread takes everything queued, writes it in one transaction and
   commits (group commit), so many events share one commit.
3. An event is *accepted* only once its inbox row is committed: the
   :class:`Ticket` says so (``durable``, ``wait()``). When the device acts on it
   is the journal's :class:`Guarantee`: ``PROMPT`` (default) at once, its inbox
   row and then its step row committed by the next group commits;
   ``DURABLE_FIRST`` only after the commit (the ``deliver`` callback runs on the
   writer then), so a device never acts on an event the journal could lose.
   Either way an inbox row is queued before the step that processed it, and
   commits keep queue order, so every committed prefix is a history that
   happened. Under ``PROMPT`` a device's inbox row is *held* (``hold=True``):
   it does not wake the writer, which would compete with the device for the
   interpreter while it runs the event, but goes to the writer with the next
   row queued (normally the event's own step) or as soon as anyone asks the
   ticket, flushes or closes.
4. How far a commit goes depends on :class:`Sync`. ``NORMAL`` (default): a committed
   event survives the process being killed (SIGKILL, a crash); after a power
   loss or OS crash the last commits may be missing. ``FULL``: a committed event
   also survives power loss (the commit waits for fsync).
5. Commits are in ``seq`` order, so ``durable_seq`` only grows; a failing write
   stops the writer, fails every waiting ticket and is raised from
   :meth:`Journal.flush` and :meth:`Journal.close`.
6. A step that sends events on (a cell's links) is one queue item with their
   inbox rows (:meth:`Journal.record` with ``sends``), and the writer never
   splits an item between commits: after a crash either the step and the events
   it sent are in the journal, or neither is and the step runs again on resume.
"""

from __future__ import annotations

import contextlib
import os
import queue
import sqlite3
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from statectl.kernel.semantics import Snapshot
from statectl.run.journal.format import (
    Guarantee,
    JournalError,
    StepKind,
    Sync,
    _problem,
    connect_db,
    encode_data,
    encode_snapshot,
)

__all__ = ["Journal", "Send", "Ticket"]


@dataclass(frozen=True, slots=True)
class Ticket:
    """The receipt for one accepted event: it is accepted once ``durable``."""

    seq: int
    journal: Journal

    @property
    def durable(self) -> bool:
        return self.journal.is_durable(self.seq)

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the event is committed (True) or ``timeout`` passes (False)."""
        return self.journal.wait_durable(self.seq, timeout)


#: One queued write: (sql, parameters, seq or 0, deliver(seq) after the commit or None)
_Write = tuple[str, tuple[Any, ...], int, Callable[[int], object] | None]

#: The commit window under ``Guarantee.PROMPT``: the writer, woken by a first row,
#: sleeps this long before it takes the batch, so the owner finishes the events it
#: is running (and their rows join the commit) before the writer's Python work
#: between SQLite calls competes with it for the interpreter (measured on 2 vCPUs:
#: post -> observer call ~45 us with the window, ~55 us without).
#: ``DURABLE_FIRST`` has no window: its device waits for the commit.
PROMPT_COMMIT_DELAY = 0.0002

#: Bound parameters per statement; SQLite allows 32,766 since 3.32 and 999 before.
_MAX_VARIABLES = 32_766 if sqlite3.sqlite_version_info >= (3, 32, 0) else 999
_INSERT_INBOX = "INSERT INTO inbox VALUES (?, ?, ?, ?, ?)"
_INSERT_STEP = "INSERT INTO steps VALUES (NULL, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)"
_NOTE = "INSERT OR REPLACE INTO meta VALUES (?, ?)"
_STOP = None  # put on the queue by close(): the writer commits what came before and ends
_GROUP = "group"  # the sql of a queue item whose parameters are writes that commit together


@dataclass(frozen=True, slots=True)
class Send:
    """An event a step sends to a device (a cell's link), accepted with the step's row."""

    device: str
    event: str
    data: Any = None
    deliver: Callable[[int], object] | None = None  # as for accept(); None under PROMPT


def _report(fn: Callable[[], object]) -> None:
    """Run a callback of the writer; one that fails is reported, never stops the journal."""
    try:
        fn()
    except Exception:
        traceback.print_exc(file=sys.stderr)


class Journal:
    """The writer side: accept events, record steps, commit in groups on one thread.

    The hot path (rule 2-3), ``DURABLE_FIRST``: a post appends to a C-level queue under a plain lock
    (which keeps ``seq`` order equal to queue order) and the writer, blocked in
    that queue, wakes at once. It takes everything queued (up to ``max_batch``),
    writes it in one transaction, commits, hands each accepted event to its
    ``deliver`` callback, marks the batch durable and then runs the
    :meth:`after_commit` hooks (a :class:`~statectl.run.runner.System` drains its
    devices there when their owner is idle), all in the same wake-up.

    An existing journal is checked first (``check``, see journal/check.py) and
    refused with :class:`~statectl.run.journal.check.JournalDamaged` if it cannot be
    trusted. A write that fails (a full disk, a file made read-only) is rolled
    back, so the file keeps every commit before it whole (rule 5).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        sync: Sync = Sync.NORMAL,
        guarantee: Guarantee | str = Guarantee.PROMPT,
        commit_delay: float | None = None,
        max_batch: int = 20_000,
        check: bool = True,
    ):
        self.path = Path(path)
        self.sync = sync
        try:
            self.guarantee = Guarantee(guarantee)
        except ValueError:
            choices = " or ".join(g.value for g in Guarantee)
            raise JournalError(f"guarantee must be {choices} (got {guarantee!r})") from None
        if commit_delay is None:
            commit_delay = PROMPT_COMMIT_DELAY if self.guarantee is Guarantee.PROMPT else 0.0
        self.commit_delay = commit_delay
        self.max_batch = max_batch
        if check and self.path.exists():
            from statectl.run.journal.check import check_journal  # it imports this module

            check_journal(self.path, reader=False)
            if not (os.access(self.path, os.W_OK) and os.access(self.path.parent, os.W_OK)):
                raise JournalError(
                    f"journal {self.path}: it is read-only (the file or its directory cannot "
                    "be written); statectl appends to a journal and writes its -wal and -shm "
                    "files beside it: make them writable, or give another --journal"
                )
        self._db = connect_db(self.path, sync=sync)
        last = self._db.execute("SELECT max(seq) FROM inbox").fetchone()[0]
        self._seq = int(last or 0)
        self.durable_seq = self._seq
        self._queue: queue.SimpleQueue[_Write | None] = queue.SimpleQueue()
        self._held: list[_Write] = []  # accepted with hold=True, not yet queued
        self._lock = threading.Lock()  # seq + enqueue, atomically
        self._cond = threading.Condition()  # waiters for durability and flush
        self._waiters = 0
        self._hooks: tuple[Callable[[], object], ...] = ()
        self._closing = False
        self._failure: BaseException | None = None
        self._enqueued = 0  # writes queued so far
        self._done = 0  # writes committed and delivered so far
        self.commits = 0
        self.rows = 0
        self._thread = threading.Thread(target=self._run, name="statectl-journal", daemon=True)
        self._thread.start()

    # -- any thread ----------------------------------------------------------------------------

    def accept(
        self,
        device: str,
        event: str,
        data: Any = None,
        deliver: Callable[[int], object] | None = None,
        *,
        hold: bool = False,
        note: tuple[str, str] | None = None,
    ) -> Ticket:
        """Queue an inbox row; ``deliver(seq)`` runs on the writer after it is committed.

        ``hold``: do not wake the writer for this row; it goes with the next row
        queued (the step that processes the event) or when anyone asks the ticket,
        :meth:`flush` or :meth:`close`. Rows keep their order either way.
        ``note``: a ``meta`` row (key, value) committed with the inbox row, never
        without it (a link event from another node and how far that link got).
        """
        text = encode_data(data)
        wall = time.time()
        with self._lock:
            self._check()
            self._seq += 1
            seq = self._seq
            self._enqueued += 1
            write: _Write = (_INSERT_INBOX, (seq, device, wall, event, text), seq, deliver)
            if note is not None:  # one queue item: never split between commits (rule 6)
                self._enqueued += 1
                write = (_GROUP, (write, (_NOTE, note, 0, None)), 0, None)
            if hold:
                self._held.append(write)
            else:
                if self._held:
                    self._release()
                self._queue.put(write)
        return Ticket(seq, self)

    def record(
        self,
        device: str,
        kind: StepKind,
        snapshot: Snapshot,
        *,
        time_: float,
        event: str | None = None,
        data: Any = None,
        inbox: int | None = None,
        outcome: str = "",
        sends: Sequence[Send] = (),
    ) -> tuple[int, ...]:
        """Queue a step row (what a device did); never blocks.

        ``sends`` are events the step sends on (a cell's links): each is accepted
        with the step, in one queue item, so one commit holds the step and its
        inbox rows or neither does (rule 6). Returns their ``seq`` numbers.
        """
        active, history, previous = encode_snapshot(snapshot)
        params = (
            device, kind.value, inbox, time.time(), time_, event, encode_data(data), outcome,
            active, history, previous,
        )  # fmt: skip
        step: _Write = (_INSERT_STEP, params, 0, None)
        if not sends:
            self._put(step)
            return ()
        texts = [encode_data(s.data) for s in sends]
        wall = time.time()
        with self._lock:
            self._check()
            if self._held:
                self._release()
            writes: list[_Write] = []
            for s, text in zip(sends, texts, strict=True):
                self._seq += 1
                seq = self._seq
                writes.append((_INSERT_INBOX, (seq, s.device, wall, s.event, text), seq, s.deliver))
            writes.append(step)
            self._enqueued += len(writes)
            self._queue.put((_GROUP, tuple(writes), 0, None))
            return tuple(w[2] for w in writes[:-1])

    def note(self, key: str, value: str) -> None:
        """Queue a ``meta`` row (key, value), committed in queue order with the rest."""
        self._put((_NOTE, (key, value), 0, None))

    def register(self, name: str, chart: str, source: str, data: Any) -> None:
        """Note which chart (and file) a device runs, for ``journal replay``."""
        sql = "INSERT OR REPLACE INTO devices VALUES (?, ?, ?, ?)"
        self._put((sql, (name, chart, source, encode_data(data)), 0, None))

    def after_commit(self, hook: Callable[[], object]) -> None:
        """Run ``hook()`` on the writer after each commit's deliveries (same wake-up)."""
        self._hooks = (*self._hooks, hook)

    def _put(self, write: _Write) -> None:
        with self._lock:
            self._check()
            self._enqueued += 1
            if self._held:
                self._release()
            self._queue.put(write)

    def _release(self) -> None:
        """Under ``_lock``: hand the held rows to the writer, in order."""
        put = self._queue.put
        for w in self._held:
            put(w)
        self._held.clear()

    def kick(self) -> None:
        """Hand held rows to the writer now (see ``accept(hold=True)``)."""
        if self._held:
            with self._lock:
                if self._held:
                    self._release()

    def is_durable(self, seq: int) -> bool:
        """Whether ``seq`` is committed; asking hands a held row to the writer."""
        if self.durable_seq >= seq:
            return True
        self.kick()
        return False

    def wait_durable(self, seq: int, timeout: float | None = None) -> bool:
        self.kick()
        return self._wait(lambda: self.durable_seq >= seq, timeout)

    def flush(self, timeout: float | None = None) -> bool:
        """Wait until everything queued so far is committed (and its events delivered)."""
        self.kick()
        target = self._enqueued
        ok = self._wait(lambda: self._done >= target, timeout)
        if self._failure is not None:
            raise self._failed()
        return ok

    def _wait(self, done: Callable[[], bool], timeout: float | None) -> bool:
        if done():
            return True
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            self._waiters += 1
            try:
                while not done():
                    if self._failure is not None:
                        raise self._failed()
                    left = None if deadline is None else deadline - time.monotonic()
                    if left is not None and left <= 0:
                        return False
                    self._cond.wait(left)
            finally:
                self._waiters -= 1
        return True

    def close(self) -> None:
        """Commit what is queued, stop the writer and close the database."""
        with self._lock:
            if self._closing:
                return
            self._closing = True
            self._release()
            self._queue.put(_STOP)
        self._thread.join()
        self._db.close()
        if self._failure is not None:
            raise self._failed()

    @property
    def queued(self) -> int:
        return self._enqueued - self._done

    def _failed(self) -> JournalError:
        """The error every caller gets once a write failed: what, where, and what to do."""
        problem = _problem(self._failure or Exception(), self.path.parent)
        return JournalError(
            f"journal {self.path}: write failed: {problem}; "
            "nothing after the last commit is accepted (the journal keeps everything before "
            "it: resume with --resume once the cause is fixed)"
        )

    def _check(self) -> None:
        if self._closing:
            raise JournalError(f"journal {self.path} is closed")
        if self._failure is not None:
            raise self._failed()

    # -- the writer thread -----------------------------------------------------------------------

    def _run(self) -> None:
        db = self._db
        take = self._queue.get
        more = self._queue.get_nowait
        delay = self.commit_delay
        while True:
            first = take()
            if delay and first is not None:
                time.sleep(delay)  # the commit window: see __init__
            stop = first is None
            batch: list[_Write] = []
            if first is not None:
                self._take(batch, first)
            while not stop and len(batch) < self.max_batch:
                try:
                    w = more()
                except queue.Empty:
                    break
                if w is None:
                    stop = True
                else:
                    self._take(batch, w)
            if batch and not self._commit(db, batch):
                return
            if stop:
                return

    @staticmethod
    def _take(batch: list[_Write], w: _Write) -> None:
        """Add a queue item to the batch; a group's writes all go in (rule 6)."""
        if w[0] == _GROUP:
            batch.extend(w[1])
        else:
            batch.append(w)

    def _commit(self, db: sqlite3.Connection, batch: list[_Write]) -> bool:
        """Write, commit, deliver, mark durable, run the hooks; False if the write failed."""
        try:
            db.execute("BEGIN")
            self._write(db, batch)
            db.execute("COMMIT")
        except BaseException as exc:  # the writer must report, never die silently
            with contextlib.suppress(sqlite3.Error):  # SQLite may have rolled it back already
                db.execute("ROLLBACK")  # nothing half-written: the transaction goes entirely
            with self._cond:
                self._failure = exc
                self._cond.notify_all()
            return False
        top = 0
        for _, _, seq, deliver in batch:
            if seq:
                top = seq
                if deliver is not None:
                    try:
                        deliver(seq)
                    except Exception:  # a failing delivery must not stop the journal
                        traceback.print_exc(file=sys.stderr)
        self.commits += 1
        self.rows += len(batch)
        if top > self.durable_seq:
            self.durable_seq = top  # seq order is queue order: everything below is in too
        self._done += len(batch)
        if self._waiters:
            with self._cond:
                self._cond.notify_all()
        for hook in self._hooks:
            _report(hook)
        return True

    @staticmethod
    def _write(db: sqlite3.Connection, batch: list[_Write]) -> None:
        """Insert the rows of each statement as multi-row INSERTs, in their order.

        sqlite3 releases the GIL for every statement it steps; while an owner
        thread keeps the interpreter busy, each release costs the writer a whole
        switch interval to get it back (a convoy: seconds for a batch of thousands
        of rows, one statement each). Many rows per statement make that a handful.
        Rows are grouped per statement (table), not per run: under the prompt
        guarantee inbox and step rows alternate. The batch is one transaction and
        no table's rows refer to another's order (an inbox row carries its ``seq``),
        so only the order within a table counts, and it is kept.
        """
        groups: dict[str, list[tuple[Any, ...]]] = {}
        for w in batch:
            rows = groups.get(w[0])
            if rows is None:
                groups[w[0]] = [w[1]]
            else:
                rows.append(w[1])
        for sql, rows in groups.items():
            head, sep, values = sql.partition(" VALUES ")
            if len(rows) == 1 or not sep:
                db.executemany(sql, rows)
                continue
            per = max(1, _MAX_VARIABLES // max(1, len(rows[0])))
            for k in range(0, len(rows), per):
                chunk = rows[k : k + per]
                db.execute(
                    f"{head} VALUES {', '.join([values] * len(chunk))}",
                    [v for row in chunk for v in row],
                )
