"""The journal: durable acceptance, steps, resume with recovery rules, show/export/replay."""

from __future__ import annotations

import io
import json
import sqlite3
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from statectl.channels.cli.demo import motor_chart
from statectl.channels.cli.journal import journal_export, journal_replay, journal_show
from statectl.channels.cli.run import run
from statectl.front.recovery import check_recovery
from statectl.front.tables import load
from statectl.kernel.errors import DiagnosticError
from statectl.run.devices import SimMotor
from statectl.run.journal import (
    Guarantee,
    Journal,
    JournalError,
    JournalReader,
    StepKind,
    Sync,
    export_jsonl,
    load_device,
    replay,
)
from statectl.run.runner import DeviceSetup, System, parse_event_line
from statectl.run.runtime import SimClock

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
#: The Motor's text without its Recovery table (the paper's two tables only).
MOTOR_TABLES = MOTOR.read_text(encoding="utf-8").split("\nrecovery:\n")[0] + "\n"
#: The shipped Motor's redo rule: Returning waits for the motor's completion.
REDO = "  - {state: Returning, redo: yes}\n"


@pytest.fixture
def device_file(tmp_path: Path) -> Path:
    """A copy of the shipped Motor, whose Recovery table takes Moving through Error."""
    path = tmp_path / "motor.yaml"
    path.write_text(MOTOR.read_text(encoding="utf-8"), encoding="utf-8")
    return path


GUARANTEES = list(Guarantee)


def make_system(
    db: Path,
    device_file: Path,
    sync: Sync = Sync.NORMAL,
    guarantee: Guarantee = Guarantee.PROMPT,
) -> System:
    dev = load_device(device_file)
    setup = DeviceSetup("Motor", dev.chart, dev.rules, str(device_file), SimMotor())
    return System((setup,), SimClock(), Journal(db, sync=sync, guarantee=guarantee))


@contextmanager
def disk_stalled(db: Path) -> Iterator[None]:
    """Hold the database's write lock, so the journal's writer cannot commit meanwhile."""
    other = sqlite3.connect(str(db), isolation_level=None)
    try:
        other.execute("BEGIN EXCLUSIVE")
        yield
        other.execute("ROLLBACK")
    finally:
        other.close()


@pytest.mark.parametrize("sync", [Sync.NORMAL, Sync.FULL])
@pytest.mark.parametrize("guarantee", GUARANTEES)
def test_an_accepted_event_is_journalled_and_reaches_its_device(
    tmp_path: Path, device_file: Path, sync: Sync, guarantee: Guarantee
) -> None:
    """Either guarantee: the ticket turns durable, the inbox holds the event, the device acts."""
    system = make_system(tmp_path / "j.db", device_file, sync, guarantee)
    try:
        system.start()
        ticket = system.post("Motor", "Movement", {"amount": 10})
        assert ticket is not None and ticket.wait(5.0) and ticket.durable
        with JournalReader(tmp_path / "j.db") as reader:
            assert [(r.seq, r.event, r.data) for r in reader.inbox()] == [
                (ticket.seq, "Movement", {"amount": 10})
            ]
        system.drain()
        assert system.subjects["Motor"].configuration == {"Moving"}
    finally:
        system.close()


@pytest.mark.parametrize(
    ("guarantee", "while_stalled", "durable_while_stalled"),
    [
        (Guarantee.PROMPT, {"Moving"}, False),  # processed at once, durable later
        (Guarantee.DURABLE_FIRST, {"Blocked"}, False),  # waits for the commit
    ],
)
def test_when_the_device_acts_depends_on_the_guarantee(
    tmp_path: Path,
    device_file: Path,
    guarantee: Guarantee,
    while_stalled: set[str],
    durable_while_stalled: bool,
) -> None:
    """With the disk stalled, prompt runs the event undurable; durable-first waits for it."""
    db = tmp_path / "j.db"
    system = make_system(db, device_file, guarantee=guarantee)
    try:
        system.start()
        assert system.journal is not None
        system.journal.flush()
        with disk_stalled(db):
            ticket = system.post("Motor", "Movement", {"amount": 10})
            assert ticket is not None
            system.drain()
            seen = set(system.subjects["Motor"].configuration)
            durable = ticket.durable
        assert ticket.wait(5.0)
        system.drain()
        after = set(system.subjects["Motor"].configuration)
    finally:
        system.close()
    assert (seen, durable, after) == (while_stalled, durable_while_stalled, {"Moving"})


