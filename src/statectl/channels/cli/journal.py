"""``statectl journal show|export|replay``: reading a journal back, never writing it.

Separate from the run command: these open a journal read-only (checked first,
refused when it cannot be trusted) and share nothing with a live run."""

from __future__ import annotations

import contextlib
import datetime as dt
import errno
import heapq
import os
import sqlite3
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, TextIO

from statectl.channels.cli.outputs import output, wrote
from statectl.kernel.errors import DiagnosticError, StatectlError, did_you_mean
from statectl.kernel.exits import OK, PROBLEMS, USAGE
from statectl.kernel.model import Chart
from statectl.kernel.semantics import Outcome
from statectl.kernel.text import shown
from statectl.run.journal import (
    JournalError,
    JournalReader,
    export_jsonl,
    load_device,
    replay,
)
from statectl.run.journal.check import journal_files, sqlite_problem
from statectl.run.journal.pg import display_url
from statectl.run.journal.read import JournalSource
from statectl.run.runner.events import (
    parse_time,
)
from statectl.run.runtime import format_data
from statectl.run.runtime.trace import format_record


def _reader(command: str, path: str, err: TextIO) -> JournalSource | int:
    """The checked journal, or the exit code: 2 if there is none, 1 if it cannot be trusted.

    The whole journal is checked before anything is written (journal/check.py), so
    a damaged journal gives a message and no partial output. A ``postgresql://``
    URL reads a shipped journal instead (journal/pg.py); 1 if it cannot be read.
    """
    if path.startswith(("postgresql://", "postgres://")):
        from statectl.run.journal.pg import PgJournalReader

        try:
            return PgJournalReader(path)
        except JournalError as exc:
            err.write(f"statectl journal {command}: {exc}\n")
            return PROBLEMS
    if not Path(path).exists():
        err.write(f"statectl journal {command}: no journal at {path}\n")
        return USAGE
    try:
        return JournalReader(path)
    except JournalError as exc:
        err.write(f"statectl journal {command}: {exc}\n")
        return PROBLEMS


def _reader_in_window(
    command: str, path: str, since: str | None, until: str | None, err: TextIO
) -> tuple[JournalSource, float | None, float | None] | int:
    """The journal and the time window a ``journal show|export`` asks for, or the exit code."""
    try:
        lo = parse_time(since) if since is not None else None
        hi = parse_time(until) if until is not None else None
    except StatectlError as exc:
        err.write(f"statectl journal {command}: {exc}\n")
        return USAGE
    reader = _reader(command, path, err)
    return reader if isinstance(reader, int) else (reader, lo, hi)


def _unknown_device(
    command: str, reader: JournalSource, device: str | None, err: TextIO, *, sent: bool = True
) -> bool:
    """Say so when ``--device`` names no journalled device (a typo), so that
    ``replay --device Motr`` does not replay nothing and pass. With ``sent``, a device
    that only has accepted events here counts: a node journals the link events it sends
    to another node's device (show and export list them; replay needs the chart)."""
    if device is None:
        return False
    names = [d.name for d in reader.devices()]
    if device in names or (sent and next(iter(reader.inbox(device=device)), None) is not None):
        return False
    found = ", ".join(names) or "none"
    err.write(
        f"statectl journal {command}: no device {device!r} in the journal; "
        f"{did_you_mean(device, names)}devices journalled: {found}\n"
    )
    return True


@contextlib.contextmanager
def _reading(command: str, path: str, err: TextIO) -> Iterator[list[int]]:
    """Turn a failure while the journal is read (damage SQLite meets late, I/O) into exit 1.

    Yields a one-element list holding the exit code: 0, or 1 after a failure.
    """
    code = [OK]
    try:
        yield code
    except (JournalError, sqlite3.Error) as exc:
        text = exc if isinstance(exc, JournalError) else sqlite_problem(exc)
        err.write(f"statectl journal {command}: journal {display_url(path)}: {text}\n")
        code[0] = PROBLEMS


def _stamp(wall: Any) -> str:
    """A row's wall-clock time as ISO text; the raw value if no date has it (a damaged row)."""
    try:
        return dt.datetime.fromtimestamp(wall).isoformat(timespec="milliseconds")
    except (OverflowError, OSError, ValueError, TypeError):
        return f"(wall {wall!r})"


