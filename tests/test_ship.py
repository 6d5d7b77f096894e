"""Shipping journals into PostgreSQL: exactly once, several sources, a reader like the file's.

Every test runs against a real PostgreSQL server the module starts itself
(tests/pgserver.py: Debian's binaries, as the postgres user, on 127.0.0.1) and
stops afterwards; without PostgreSQL or runuser the module is skipped.
"""

from __future__ import annotations

import io
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import pgserver
from statectl.channels.cli.journal import journal_export, journal_replay, journal_show
from statectl.channels.cli.run import run
from statectl.channels.cli.ship import journal_ship
from statectl.channels.runconfig import load_run_config
from statectl.kernel.errors import DiagnosticError
from statectl.kernel.semantics import Snapshot
from statectl.run.journal import Journal, JournalError, JournalReader, StepKind
from statectl.run.journal.pg import PgJournalReader, display_url, split_url
from statectl.run.journal.ship import Shipper, ShipRefused, ShipThread
from statectl.run.journal.ship_config import ShipConfig

psycopg = pytest.importorskip("psycopg")

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
IDLE = Snapshot(frozenset({"Idle"}), (), None)
BUSY = Snapshot(frozenset({"Busy"}), (), "Idle")


@pytest.fixture(scope="module")
def server() -> Iterator[pgserver.PgServer]:
    why = pgserver.why_not()
    if why is not None:
        pytest.skip(why)
    srv = pgserver.start()
    assert srv is not None
    try:
        yield srv
    finally:
        srv.stop()


@pytest.fixture
def url(server: pgserver.PgServer) -> Iterator[str]:
    """A fresh database per test, on the module's server."""
    name = f"t{os.getpid()}_{time.monotonic_ns()}"
    with psycopg.connect(server.url, autocommit=True) as conn:
        conn.execute(f"CREATE DATABASE {name}")
    yield server.url.rsplit("/", 1)[0] + "/" + name
    with psycopg.connect(server.url, autocommit=True) as conn:
        conn.execute(f"DROP DATABASE {name} WITH (FORCE)")


def fill(path: Path, events: int, device: str = "Arm", fault_every: int = 0) -> None:
    """A journal of one device: a start, then ``events`` accepted events and their steps."""
    j = Journal(path)
    if not path.with_name(path.name + ".started").exists():
        j.register(device, device, "arm.yaml", {"speed": 3})
        j.record(device, StepKind.START, IDLE, time_=0.0)
        path.with_name(path.name + ".started").touch()
    for i in range(events):
        t = j.accept(device, "Go", {"n": i})
        fault = fault_every and i % fault_every == 0
        data = {"detail": "overcurrent"} if fault else None
        snap = BUSY if i % 2 == 0 else IDLE
        j.record(device, StepKind.EVENT, snap, time_=float(i), event="Go", data=data,
                 inbox=t.seq, outcome="handled")  # fmt: skip
    j.flush()
    j.close()


def query(url: str, sql: str, *args: Any) -> list[tuple[Any, ...]]:
    with psycopg.connect(url) as conn:
        return list(conn.execute(sql, args).fetchall())


def same_rows(journal: Path, url: str, source: str | None = None) -> None:
    """The shipped journal reads back exactly as the file: every row, once, in order."""
    with JournalReader(journal) as file, PgJournalReader(url, source=source) as pg:
        assert list(pg.steps()) == list(file.steps())
        assert list(pg.inbox()) == list(file.inbox())
        assert pg.devices() == file.devices()
        assert pg.counts() == file.counts()


