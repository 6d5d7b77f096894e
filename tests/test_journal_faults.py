"""The journal under faults: every damaged journal is refused by every command, clearly.

One table of faults (what is done to a good journal, what the message must say) runs
through one helper against each command that reads a journal: ``journal show``,
``journal export`` (to standard output and to a file), ``journal replay`` and
``run --resume``. Each must exit 1 with a message naming the journal and the fault,
write nothing on standard output (and no file), and leave the journal as it was.
A full disk and a read-only journal need a file system of their own (a small tmpfs);
those tests skip when the machine does not allow mounting one.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import sqlite3
import subprocess
import sys
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from statectl.channels.cli import main
from statectl.channels.cli.run import run
from statectl.kernel.exits import BROKEN_PIPE
from statectl.kernel.semantics import Snapshot
from statectl.run.journal import (
    Journal,
    JournalDamaged,
    JournalError,
    JournalReader,
    StepKind,
    check_journal,
    load_device,
    replay,
)
from statectl.run.runner import DeviceSetup, System
from statectl.run.runtime import SimClock

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
SRC = Path(__file__).parent.parent / "src"
EVENTS = "Movement {amount: 2}\n+5\nMovement {amount: 1}\n+5\nMovement {amount: 3}\n"


@pytest.fixture(scope="module")
def good_journal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A journal of a real run: three movements of the shipped Motor, closed cleanly."""
    where = tmp_path_factory.mktemp("good")
    db = where / "run.db"
    code = run(str(MOTOR), journal=str(db), events=io.StringIO(EVENTS), out=io.StringIO())
    assert code == 0
    return db


def sql(*statements: str) -> Callable[[Path], None]:
    def damage(db: Path) -> None:
        con = sqlite3.connect(db)
        try:
            for s in statements:
                con.execute(s)
            con.commit()
        finally:
            con.close()

    return damage