@pytest.mark.parametrize(
    ("guarantee", "before_the_crash"),
    [(Guarantee.PROMPT, {"Moving"}), (Guarantee.DURABLE_FIRST, {"Blocked"})],
)
def test_a_crash_before_the_commit_leaves_no_trace_of_the_event(
    tmp_path: Path, device_file: Path, guarantee: Guarantee, before_the_crash: set[str]
) -> None:
    """An event not yet durable at a crash is not in the journal; resume finds the device before it.

    The "crash" is a copy of the database files taken while the writer cannot
    commit: what the disk holds if the process dies at that moment.
    """
    db, crashed = tmp_path / "j.db", tmp_path / "crashed.db"
    system = make_system(db, device_file, guarantee=guarantee)
    try:
        system.start()
        assert system.journal is not None
        system.journal.flush()
        with disk_stalled(db):
            ticket = system.post("Motor", "Movement", {"amount": 10})
            assert ticket is not None
            system.drain()
            state = set(system.subjects["Motor"].configuration)
            acknowledged = ticket.durable
            for suffix in ("", "-wal"):
                source = Path(f"{db}{suffix}")
                if source.exists():
                    Path(f"{crashed}{suffix}").write_bytes(source.read_bytes())
    finally:
        system.close()
    again = make_system(crashed, device_file, guarantee=guarantee)
    try:
        came_back = again.start(resume=True)
        resumed = set(again.subjects["Motor"].configuration)
        with JournalReader(crashed) as reader:
            inbox = list(reader.inbox())
    finally:
        again.close()
    assert came_back == {"Motor": True}  # the start step was on disk
    assert (state, acknowledged, resumed, inbox) == (before_the_crash, False, {"Blocked"}, [])


@pytest.mark.parametrize(
    ("value", "accepted"),
    [
        ("prompt", Guarantee.PROMPT),
        ("durable-first", Guarantee.DURABLE_FIRST),
        (Guarantee.DURABLE_FIRST, Guarantee.DURABLE_FIRST),
        ("eventually", None),
    ],
)
def test_the_guarantee_option(tmp_path: Path, value: object, accepted: Guarantee | None) -> None:
    """A journal takes a guarantee by enum or name; an unknown name is a JournalError."""
    if accepted is None:
        with pytest.raises(JournalError, match="prompt or durable-first"):
            Journal(tmp_path / "j.db", guarantee=value)  # type: ignore[arg-type]
        return
    journal = Journal(tmp_path / "j.db", guarantee=value)  # type: ignore[arg-type]
    try:
        assert journal.guarantee is accepted
    finally:
        journal.close()


def test_journal_defaults_to_the_prompt_guarantee(tmp_path: Path) -> None:
    """Without an option a journal is prompt: devices do not wait for the disk."""
    journal = Journal(tmp_path / "j.db")
    try:
        assert journal.guarantee is Guarantee.PROMPT
    finally:
        journal.close()


@pytest.mark.parametrize(
    ("guarantee", "code", "used", "says"),
    [
        ("durable-first", 0, Guarantee.DURABLE_FIRST, "final state Blocked"),
        ("prompt", 0, Guarantee.PROMPT, "final state Blocked"),
        ("eventually", 2, None, "--guarantee must be prompt or durable-first"),
    ],
)
def test_run_takes_a_guarantee(
    tmp_path: Path,
    device_file: Path,
    guarantee: str,
    code: int,
    used: Guarantee | None,
    says: str,
) -> None:
    """``statectl run --journal DB --guarantee G`` runs under G; an unknown G is a usage error."""
    out, err = io.StringIO(), io.StringIO()
    seen: list[Guarantee] = []

    def ready(system: System, url: str | None) -> None:
        assert system.journal is not None
        seen.append(system.journal.guarantee)

    result = run(
        str(device_file),
        journal=str(tmp_path / "j.db"),
        guarantee=guarantee,
        events=io.StringIO("Movement {amount: 1}\n"),
        out=out,
        err=err,
        ready=ready,
    )
    assert (result, seen) == (code, [used] if used is not None else [])
    assert says in out.getvalue() + err.getvalue()


