"""The journal: durable acceptance, steps, resume with recovery rules, show/export/replay."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest

from statectl.demo import motor_chart
from statectl.devices import SimMotor
from statectl.errors import DiagnosticError
from statectl.journal import (
    Journal,
    JournalReader,
    StepKind,
    Sync,
    check_recovery,
    export_jsonl,
    load_device,
    load_recovery,
    replay,
)
from statectl.runner import (
    DeviceSetup,
    System,
    journal_export,
    journal_replay,
    journal_show,
    parse_event_line,
)
from statectl.runtime import SimClock

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
RECOVERY = """
recovery:
  - state: Moving
    event: Error
    data: {detail: resumed after a restart}
"""


@pytest.fixture
def device_file(tmp_path: Path) -> Path:
    path = tmp_path / "motor.yaml"
    path.write_text(MOTOR.read_text(encoding="utf-8") + RECOVERY, encoding="utf-8")
    return path


def make_system(db: Path, device_file: Path, sync: Sync = Sync.NORMAL) -> System:
    dev = load_device(device_file)
    setup = DeviceSetup("Motor", dev.chart, dev.rules, str(device_file), SimMotor())
    return System((setup,), SimClock(), Journal(db, sync=sync))


@pytest.mark.parametrize("sync", [Sync.NORMAL, Sync.FULL])
def test_an_accepted_event_is_durable_before_the_device_sees_it(
    tmp_path: Path, device_file: Path, sync: Sync
) -> None:
    """The ticket turns durable, the inbox holds the event, then the device acts on it."""
    system = make_system(tmp_path / "j.db", device_file, sync)
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


def test_every_step_is_journalled_with_its_snapshot(tmp_path: Path, device_file: Path) -> None:
    """Start, the accepted Movement and the driver's completion each leave one step row."""
    system = make_system(tmp_path / "j.db", device_file)
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


def test_resume_takes_the_recovery_transition_and_redelivers_pending_events(
    tmp_path: Path, device_file: Path
) -> None:
    """A Motor journalled Moving resumes through Error; an accepted, unprocessed event follows."""
    db = tmp_path / "j.db"
    first = make_system(db, device_file)
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

    second = make_system(db, device_file)
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


def test_replay_reaches_every_journalled_snapshot(tmp_path: Path, device_file: Path) -> None:
    """Replaying a run with a restart on the SimClock finds no mismatch and the same end state."""
    db = tmp_path / "j.db"
    for resume in (False, True):
        system = make_system(db, device_file)
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
        ("recovery:\n  - {state: Moving, event: Error}\n", []),
        ("recovery: 3\n", ["J601", "J606"]),
        ("recovery:\n  - {state: Moving}\n", ["J602", "J606"]),
        ("recovery:\n  - {state: Moving, event: Error, when: x}\n", ["J602"]),
        ("recovery:\n  - {state: Flying, event: Error}\n", ["J603", "J606"]),
        ("recovery:\n  - {state: Moving, event: Initialization}\n", ["J604"]),
        (
            "recovery:\n  - {state: Moving, event: Error}\n  - {state: Moving, event: Error}\n",
            ["J605"],
        ),
        ("recovery: []\n", ["J606"]),
    ],
)
def test_recovery_rules_are_checked(tmp_path: Path, text: str, codes: list[str]) -> None:
    """Each problem of a recovery section is one diagnostic with its code."""
    path = tmp_path / "r.yaml"
    path.write_text(text, encoding="utf-8")
    rules, diags = load_recovery(path)
    diags += check_recovery(motor_chart(), rules)
    assert sorted(d.code for d in diags) == sorted(codes)


def test_a_device_file_with_a_recovery_section_keeps_its_line_numbers(tmp_path: Path) -> None:
    """The section is blanked for the table loader, so a later table error names its own line."""
    text = MOTOR.read_text(encoding="utf-8").replace("device: Motor", RECOVERY + "device: Motor")
    text = text.replace("new: Moving", "new: Nowhere", 1)
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DiagnosticError) as caught:
        load_device(path)
    line = next(i for i, t in enumerate(text.splitlines(), 1) if t == "  - event: Movement")
    assert any(d.where.line == line for d in caught.value.diagnostics)


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