def truncate(db: Path) -> None:
    with db.open("r+b") as f:
        f.truncate(db.stat().st_size // 2)


def flip_bytes(db: Path) -> None:
    """Invert 64 bytes at the start of the third page: a b-tree page's header."""
    with db.open("r+b") as f:
        page = int.from_bytes(f.read(18)[16:18], "big")
        f.seek(2 * page)
        block = f.read(64)
        f.seek(2 * page)
        f.write(bytes(b ^ 0xFF for b in block))


def not_sqlite(db: Path) -> None:
    db.write_text("device,event\nMotor,Movement\n", encoding="utf-8")


def empty(db: Path) -> None:
    db.write_bytes(b"")


def directory(db: Path) -> None:
    db.unlink()
    db.mkdir()


COPY_STEP = (
    "INSERT INTO steps SELECT NULL, device, kind, inbox, wall, time, event, data, outcome, "
    "active, history, previous FROM steps WHERE inbox = 1"
)

LAST = "id = (SELECT max(id) FROM steps)"  # the step resume reads
PENDING = "INSERT INTO inbox VALUES (99, 'Motor', 0, 'Movement', '{oops')"  # resume reads it

# (fault, what is done to a good journal, what the message says)
FAULTS: list[tuple[str, Callable[[Path], None], str]] = [
    ("truncated", truncate, "is truncated"),
    ("flipped bytes", flip_bytes, "damaged"),
    ("not SQLite", not_sqlite, "not a SQLite database"),
    ("empty", empty, "empty (0 bytes)"),
    ("a directory", directory, "is a directory"),
    ("steps table dropped", sql("DROP TABLE steps"), "table steps is missing"),
    ("inbox table dropped", sql("DROP TABLE inbox"), "table inbox is missing"),
    ("newer schema", sql("UPDATE meta SET value = '2'"), "schema version is '2'"),
    ("no schema version", sql("DELETE FROM meta"), "no schema version"),
    ("unknown step kind", sql("UPDATE steps SET kind = 'teleport' WHERE id = 2"), "'teleport'"),
    ("step of wrong type", sql(f"UPDATE steps SET active = 42 WHERE {LAST}"), "wrong type"),
    ("step data not JSON", sql(f"UPDATE steps SET data = '{{oops' WHERE {LAST}"), "wrong type"),
    ("event data not JSON", sql(PENDING), "accepted events with columns of the wrong type: #99"),
    ("event applied twice", sql(COPY_STEP), "applied more than once: #1 by steps 2, "),
    ("steps missing", sql("DELETE FROM steps WHERE inbox = 1"), "steps are missing"),
    ("step of no event", sql("DELETE FROM inbox WHERE seq = 2"), "does not hold"),
]


def damaged(good: Path, tmp_path: Path, fault: Callable[[Path], None]) -> Path:
    db = tmp_path / "run.db"
    shutil.copyfile(good, db)
    fault(db)
    return db


def snapshot_of(path: Path) -> bytes | None:
    return path.read_bytes() if path.is_file() else None


def command(name: str, db: Path, tmp_path: Path) -> list[str]:
    return {
        "show": ["journal", "show", str(db)],
        "export": ["journal", "export", str(db)],
        "export --out": ["journal", "export", str(db), "--out", str(tmp_path / "out.jsonl")],
        "replay": ["journal", "replay", str(db)],
        "run --resume": ["run", str(MOTOR), "--journal", str(db), "--resume"],
    }[name]


COMMANDS = ["show", "export", "export --out", "replay", "run --resume"]


def cli(argv: list[str], monkeypatch: pytest.MonkeyPatch) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    monkeypatch.setattr(sys, "stdin", io.StringIO("Movement {amount: 1}\n"))
    code = main(argv, out, err)
    return code, out.getvalue(), err.getvalue()


@pytest.mark.parametrize("name", COMMANDS)
@pytest.mark.parametrize(("fault", "damage", "says"), FAULTS, ids=[f[0] for f in FAULTS])
def test_every_command_refuses_a_damaged_journal(
    good_journal: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    name: str,
    fault: str,
    damage: Callable[[Path], None],
    says: str,
) -> None:
    """Exit 1, one message naming the journal and the fault, no output, the journal untouched."""
    db = damaged(good_journal, tmp_path, damage)
    before = snapshot_of(db)
    code, out, err = cli(command(name, db, tmp_path), monkeypatch)
    assert (code, says in err, str(db) in err) == (1, True, True), err
    assert out == ""  # nothing shown, exported or started
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.db"]  # no output file, no temp
    assert snapshot_of(db) == before


# (fault, damage of the right SQL type that only decoding the row finds, what the message says)
DECODE_FAULTS: list[tuple[str, Callable[[Path], None], str]] = [
    (
        "active not state names",
        sql(f"UPDATE steps SET active = '[1, 2]' WHERE {LAST}"),
        "active states are not a list of state names",
    ),
    (
        "history not pairs",
        sql(f"UPDATE steps SET history = '[[1]]' WHERE {LAST}"),
        "history is not a list of [state, [states]]",
    ),
    (
        "datamodel not an object",
        sql("UPDATE devices SET data = '5'"),
        "its data is not a JSON object",
    ),
]


@pytest.mark.parametrize("argv", [["journal", "replay"], ["coverage"]])
@pytest.mark.parametrize(
    ("fault", "damage", "says"), DECODE_FAULTS, ids=[f[0] for f in DECODE_FAULTS]
)
def test_a_row_of_the_right_type_that_does_not_decode_is_refused(
    good_journal: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    argv: list[str],
    fault: str,
    damage: Callable[[Path], None],
    says: str,
) -> None:
    """Text columns holding JSON no journal writes: exit 1 naming the fault, not a
    TypeError or KeyError from the replay or the coverage walk."""
    db = damaged(good_journal, tmp_path, damage)
    extra = [str(MOTOR)] if argv == ["coverage"] else []
    code, _out, err = cli([*argv, str(db), *extra], monkeypatch)
    assert (code, says in err) == (1, True), err


def test_show_prints_a_wall_time_no_date_holds_as_it_is(
    good_journal: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A step's wall time out of the date range is shown raw, not an OverflowError."""
    db = damaged(good_journal, tmp_path, sql(f"UPDATE steps SET wall = 1e999 WHERE {LAST}"))
    code, out, err = cli(command("show", db, tmp_path), monkeypatch)
    assert (code, "(wall inf)" in out) == (0, True), err


def test_a_bad_row_resume_does_not_read_is_refused_by_readers_only(
    good_journal: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An old event's data that is not JSON: show refuses it; resume, which never reads
    it (and checks only the rows it reads, to stay fast), resumes."""
    db = damaged(good_journal, tmp_path, sql("UPDATE inbox SET data = '{oops' WHERE seq = 1"))
    shown = cli(command("show", db, tmp_path), monkeypatch)
    assert (shown[0], "accepted events with columns of the wrong type: #1" in shown[2]) == (
        1,
        True,
    )
    resumed = cli(command("run --resume", db, tmp_path), monkeypatch)
    assert (resumed[0], "resumed Motor in Blocked" in resumed[1]) == (0, True), resumed[2]


def test_a_bad_old_step_a_redo_walks_back_to_fails_the_resume_clearly(tmp_path: Path) -> None:
    """Resume reads an untyped old step only for a redo: a row that does not parse is named."""
    db = tmp_path / "run.db"
    dev = load_device(MOTOR)
    first = System(
        (DeviceSetup("Motor", dev.chart, dev.rules, str(MOTOR)),), SimClock(), Journal(db)
    )
    first.start()
    for event in ("Movement", "Error"):  # Returning, which the Motor's redo rule redoes
        first.post(None, event)
        first.drain()
    first.close()
    sql("UPDATE steps SET history = 'oops' WHERE event = 'Movement'")(db)
    out, err = io.StringIO(), io.StringIO()
    code = run(str(MOTOR), journal=str(db), resume=True, events=io.StringIO(), out=out, err=err)
    assert (code, f"journal {db}: step 2 cannot be read" in err.getvalue()) == (1, True), err


def test_a_journal_without_steps_is_not_resumed_and_nothing_is_redelivered(
    good_journal: Path, tmp_path: Path
) -> None:
    """Dropping ``steps`` used to resume with exit 0 and send every old Movement again."""
    db = damaged(good_journal, tmp_path, sql("DROP TABLE steps"))
    out, err = io.StringIO(), io.StringIO()
    code = run(str(MOTOR), journal=str(db), resume=True, events=io.StringIO(), out=out, err=err)
    assert (code, "Movement" in out.getvalue()) == (1, False)
    assert "--fresh" in err.getvalue()
    with sqlite3.connect(db) as con:  # the table was not made again behind the user's back
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert "steps" not in tables


def test_a_journal_of_another_chart_is_refused_and_left_as_it_was(
    good_journal: Path, tmp_path: Path
) -> None:
    """Resuming with a device file whose states differ from the journalled ones (Moving
    renamed) is refused with what to do, and the journal still names its own chart: the
    refused resume used to rewrite the ``devices`` row, so replay then mismatched."""
    other = tmp_path / "renamed.yaml"
    other.write_text(MOTOR.read_text().replace("Moving", "Running"))
    db = damaged(good_journal, tmp_path, lambda _: None)
    before = snapshot_of(db)
    out, err = io.StringIO(), io.StringIO()
    code = run(str(other), journal=str(db), resume=True, events=io.StringIO(), out=out, err=err)
    said = err.getvalue()
    assert (code, "written by another chart" in said, "Moving" in said) == (1, True, True), said
    assert ("Nothing was started" in said, "resumed" in out.getvalue()) == (True, False)
    assert snapshot_of(db) == before
    with JournalReader(db) as reader:
        row = reader.device("Motor")
    assert row is not None and row.source == str(MOTOR)


def test_replay_names_an_event_applied_twice_even_unchecked(
    good_journal: Path, tmp_path: Path
) -> None:
    """replay() itself refuses a second step for one accepted event, naming both steps."""
    db = damaged(good_journal, tmp_path, sql(COPY_STEP))
    with JournalReader(db, check=False) as reader, pytest.raises(JournalError) as caught:
        replay(reader, {"Motor": load_device(MOTOR).chart})
    assert "accepted event #1 (Motor: Movement) was applied twice, by steps 2 and" in str(
        caught.value
    )


@pytest.mark.parametrize("resume", [True, False])
def test_fresh_sets_the_old_journal_aside_and_says_where(
    good_journal: Path, tmp_path: Path, resume: bool
) -> None:
    """--fresh renames the journal with a timestamp and starts a new one; --resume --fresh
    does so only for a journal it cannot trust."""
    db = damaged(good_journal, tmp_path, sql("DROP TABLE steps"))
    before = db.read_bytes()
    out = io.StringIO()
    code = run(
        str(MOTOR), journal=str(db), resume=resume, fresh=True, events=io.StringIO(), out=out
    )
    aside = [p for p in tmp_path.iterdir() if p.name.startswith("run.db.")]
    assert (code, len(aside)) == (0, 1)
    assert f"set aside as {aside[0]}" in out.getvalue()
    assert aside[0].read_bytes() == before
    check_journal(db)  # the new journal is whole
    with JournalReader(db) as reader:
        assert [s.kind for s in reader.steps()] == [StepKind.START]


def test_resume_fresh_resumes_a_journal_it_can_trust(good_journal: Path, tmp_path: Path) -> None:
    """--resume --fresh on a good journal resumes it and sets nothing aside."""
    db = damaged(good_journal, tmp_path, lambda db: None)
    out = io.StringIO()
    code = run(str(MOTOR), journal=str(db), resume=True, fresh=True, events=io.StringIO(), out=out)
    assert (code, "resumed Motor in Blocked" in out.getvalue()) == (0, True)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("run.db")) == ["run.db"]


def test_fresh_needs_a_journal(tmp_path: Path) -> None:
    """--fresh without --journal is a usage error."""
    err = io.StringIO()
    assert run(str(MOTOR), fresh=True, events=io.StringIO(), err=err) == 2
    assert "--fresh needs --journal" in err.getvalue()


# --- a reader that goes away -----------------------------------------------------------------


@pytest.fixture(scope="module")
def long_journal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A journal whose show/export output is far larger than a pipe's buffer."""
    db = tmp_path_factory.mktemp("long") / "long.db"
    journal = Journal(db)
    blocked = Snapshot(frozenset({"Blocked"}), (), None)
    journal.register("Motor", "Motor", str(MOTOR), {})
    journal.record("Motor", StepKind.START, blocked, time_=0.0)
    for i in range(3000):
        seq = journal.accept("Motor", "Initialization").seq
        journal.record(
            "Motor", StepKind.EVENT, blocked, time_=i, event="Initialization", inbox=seq,
            outcome="guard false",
        )  # fmt: skip
    journal.close()
    return db


@pytest.mark.parametrize("name", ["show", "export", "replay", "run"])
def test_a_reader_that_goes_away_ends_the_command_quietly(
    long_journal: Path, tmp_path: Path, name: str
) -> None:
    """``statectl journal show DB | head -1``: no traceback, the exit status of SIGPIPE."""
    env = {**os.environ, "PYTHONPATH": f"{SRC}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    argv = ["journal", name, str(long_journal)]
    events = tmp_path / "events.txt"
    events.write_text("Movement {amount: 1}\n+2\n" * 3000, encoding="utf-8")
    if name == "run":  # its trace streams too
        argv = ["run", str(MOTOR), "--journal", str(tmp_path / "run.db")]
    with events.open("rb") as stdin:
        child = subprocess.Popen(
            [sys.executable, "-m", "statectl", *argv],
            stdin=stdin,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
        )
    assert child.stdout is not None and child.stderr is not None
    first = child.stdout.readline()
    child.stdout.close()  # what head does after its line
    err = child.stderr.read().decode()
    child.stderr.close()
    code = child.wait(timeout=60)
    assert first
    assert (code, err) == (BROKEN_PIPE, "")


@pytest.mark.parametrize(("reader_open", "code"), [(False, BROKEN_PIPE), (True, 1)])
def test_a_broken_pipe_elsewhere_is_an_error(
    monkeypatch: pytest.MonkeyPatch, reader_open: bool, code: int
) -> None:
    """Only a closed standard output ends quietly; a broken pipe of another kind is reported."""
    import statectl.channels.cli

    def broken(*_: object) -> int:
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(statectl.channels.cli, "cmd_journal", broken)
    read, write = os.pipe()
    if not reader_open:
        os.close(read)
    err = io.StringIO()
    with os.fdopen(write, "w") as out:
        got = main(["journal", "show", "x.db"], out, err)
    if reader_open:
        os.close(read)
    assert (got, "Broken pipe" in err.getvalue()) == (code, reader_open)


# --- a file system of its own: full, read-only ---------------------------------------------


@contextlib.contextmanager
def tmpfs(where: Path, size: str) -> Iterator[Path]:
    """A small tmpfs at ``where``; skips the test where mounting is not allowed."""
    where.mkdir()
    if sys.platform != "linux" or shutil.which("mount") is None:
        pytest.skip("needs Linux mount")
    made = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", f"statectl-{uuid.uuid4().hex[:8]}",
         str(where)],
        capture_output=True,
        check=False,
    )  # fmt: skip
    if made.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {made.stderr.decode().strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def fill(directory: Path) -> None:
    """Take every free byte of ``directory``'s file system."""
    with contextlib.suppress(OSError), (directory / "filler").open("wb") as f:
        while True:
            f.write(b"\0" * 4096)
            f.flush()


def grow(disk: Path) -> None:
    """Make room on the tmpfs: the disk full no more."""
    subprocess.run(["mount", "-o", "remount,size=16m", str(disk)], check=True)


def test_a_full_disk_stops_the_run_keeps_every_acknowledged_event(tmp_path: Path) -> None:
    """On a full disk a post fails clearly; what was acknowledged is in the journal, whole."""
    chart = load_device(MOTOR)
    with tmpfs(tmp_path / "disk", "1m") as disk:
        db = disk / "run.db"
        setup = DeviceSetup("Motor", chart.chart, chart.rules, str(MOTOR))
        system = System((setup,), SimClock(), Journal(db))
        system.start()
        acknowledged: list[int] = []
        failure = None
        try:
            for i in range(5000):  # each posts 2 kB: far more than the space left
                ticket = system.post(None, "Initialization", {"pad": "x" * 2000, "i": i})
                assert ticket is not None
                ticket.wait(10.0)
                acknowledged.append(ticket.seq)
                system.drain()
        except JournalError as exc:
            failure = str(exc)
        with pytest.raises(JournalError):
            system.close()
        assert failure is not None and "the disk is full" in failure and str(db) in failure
        assert acknowledged  # the disk filled up during the run, not before it
        grow(disk)
        check_journal(db)  # whole: the failed transaction left nothing behind
        with JournalReader(db) as reader:
            kept = {r.seq for r in reader.inbox()}
            assert set(acknowledged) <= kept
            assert replay(reader, {"Motor": chart.chart}).ok
        resumed = System((setup,), SimClock(), Journal(db))
        try:
            assert resumed.start(resume=True) == {"Motor": True}
        finally:
            resumed.close()


def test_a_resume_on_a_full_disk_fails_before_anything_reaches_the_device(
    tmp_path: Path,
) -> None:
    """The restore is committed first: on a full disk resume fails, the pending event unsent."""
    chart = load_device(MOTOR)
    setup = DeviceSetup("Motor", chart.chart, chart.rules, str(MOTOR))
    with tmpfs(tmp_path / "disk", "1m") as disk:
        db = disk / "run.db"
        first = System((setup,), SimClock(), Journal(db))
        first.start()
        with first.owner:  # accepted, never processed: resume would redeliver it
            ticket = first.post(None, "Movement", {"amount": 1})
            assert ticket is not None and ticket.wait(5.0)
            first.close()
        again = System((setup,), SimClock(), Journal(db))
        assert again.journal is not None
        again.journal.flush()  # the devices rows: what is written next is the restore
        fill(disk)
        with pytest.raises(JournalError, match="the disk is full"):
            again.start(resume=True)
        assert (again.subjects["Motor"].queued, again.bound["Motor"].redelivered) == (0, 0)
        with pytest.raises(JournalError):
            again.close()


def test_a_full_disk_fails_the_command_line_run_and_export(tmp_path: Path) -> None:
    """``statectl run`` says which line was not accepted and why; export leaves no file."""
    with tmpfs(tmp_path / "disk", "1m") as disk:
        db = disk / "run.db"
        lines = "".join(f"Initialization {{pad: {'x' * 2000}}}\n" for _ in range(600))
        out, err = io.StringIO(), io.StringIO()
        code = run(str(MOTOR), journal=str(db), events=io.StringIO(lines), out=out, err=err)
        text = err.getvalue()
        assert (code, "the disk is full" in text, "line " in text) == (1, True, True), text
        assert "Traceback" not in text
        fill(disk)
        got = main(["journal", "export", str(db), "--out", str(disk / "out.jsonl")],
                   io.StringIO(), err := io.StringIO())  # fmt: skip
        assert (got, "disk is full" in err.getvalue()) == (1, True), err.getvalue()
        assert not [p for p in disk.iterdir() if "out.jsonl" in p.name]
        grow(disk)
        assert main(["journal", "replay", str(db)], io.StringIO(), io.StringIO()) == 0


def test_a_read_only_journal_is_read_but_not_resumed(good_journal: Path, tmp_path: Path) -> None:
    """show/export/replay read a journal on a read-only file system; --resume says why not."""
    with tmpfs(tmp_path / "disk", "4m") as disk:
        db = disk / "run.db"
        shutil.copyfile(good_journal, db)
        remount = subprocess.run(
            ["mount", "-o", "remount,ro", str(disk)], capture_output=True, check=False
        )
        if remount.returncode != 0:
            pytest.skip(f"cannot remount read-only: {remount.stderr.decode().strip()}")
        for argv in (["show"], ["export"], ["replay"]):
            out, err = io.StringIO(), io.StringIO()
            assert main(["journal", *argv, str(db)], out, err) == 0, err.getvalue()
            assert out.getvalue()
        out, err = io.StringIO(), io.StringIO()
        code = run(str(MOTOR), journal=str(db), resume=True, events=io.StringIO(), out=out,
                   err=err)  # fmt: skip
        assert (code, "read-only" in err.getvalue(), str(db) in err.getvalue()) == (1, True, True)
        with pytest.raises(JournalError, match="read-only"):
            Journal(db)


def test_check_journal_finds_a_damaged_journal_as_a_value(
    good_journal: Path, tmp_path: Path
) -> None:
    """JournalDamaged carries its path and one line per problem."""
    db = damaged(good_journal, tmp_path, sql("DROP TABLE steps", "DROP TABLE inbox"))
    with pytest.raises(JournalDamaged) as caught:
        check_journal(db)
    assert (caught.value.path, caught.value.problems) == (
        db,
        ("table inbox is missing", "table steps is missing"),
    )


@pytest.mark.parametrize("suffix", ["", "-wal"])
def test_export_out_the_journal_itself_is_refused_and_the_journal_kept(
    good_journal: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str
) -> None:
    """`journal export run.db --out run.db` (the journal, or its -wal file) is refused,
    exit 2 as any --out naming an input, and the journal still reads; it used to be
    replaced by the JSON Lines."""
    db = damaged(good_journal, tmp_path, lambda _: None)
    aside = Path(f"{db}{suffix}")
    aside.touch()
    before = snapshot_of(db)
    code, out, err = cli(["journal", "export", str(db), "--out", str(aside)], monkeypatch)
    said = "is an input of this command" in err or "is the journal itself" in err
    assert (code, said, out) == (2, True, ""), err
    assert snapshot_of(db) == before
    check_journal(db)  # still a journal


@pytest.mark.parametrize("fresh", [False, True])
def test_a_journal_path_that_is_the_device_file_is_refused(tmp_path: Path, fresh: bool) -> None:
    """`run motor.yaml --journal motor.yaml [--fresh]` is refused, exit 1, the device file
    untouched; with --fresh (which the refusal of a non-journal suggests) it used to move
    the device file aside and write a journal in its place."""
    device = tmp_path / "motor.yaml"
    shutil.copyfile(MOTOR, device)
    before = snapshot_of(device)
    out, err = io.StringIO(), io.StringIO()
    code = run(
        str(device), journal=str(device), fresh=fresh, events=io.StringIO(), out=out, err=err
    )
    assert (code, "is the run's input file" in err.getvalue()) == (1, True), err.getvalue()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["motor.yaml"]
    assert snapshot_of(device) == before


@pytest.mark.parametrize("fresh", [False, True])
def test_a_journal_path_that_is_a_directory_is_refused(tmp_path: Path, fresh: bool) -> None:
    """`run motor.yaml --journal logs [--fresh]` where logs is a directory: exit 1 naming
    it and what to do, the directory untouched; with --fresh it used to be renamed aside
    (with everything in it) and a journal file written in its place."""
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "keep.txt").write_text("mine")
    out, err = io.StringIO(), io.StringIO()
    code = run(str(MOTOR), journal=str(logs), fresh=fresh, events=io.StringIO(), out=out, err=err)
    said = err.getvalue()
    assert (code, f"--journal {logs} is a directory" in said) == (1, True), said
    assert sorted(p.name for p in tmp_path.iterdir()) == ["logs"]
    assert (logs / "keep.txt").read_text() == "mine"


GRIPPER = Path(__file__).parent.parent / "examples" / "pick-and-place" / "gripper.yaml"


@pytest.mark.parametrize("existing", [False, True])
def test_a_run_refused_before_it_starts_leaves_the_journal_as_it_was(
    good_journal: Path, tmp_path: Path, existing: bool
) -> None:
    """A run refused after its journal opened (a driver that cannot drive the device)
    leaves no new journal and an existing one as it was, with no -wal/-shm beside it; it
    used to leave the new file and an unmerged 74 KB -wal, the journal never closed."""
    db = tmp_path / "run.db"
    if existing:
        shutil.copyfile(good_journal, db)
    before = snapshot_of(db)
    out, err = io.StringIO(), io.StringIO()
    code = run(
        str(GRIPPER), driver="sim-motor", journal=str(db), events=io.StringIO(), out=out, err=err
    )
    assert (code, "SimMotor cannot drive Gripper" in err.getvalue()) == (1, True), err.getvalue()
    assert sorted(p.name for p in tmp_path.iterdir()) == (["run.db"] if existing else [])
    assert snapshot_of(db) == before


def test_a_journal_in_a_directory_that_does_not_exist_makes_it(tmp_path: Path) -> None:
    """`--journal nowhere/run.db`: the missing directory is made (the output rule) and the
    run journals there; it used to refuse, unlike codegen and testgen."""
    db = tmp_path / "nowhere" / "run.db"
    out, err = io.StringIO(), io.StringIO()
    code = run(str(MOTOR), journal=str(db), events=io.StringIO("Movement\n"), out=out, err=err)
    assert (code, db.is_file()) == (0, True), err.getvalue()
    assert f"wrote {db}" in out.getvalue()


def test_a_journal_path_ending_in_a_slash_is_a_directory(tmp_path: Path) -> None:
    """`--journal logs/`: the journal is logs/run.db, the directory made (the output rule)."""
    out, err = io.StringIO(), io.StringIO()
    logs = f"{tmp_path / 'logs'}/"
    code = run(str(MOTOR), journal=logs, events=io.StringIO("Movement\n"), out=out, err=err)
    assert (code, (tmp_path / "logs" / "run.db").is_file()) == (0, True), err.getvalue()


def test_a_run_refused_at_start_leaves_no_journal_in_the_folder_given(tmp_path: Path) -> None:
    """``--journal DIR/`` on a run refused before it starts (a driver that cannot drive
    its device): the journal made in DIR is removed again, nothing half-written is left."""
    folder = tmp_path / "journals"
    err = io.StringIO()
    code = run(
        str(GRIPPER),
        driver="sim-motor",
        journal=f"{folder}/",
        events=io.StringIO("Grip\n"),
        out=io.StringIO(),
        err=err,
    )
    assert code == 1 and "Grip()" in err.getvalue(), err.getvalue()
    assert not folder.exists() or list(folder.iterdir()) == []