@pytest.mark.parametrize("guarantee", GUARANTEES)
def test_every_step_is_journalled_with_its_snapshot(
    tmp_path: Path, device_file: Path, guarantee: Guarantee
) -> None:
    """Start, the accepted Movement and the driver's completion each leave one step row."""
    system = make_system(tmp_path / "j.db", device_file, guarantee=guarantee)
    try:
        system.start()
        ticket = system.post(None, "Movement", {"amount": 10})
        assert ticket is not None
        ticket.wait(5.0)
        system.settle()
        assert system.journal is not None
        system.journal.flush()
        with JournalReader(tmp_path / "j.db") as reader:
            rows = [
                (s.kind, s.event, s.inbox, tuple(sorted(s.snapshot.active))) for s in reader.steps()
            ]
    finally:
        system.close()
    assert rows == [
        (StepKind.START, None, None, ("Blocked",)),
        (StepKind.EVENT, "Movement", ticket.seq, ("Moving",)),
        (StepKind.EVENT, "Movement completion", None, ("Blocked",)),
    ]


@pytest.mark.parametrize("guarantee", GUARANTEES)
def test_resume_takes_the_recovery_transition_and_redelivers_pending_events(
    tmp_path: Path, device_file: Path, guarantee: Guarantee
) -> None:
    """A Motor journalled Moving resumes through Error; an accepted, unprocessed event follows."""
    db = tmp_path / "j.db"
    first = make_system(db, device_file, guarantee=guarantee)
    first.start()
    ticket = first.post(None, "Movement", {"amount": 10})
    assert ticket is not None
    ticket.wait(5.0)
    first.drain()  # Moving; the motor is on its way when the "crash" comes
    assert first.journal is not None
    with first.owner:  # the owner is busy when the "crash" comes: accepted, never processed
        late = first.post(None, "Initialization")
        assert late is not None
        late.wait(5.0)
        first.journal.flush()
        first.journal.close()

    second = make_system(db, device_file, guarantee=guarantee)
    try:
        resumed = second.start(resume=True)
        assert resumed == {"Motor": True}
        assert second.bound["Motor"].recovered == ("Error",)
        assert second.bound["Motor"].redelivered == 1
        second.settle()
        assert second.journal is not None
        second.journal.flush()
        with JournalReader(db) as reader:
            kinds = [(s.kind, s.event, s.outcome) for s in reader.steps(after=2)]
            assert reader.pending("Motor") == ()
    finally:
        second.close()
    assert kinds[:3] == [
        (StepKind.RESTORE, None, ""),
        (StepKind.RECOVERY, "Error", "handled"),
        (StepKind.EVENT, "Initialization", "declared ignored"),
    ]


@pytest.mark.parametrize("guarantee", GUARANTEES)
def test_replay_reaches_every_journalled_snapshot(
    tmp_path: Path, device_file: Path, guarantee: Guarantee
) -> None:
    """Replaying a run with a restart on the SimClock finds no mismatch and the same end state."""
    db = tmp_path / "j.db"
    for resume in (False, True):
        system = make_system(db, device_file, guarantee=guarantee)
        system.start(resume=resume)
        for line in ("Movement {amount: 3}", "Initialization", "Movement {amount: 4}"):
            parsed = parse_event_line(line)
            assert isinstance(parsed, tuple)
            ticket = system.post(*parsed)
            assert ticket is not None
            ticket.wait(5.0)
            system.settle()
        final = system.subjects["Motor"].snapshot
        system.close()
    with JournalReader(db) as reader:
        result = replay(reader, {"Motor": load_device(device_file).chart})
    assert result.ok, result.mismatches
    assert result.final["Motor"] == final