def test_ship_copies_every_committed_row_once_and_a_second_pass_adds_nothing(
    tmp_path: Path, url: str
) -> None:
    """Shipping twice ships each row once: the marks, not the shipper's memory, decide."""
    db = tmp_path / "a.db"
    fill(db, 120)
    first = Shipper(db, url, batch=50).ship_all()
    assert (first.inbox, first.steps) == (120, 121)
    again = Shipper(db, url, batch=50).ship_all()
    assert (again.inbox, again.steps, again.steps_upto) == (0, 0, 121)
    fill(db, 30)
    more = Shipper(db, url).ship_all()
    assert (more.inbox, more.steps, more.inbox_upto) == (30, 30, 150)
    same_rows(db, url)
    marks = query(url, "SELECT inbox_upto, steps_upto FROM statectl_sources")
    assert marks == [(150, 151)]


def test_kill_mid_batch_and_restart_loses_and_doubles_nothing(tmp_path: Path, url: str) -> None:
    """SIGKILL the shipper while it ships small batches, restart it: every row exactly once."""
    db = tmp_path / "big.db"
    fill(db, 30_000)
    cmd = [sys.executable, "-m", "statectl", "journal", "ship", str(db), "--to", url,
           "--batch", "200", "--source", "cell-a"]  # fmt: skip
    kills = 0
    for _ in range(3):
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 60
        before = _shipped(url)
        while time.monotonic() < deadline and proc.poll() is None:
            if _shipped(url) > before + 2000:
                break
            time.sleep(0.02)
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            kills += 1
        proc.wait(10)
        assert proc.returncode in (0, -signal.SIGKILL), proc.stderr.read() if proc.stderr else ""
        if proc.stderr:
            proc.stderr.close()
        marks = query(url, "SELECT inbox_upto, steps_upto FROM statectl_sources")
        counts = query(
            url,
            "SELECT (SELECT count(*) FROM statectl_inbox), (SELECT count(*) FROM statectl_steps)",
        )
        assert marks == counts, "a killed batch left rows beyond the marks, or marks beyond rows"
    assert kills >= 1, "the shipper finished before it could be killed"
    assert 0 < _shipped(url) < 60_001
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    same_rows(db, url, "cell-a")
    dupes = query(url, "SELECT count(*) - count(DISTINCT id) FROM statectl_steps")
    assert dupes == [(0,)]


def _shipped(url: str) -> int:
    try:
        rows = query(url, "SELECT coalesce(sum(inbox_upto + steps_upto), 0) FROM statectl_sources")
    except psycopg.errors.UndefinedTable:
        return 0
    return int(rows[0][0])