def journal_show(
    path: str,
    *,
    device: str | None = None,
    since: str | None = None,
    until: str | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
) -> int:
    """``statectl journal show``: one line per accepted event and step, in order."""
    opened = _reader_in_window("show", path, since, until, err)
    if isinstance(opened, int):
        return opened
    reader, lo, hi = opened

    def accepted() -> Iterator[tuple[float, int, str]]:
        for r in reader.inbox(device, lo, hi):
            data = "" if r.data is None else " " + format_data(r.data)
            yield r.wall, 0, f"#{r.seq:<6} {r.device}  accepted  {r.event}{data}"

    def steps() -> Iterator[tuple[float, int, str]]:
        for s in reader.steps(device, lo, hi):
            what = s.event or ""
            if s.data is not None:
                what += " " + format_data(s.data)
            via = f" (#{s.inbox})" if s.inbox else ""
            state = ", ".join(sorted(s.snapshot.active))
            text = f"step {s.id:<4} {s.device}  {s.kind.value:<8} {what}{via} -> [{state}]"
            if s.outcome and s.outcome != Outcome.HANDLED:
                text += f"  {s.outcome}"
            yield s.wall, 1, text

    with reader, _reading("show", path, err) as code:
        if _unknown_device("show", reader, device, err):
            return PROBLEMS
        # Both come in journal order, which is wall-clock order: merged as they stream, so
        # a journal of millions of rows is shown without being held in memory.
        for wall, _, text in heapq.merge(accepted(), steps(), key=lambda x: (x[0], x[1])):
            out.write(f"{_stamp(wall)}  {shown(text)}\n")  # a name cannot forge a line
    return code[0]


def journal_export(
    path: str,
    *,
    device: str | None = None,
    since: str | None = None,
    until: str | None = None,
    to: str | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
) -> int:
    """``statectl journal export``: JSON Lines (accepted events, then steps).

    ``to`` (``--out FILE``): written to a temporary file beside it and renamed
    over it once complete, so a failure (a damaged row, a full disk) leaves no
    partial file and an existing FILE untouched.
    """
    if to is not None and _is_the_journal(Path(to), path):
        err.write(
            f"statectl journal export: --out {to} is the journal itself (or its -wal/-shm "
            "file); writing there would destroy it: name another file\n"
        )
        return USAGE  # as any --out naming an input (cli/__init__.py)
    opened = _reader_in_window("export", path, since, until, err)
    if isinstance(opened, int):
        return opened
    reader, lo, hi = opened
    with reader, _reading("export", path, err) as code:
        if _unknown_device("export", reader, device, err):
            return PROBLEMS
        if to is None:
            export_jsonl(reader, out, device=device, since=lo, until=hi)
            return OK
        name = f"{Path(path).stem}.jsonl"
        try:
            with output(to, name) as target:  # cli/outputs.py: the one output rule
                n = _export_to(reader, target, device, lo, hi)
        except OSError as exc:
            known = exc.errno in (errno.EISDIR, errno.ENOTDIR)  # said in words above
            why = exc.strerror if known and exc.strerror else sqlite_problem(exc)
            err.write(f"statectl journal export: cannot write {to}: {why}\n")
            code[0] = PROBLEMS
        if code[0] == OK:
            wrote(out, target, f"{n} line(s)")
    return code[0]


def _export_to(
    reader: JournalSource, target: Path, device: str | None, lo: float | None, hi: float | None
) -> int:
    """Export to ``target`` whole or not at all (a temporary file renamed); the lines."""
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        if not target.parent.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, f"{target.parent} is not a directory")
        with tmp.open("w", encoding="utf-8") as f:
            n = export_jsonl(reader, f, device=device, since=lo, until=hi)
        tmp.replace(target)
        return n
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)


def _is_the_journal(target: Path, journal: str) -> bool:
    """Whether ``target`` is the journal file (or one of SQLite's files beside it)."""
    if not target.exists():
        return False
    for beside in journal_files(journal):
        with contextlib.suppress(OSError):
            if beside.exists() and os.path.samefile(target, beside):
                return True
    return False


def journal_replay(
    path: str,
    *,
    device: str | None = None,
    model: Mapping[str, str] | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
) -> int:
    """``statectl journal replay``: rerun the journal on the model; 1 if it disagrees.

    The charts come from the device files the journal names, or ``model``
    (device -> file) where given.
    """
    reader = _reader("replay", path, err)
    if isinstance(reader, int):
        return reader
    with reader, _reading("replay", path, err) as code:
        if _unknown_device("replay", reader, device, err, sent=False):
            return PROBLEMS
        charts: dict[str, Chart] = {}
        for d in reader.devices():
            if device is not None and d.name != device:
                continue
            source = (model or {}).get(d.name, d.source)
            try:
                charts[d.name] = load_device(source).chart
            except DiagnosticError as exc:
                err.write(f"statectl journal replay: {d.name}: cannot load {source}\n")
                for diag in exc.diagnostics:
                    err.write(f"{diag}\n")
                return PROBLEMS
        width = max((len(n) for n in charts), default=0)
        try:
            result = replay(
                reader,
                charts,
                device=device,
                listener=lambda r: print(format_record(r, device_width=width), file=out),
            )
        except JournalError as exc:
            err.write(f"statectl journal replay: {exc}\n")
            return PROBLEMS
    if code[0] != OK:
        return code[0]
    for m in result.mismatches:
        out.write(f"MISMATCH {m}\n")
    for name, snap in sorted(result.final.items()):
        out.write(f"final {name}: {', '.join(sorted(snap.active))}\n")
    out.write(f"{result.steps} step(s) replayed; {len(result.mismatches)} mismatch(es)\n")
    return OK if result.ok else PROBLEMS