@pytest.mark.parametrize(
    ("text", "codes"),
    [
        ("recovery:\n  - {state: Moving, event: Error}\n" + REDO, []),
        ("recovery:\n  - {state: Moving, event: Error}\n", ["J608"]),
        ("recovery: 3\n", ["T108"]),
        ("recovery:\n  - Moving\n", ["T108"]),
        ("recovery:\n  - {state: Moving}\n", ["T104"]),
        ("recovery:\n  - {state: Moving, event: Error, when: x}\n", ["T103"]),
        ("recovery:\n  - {state: Moving, event: Error, data: 2016-01-01}\n", ["T108"]),
        ("recovery:\n  - {state: Flying, event: Error}\n" + REDO, ["J603", "J606"]),
        ("recovery:\n  - {state: Moving, event: Initialization}\n" + REDO, ["J604"]),
        (
            "recovery:\n  - {state: Moving, event: Error}\n  - {state: Moving, event: Error}\n"
            + REDO,
            ["J605"],
        ),
        (
            "recovery:\n  - {state: Moving, event: Error}\n  - {state: Blocked, redo: yes}\n"
            + REDO,
            ["J607"],
        ),
        ("recovery:\n  - {state: Returning, event: Error, redo: yes}\n", ["T114"]),
        ("recovery: []\n", ["J606", "J608"]),
        ("", ["J606", "J608"]),
    ],
)
def test_recovery_rules_are_checked(tmp_path: Path, text: str, codes: list[str]) -> None:
    """Each problem of a Recovery table is one diagnostic: its shape T1xx, its meaning J60x."""
    path = tmp_path / "motor.yaml"
    path.write_text(MOTOR_TABLES + text, encoding="utf-8")
    tables, diags = load(path)
    assert tables is not None
    if not diags:
        diags = check_recovery(motor_chart(), tables.recovery)
    assert sorted(d.code for d in diags) == sorted(codes)


def test_load_device_reports_every_recovery_error_at_its_line(tmp_path: Path) -> None:
    """A bad rule stops the load with its code and line; a table error later is reported too."""
    text = MOTOR_TABLES.replace("device: Motor", "recovery:\n  - {state: Moving}\ndevice: Motor")
    text = text.replace("new: Moving", "new: Nowhere", 1)
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DiagnosticError) as caught:
        load_device(path)
    lines = text.splitlines()
    rule = lines.index("  - {state: Moving}") + 1
    row = lines.index("  - event: Movement") + 1
    found = {(d.code, d.where.line) for d in caught.value.diagnostics}
    assert ("T104", rule) in found
    assert any(line == row for _, line in found), found


@pytest.mark.parametrize(
    ("text", "severities"),
    [
        ("", {"J606": "warning", "J608": "warning"}),
        ("recovery:\n  - {state: Moving, event: Error}\n", {"J608": "warning"}),
        ("recovery:\n  - {state: Moving, event: Error}\n" + REDO, {}),
    ],
)
def test_load_device_warns_about_a_state_without_the_rule_it_needs(
    tmp_path: Path, text: str, severities: dict[str, str]
) -> None:
    """For a journalled run J606 and J608 are warnings (statectl check shows them as info)."""
    path = tmp_path / "motor.yaml"
    path.write_text(MOTOR_TABLES + text, encoding="utf-8")
    dev = load_device(path)
    assert {d.code: d.severity.value for d in dev.warnings} == severities
    assert [(r.state, r.event) for r in dev.rules][:1] == [("Moving", "Error")] * bool(text)


def test_non_json_event_data_is_refused(tmp_path: Path) -> None:
    """Data the journal could not give back is refused at acceptance, not lost later."""
    journal = Journal(tmp_path / "j.db")
    try:
        with pytest.raises(Exception, match="must be JSON"):
            journal.accept("Motor", "Movement", {"amount": object()})
    finally:
        journal.close()