def test_several_sources_ship_into_one_database_and_each_reads_back_alone(
    tmp_path: Path, url: str
) -> None:
    """Four journals shipped at once (threads) land side by side; faults are found across them."""
    journals = [tmp_path / f"c{i}.db" for i in range(4)]
    for i, db in enumerate(journals):
        fill(db, 200 + i, device=f"Arm{i}", fault_every=50)
    codes: list[int] = []
    threads = [
        threading.Thread(
            target=lambda d=db, i=i: codes.append(
                journal_ship(str(d), url, source=f"c{i}", batch=64, out=io.StringIO())
            )
        )
        for i, db in enumerate(journals)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert codes == [0, 0, 0, 0]
    for i, db in enumerate(journals):
        same_rows(db, url, f"c{i}")
    faults = query(
        url,
        "SELECT source, count(*) FROM statectl_steps "
        "WHERE fault AND at >= date_trunc('day', now()) GROUP BY source ORDER BY source",
    )
    assert faults == [("c0", 4), ("c1", 5), ("c2", 5), ("c3", 5)]
    plan = "\n".join(
        r[0]
        for r in query(
            url,
            "EXPLAIN SELECT * FROM statectl_steps WHERE device = 'Arm1' AND at >= now() - "
            "interval '1 hour' AND at < now()",
        )
    )
    assert "statectl_steps_device_at" in plan or "Seq Scan" in plan  # small table: either


def test_a_different_journal_at_the_same_source_is_refused(tmp_path: Path, url: str) -> None:
    """A journal started anew under a shipped source's name is refused, not shipped from its id."""
    db = tmp_path / "a.db"
    fill(db, 10)
    Shipper(db, url, source="s").ship_all()
    other = tmp_path / "b.db"
    fill(other, 20)
    with pytest.raises(ShipRefused, match="another journal"):
        Shipper(other, url, source="s").ship_all()
    err = io.StringIO()
    assert journal_ship(str(other), url, source="s", out=io.StringIO(), err=err) == 1
    assert "under another name" in err.getvalue()


def test_show_export_and_replay_read_a_shipped_journal_as_the_file(
    tmp_path: Path, url: str
) -> None:
    """show, export and replay print the same from the URL as from the SQLite file."""
    db = tmp_path / "run.db"
    events = io.StringIO("Movement\n+5\nInitialization\n")
    assert run(str(MOTOR), journal=str(db), events=events, out=io.StringIO()) == 0
    assert journal_ship(str(db), url, source="m", out=io.StringIO()) == 0
    for command in (journal_show, journal_export, journal_replay):
        a, b = io.StringIO(), io.StringIO()
        assert command(str(db), out=a) == command(url + "?source=m", out=b) == 0
        assert a.getvalue() == b.getvalue() and a.getvalue()


def test_a_shipped_journal_reads_every_window_as_the_file(tmp_path: Path, url: str) -> None:
    """device, since/until (journal/read.py rule 2) and after/upto pick the same rows from
    the URL as from the file."""
    db = tmp_path / "run.db"
    fill(db, 6)
    Shipper(db, url, source="s").ship_all()
    with JournalReader(db) as file, PgJournalReader(url, source="s") as pg:
        walls = sorted({s.wall for s in file.steps()})
        windows: list[dict[str, Any]] = [
            {},
            {"device": "Arm"},
            {"device": "Nobody"},
            {"since": walls[len(walls) // 2]},
            {"until": walls[len(walls) // 2]},
            {"device": "Arm", "since": walls[1], "until": walls[-1]},
        ]
        for window in windows:
            assert list(pg.steps(**window)) == list(file.steps(**window)), window
            assert list(pg.inbox(**window)) == list(file.inbox(**window)), window
        bounds = [{"after": 2}, {"upto": 4}, {"after": 2, "upto": 5}, {"device": "Arm", "after": 6}]
        picked = [[s.id for s in file.steps(**b)] for b in bounds]
        assert [[s.id for s in pg.steps(**b)] for b in bounds] == picked
    assert picked == [[3, 4, 5, 6, 7], [1, 2, 3, 4], [3, 4, 5], [7]]


def test_a_shipped_journal_finds_the_step_that_entered_a_state_as_the_file(
    tmp_path: Path, url: str
) -> None:
    """entering_step (journal/read.py rule 4) answers alike from the URL and from the file."""
    db = tmp_path / "run.db"
    fill(db, 5)
    Shipper(db, url, source="s").ship_all()
    with JournalReader(db) as file, PgJournalReader(url, source="s") as pg:
        asked = [(state, upto) for state in ("Busy", "Idle") for upto in (None, 1, 2, 3, 4, 5, 6)]
        found = {(s, u): file.entering_step("Arm", s, u) for s, u in asked}
        assert {(s, u): pg.entering_step("Arm", s, u) for s, u in asked} == found
    entered = {(s, u): (b.id, e.id) for (s, u), f in found.items() if f is not None for b, e in [f]}
    assert entered == {("Busy", None): (5, 6), ("Busy", 2): (1, 2), ("Busy", 4): (3, 4),
                       ("Busy", 6): (5, 6), ("Idle", 3): (2, 3), ("Idle", 5): (4, 5)}  # fmt: skip


BAD = [
    ("postgresql://statectl:s3cret@127.0.0.1:1/nowhere", "cannot connect"),
    ("postgresql://127.0.0.1:1/x?bogus_option=1", "cannot connect"),
    ("postgresql://statectl:s3cret@[::1/nowhere", "not a valid URL"),  # was a traceback
    ("postgresql://statectl:s3cret@127.0.0.1:port/x", "not a valid URL"),
]


@pytest.mark.parametrize(("target", "says"), BAD)
def test_bad_url_or_server_down_is_a_message_and_exit_1(
    tmp_path: Path, target: str, says: str
) -> None:
    """A server that is down or a bad URL: one line, exit 1, no traceback, no password."""
    db = tmp_path / "a.db"
    fill(db, 3)
    for argv in (
        ["journal", "ship", str(db), "--to", target],
        ["journal", "show", target],
        ["journal", "replay", target],
    ):
        r = subprocess.run(
            [sys.executable, "-m", "statectl", *argv], capture_output=True, text=True, timeout=60
        )
        assert r.returncode == 1, (argv, r.stderr)
        assert says in r.stderr and "Traceback" not in r.stderr
        assert "s3cret" not in r.stderr


def test_a_file_that_is_no_journal_is_refused_before_shipping(tmp_path: Path, url: str) -> None:
    """Shipping a text file or a foreign database: exit 1 with what is wrong, nothing shipped."""
    text = tmp_path / "notes.db"
    text.write_text("not a database\n" * 100)
    other = tmp_path / "other.db"
    sqlite3.connect(other).execute("CREATE TABLE x (a)").connection.commit()
    for path in (text, other):
        err = io.StringIO()
        assert journal_ship(str(path), url, out=io.StringIO(), err=err) == 1
        assert str(path) in err.getvalue() and "Traceback" not in err.getvalue()
    assert _shipped(url) == 0


def test_url_helpers_take_off_the_source_and_hide_the_password() -> None:
    """``?source=`` is statectl's, not libpq's; a password never reaches a message."""
    assert split_url("postgresql://h/db?source=a&sslmode=disable") == (
        "postgresql://h/db?sslmode=disable",
        "a",
    )
    assert display_url("postgresql://u:pw@h:5/db") == "postgresql://u:***@h:5/db"


def test_a_running_device_is_never_blocked_while_the_server_is_down(tmp_path: Path) -> None:
    """With the server down the shipper reports and retries; the journal's commits go on."""
    db = tmp_path / "live.db"
    j = Journal(db)
    said: list[str] = []
    ship = ShipThread(
        Shipper(db, "postgresql://u:pw@127.0.0.1:1/x"), interval=0.01, retry=0.05,
        report=said.append,
    )  # fmt: skip
    j.after_commit(ship.wake)
    ship.start()
    j.record("Arm", StepKind.START, IDLE, time_=0.0)
    began = time.monotonic()
    for i in range(2000):
        j.accept("Arm", "Go").wait(5)
        j.record("Arm", StepKind.EVENT, IDLE, time_=float(i), event="Go", outcome="handled")
    j.flush()
    took = time.monotonic() - began
    ship.stop(drain=0.1)
    j.close()
    assert took < 10, f"2000 committed events took {took:.1f} s with the server down"
    assert len(said) == 1 and "retrying" in said[0] and "pw@" not in said[0]


def test_a_run_with_ship_and_the_server_down_runs_and_says_so(tmp_path: Path) -> None:
    """``ship:`` to a server that is down: the run completes (exit 0) and reports it once."""
    config = tmp_path / "run.yaml"
    config.write_text("ship: {to: 'postgresql://u:pw@127.0.0.1:1/x', retry: 0.05}\n")
    out, err = io.StringIO(), io.StringIO()
    events = io.StringIO("Movement\n+5\nMovement\n+5\n")
    code = run(str(MOTOR), journal=str(tmp_path / "r.db"), config=str(config), events=events,
               out=out, err=err)  # fmt: skip
    assert code == 0, err.getvalue()
    assert "final state" in out.getvalue()
    assert err.getvalue().count("retrying") == 1 and "pw@" not in err.getvalue()
    err = io.StringIO()
    assert run(str(MOTOR), config=str(config), events=io.StringIO(""), out=out, err=err) == 1
    assert "run with --journal DB" in err.getvalue()


def test_run_config_ship_section_ships_while_the_run_goes_on(tmp_path: Path, url: str) -> None:
    """``ship:`` in the run config ships the run's journal; it is all there after the run."""
    config = tmp_path / "run.yaml"
    config.write_text(f"ship: {{to: '{url}', source: cell-a, interval: 0.05}}\n")
    db = tmp_path / "run.db"
    err = io.StringIO()
    events = io.StringIO("Movement\n+5\nMovement\n+5\n")
    code = run(str(MOTOR), journal=str(db), config=str(config), events=events,
               out=io.StringIO(), err=err)  # fmt: skip
    assert code == 0, err.getvalue()
    same_rows(db, url, "cell-a")


SHIP_CONFIGS = [
    ("ship: {to: 'postgresql://h/db', batch: 10}\n", None),
    ("ship: {to: 'mysql://h/db'}\n", "to must be a postgresql:// URL"),
    ("ship: {to: 'postgresql://h/db', interval: 0}\n", "interval must be seconds"),
    ("ship: {to: 'postgresql://h/db', batch: 0}\n", "batch must be a number of rows"),
    ("ship: {to: 'postgresql://h/db', speed: 3}\n", "unknown key 'speed'"),
    ("ship: {source: a}\n", "no 'to'"),
    ("ship: [1]\n", "'ship' must be a mapping"),
    ("ship: {to: 'postgresql://u:s3cret@[::1/db'}\n", "to is not a valid URL (Invalid IPv6"),
]


@pytest.mark.parametrize(("text", "says"), SHIP_CONFIGS)
def test_ship_section_problems_are_d520_with_their_line(
    tmp_path: Path, text: str, says: str | None
) -> None:
    """Each bad ``ship:`` value is one D530 at line 1; a good one parses."""
    config = tmp_path / "run.yaml"
    config.write_text(text)
    if says is None:
        assert load_run_config(config).ship == ShipConfig("postgresql://h/db", batch=10)
        return
    with pytest.raises(DiagnosticError) as info:
        load_run_config(config)
    (diag,) = info.value.diagnostics
    assert diag.code == "D530" and says in diag.message and diag.where.line == 1
    assert "s3cret" not in str(diag)


def test_reader_without_a_shipped_journal_says_so(url: str) -> None:
    """An empty database is a clear JournalError, not a missing-table traceback."""
    with pytest.raises(JournalError, match="holds no shipped journal"):
        PgJournalReader(url)


def test_a_server_crash_mid_run_loses_and_doubles_nothing(tmp_path: Path) -> None:
    """PostgreSQL killed (SIGQUIT) while a node writes and ships, then restarted: all, once."""
    why = pgserver.why_not()
    if why is not None:
        pytest.skip(why)
    srv = pgserver.start(durable=True)
    assert srv is not None
    try:
        db = tmp_path / "live.db"
        j = Journal(db)
        said: list[str] = []
        ship = ShipThread(Shipper(db, srv.url, batch=100), interval=0.01, retry=0.1,
                          report=said.append)  # fmt: skip
        j.after_commit(ship.wake)
        ship.start()
        j.register("Arm", "Arm", "arm.yaml", None)
        j.record("Arm", StepKind.START, IDLE, time_=0.0)

        def burst(first: int) -> None:
            for i in range(first, first + 3000):
                t = j.accept("Arm", "Go", {"n": i})
                j.record("Arm", StepKind.EVENT, IDLE, time_=float(i), event="Go",
                         inbox=t.seq, outcome="handled")  # fmt: skip
                if i % 100 == 0:
                    time.sleep(0.002)

        burst(0)
        srv.crash()
        burst(3000)  # the server is down: the journal goes on
        j.flush()
        srv.restart()
        burst(6000)
        j.flush()
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and _shipped(srv.url) < 2 * 9000 + 1:
            time.sleep(0.05)
        ship.stop()
        j.close()
        assert any("retrying" in s for s in said) and any("resumed" in s for s in said), said
        same_rows(db, srv.url)
    finally:
        srv.stop()