@pytest.mark.parametrize(
    ("line", "parsed"),
    [
        ("Movement {amount: 10}", (None, "Movement", {"amount": 10})),
        ("Motor: Movement completion", ("Motor", "Movement completion", None)),
        ("+1.5", 1.5),
        ("   # a comment", None),
    ],
)
def test_event_lines(line: str, parsed: object) -> None:
    """``[DEVICE:] EVENT [DATA]`` lines, time steps and comments."""
    assert parse_event_line(line) == parsed


def test_show_export_and_replay_commands(tmp_path: Path, device_file: Path) -> None:
    """The three journal commands read one journal: lines, JSON Lines, a replay with exit 0."""
    db = tmp_path / "j.db"
    system = make_system(db, device_file)
    system.start()
    ticket = system.post(None, "Movement", {"amount": 2})
    assert ticket is not None
    ticket.wait(5.0)
    system.settle()
    system.close()
    shown, exported, replayed, err = io.StringIO(), io.StringIO(), io.StringIO(), io.StringIO()
    assert journal_show(str(db), device="Motor", out=shown, err=err) == 0
    assert journal_export(str(db), since="0", out=exported, err=err) == 0
    assert journal_replay(str(db), out=replayed, err=err) == 0, err.getvalue()
    assert "accepted  Movement {amount: 2}" in shown.getvalue()
    kinds = [json.loads(x)["type"] for x in exported.getvalue().splitlines()]
    assert kinds == ["accepted", "step", "step", "step"]
    assert "0 mismatch(es)" in replayed.getvalue()


def test_export_filters_by_device_and_time(tmp_path: Path) -> None:
    """A window after every row exports nothing; another device's name exports nothing."""
    journal = Journal(tmp_path / "j.db")
    journal.accept("Motor", "Movement", {"amount": 1}).wait(5.0)
    journal.close()
    with JournalReader(tmp_path / "j.db") as reader:
        counts = [
            export_jsonl(reader, io.StringIO()),
            export_jsonl(reader, io.StringIO(), device="Arm"),
            export_jsonl(reader, io.StringIO(), since=4e9),
        ]
    assert counts == [1, 0, 0]


def test_show_interleaves_accepted_events_and_steps_in_time_order(
    tmp_path: Path, device_file: Path
) -> None:
    """Each accepted event is shown before the step that processed it, all in wall order."""
    db = tmp_path / "j.db"
    system = make_system(db, device_file)
    system.start()
    for event, data in (("Movement", {"amount": 1}), ("Error", None), ("Movement", None)):
        system.post(None, event, data)  # the last is ignored in Returning, still a step
        system.drain()
    system.close()
    shown = io.StringIO()
    assert journal_show(str(db), out=shown, err=io.StringIO()) == 0
    lines = shown.getvalue().splitlines()
    stamps = [line.split("  ", 1)[0] for line in lines]
    assert stamps == sorted(stamps)
    order = [line.split("  ", 1)[1].split()[0][:1] for line in lines]  # '#' accepted, 's' step
    assert order[0] == "s"  # the start step comes first
    for i, mark in enumerate(order):
        if mark == "#":
            seq = lines[i].split("  ", 1)[1].split()[0]
            later = [x for x in lines[i + 1 :] if f"({seq})" in x]
            assert later, f"no step after accepted {seq}"


@pytest.mark.parametrize("command", [journal_show, journal_export, journal_replay])
def test_a_device_the_journal_does_not_hold_is_an_error(
    tmp_path: Path, device_file: Path, command: Callable[..., int]
) -> None:
    """``--device`` naming no journalled device (a typo) exits 1 naming the devices, no output.

    Otherwise ``journal replay --device Motr`` replays nothing and passes.
    """
    db = tmp_path / "j.db"
    system = make_system(db, device_file)
    system.start()
    system.close()
    out, err = io.StringIO(), io.StringIO()
    assert command(str(db), device="Motr", out=out, err=err) == 1
    assert out.getvalue() == ""
    said = "no device 'Motr' in the journal; did you mean 'Motor'? devices journalled: Motor"
    assert said in err.getvalue()


def test_a_line_of_bytes_that_are_not_utf8_is_a_bad_line_not_a_dead_journal(
    tmp_path: Path,
) -> None:
    """`statectl run --journal` fed a line with a byte that is not UTF-8 (in the event name
    or its data) reports that line and goes on; the name used to fail the journal's write,
    which stops accepting anything, and the data a YAML traceback."""
    import os
    import subprocess
    import sys

    db = tmp_path / "run.db"
    src = str(Path(__file__).parent.parent / "src")
    done = subprocess.run(
        [sys.executable, "-m", "statectl", "run", str(MOTOR), "--journal", str(db)],
        input=b'Movement\xff\nInitialization {a: "x\xfe"}\nMovement {amount: 1}\n',
        capture_output=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": src},
    )
    err = done.stderr.decode("utf-8", "replace")
    assert (done.returncode, "Traceback" in err, "write failed" in err) == (1, False, False), err
    assert "line 1: the line is not UTF-8 text (byte 0xff" in err
    assert "line 2: the line is not UTF-8 text (byte 0xfe" in err
    with JournalReader(db) as reader:
        assert [row.event for row in reader.inbox()] == ["Movement"]


@pytest.mark.parametrize(("since", "code"), [("nan", 2), ("yesterday", 2), ("0", 0)])
def test_a_since_that_is_no_time_is_a_usage_error(
    tmp_path: Path, device_file: Path, since: str, code: int
) -> None:
    """`journal show --since nan` is a usage error like any text that is no time (it used
    to show an empty window and exit 0: no comparison with NaN holds)."""
    db = tmp_path / "j.db"
    ran = run(
        str(device_file), journal=str(db), events=io.StringIO("Movement\n"), out=io.StringIO()
    )
    assert ran == 0
    out, err = io.StringIO(), io.StringIO()
    assert journal_show(str(db), since=since, out=out, err=err) == code, err.getvalue()
    assert ("not a time" in err.getvalue(), out.getvalue() != "") == (code == 2, code == 0)


@pytest.mark.parametrize(
    ("command", "code"), [(journal_show, 0), (journal_export, 0), (journal_replay, 1)]
)
def test_a_device_with_only_sent_events_is_shown_not_replayed(
    tmp_path: Path, device_file: Path, command: Callable[..., int], code: int
) -> None:
    """A device this journal only holds accepted events for (a node's link events to
    another node's device) is one show and export list; replay, which needs its chart,
    says it is not journalled here."""
    db = tmp_path / "j.db"
    system = make_system(db, device_file)
    system.start()
    assert system.journal is not None
    system.journal.accept("Conveyor", "Arrive")
    system.journal.flush()
    system.close()
    out, err = io.StringIO(), io.StringIO()
    assert command(str(db), device="Conveyor", out=out, err=err) == code, err.getvalue()
    assert ("Arrive" in out.getvalue()) is (code == 0)


def test_a_step_whose_driver_refuses_its_data_is_journalled(
    tmp_path: Path, device_file: Path
) -> None:
    """Movement with data the driver refuses still moved the device (the transition comes
    before the call): the journal has that step, so replay agrees with the run and a
    resume does not redeliver the event to fail again."""
    db = tmp_path / "j.db"
    lines = io.StringIO("Movement {amount: abc}\nError\n")
    out, err = io.StringIO(), io.StringIO()
    code = run(
        str(device_file), driver="sim-motor", journal=str(db), events=lines, out=out, err=err
    )
    assert code == 1, err.getvalue()
    out, err = io.StringIO(), io.StringIO()
    assert journal_replay(str(db), out=out, err=err) == 0, out.getvalue() + err.getvalue()
    assert "0 mismatch(es)" in out.getvalue()
    out, err = io.StringIO(), io.StringIO()
    assert journal_show(str(db), out=out, err=err) == 0
    assert "Movement {amount: abc} (#1) -> [Moving]" in out.getvalue()
