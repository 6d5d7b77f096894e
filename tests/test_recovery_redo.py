"""Recovery ``redo``: a device restarted in a state it was working in gets that work again.

The Motor's Returning is left only by the motor's completion. A journalled Motor
left in Returning when the process died resumes there with nobody returning the
motor; its redo rule issues the entering step's device calls again (``Error()``
or ``Initialization()``), so the completion comes and the Motor is Blocked.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from statectl.front.builder.build import load_chart
from statectl.front.observers import Notification
from statectl.front.recovery import check_recovery
from statectl.front.tables import load
from statectl.kernel.model import Notify
from statectl.kernel.semantics import step
from statectl.run.devices import SimMotor, SimTwin
from statectl.run.journal import REDO, Journal, JournalReader, StepKind, load_device, replay
from statectl.run.runner import DeviceSetup, System
from statectl.run.runtime import SimClock, Subject
from statectl.run.runtime.records import EventReceived, InvokeIssued, ObserverCalled, Record
from support import PARALLEL_PRESS

ROOT = Path(__file__).resolve().parent.parent
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"
LONG = 100.0  # seconds the twin takes to return: the run is closed long before


@pytest.fixture
def device_file(tmp_path: Path) -> Path:
    """A copy of the shipped Motor: Moving resumes through Error, Returning is redone."""
    path = tmp_path / "motor.yaml"
    path.write_text(MOTOR.read_text(encoding="utf-8"), encoding="utf-8")
    return path


def make_system(db: Path, device_file: Path, driver: str = "twin") -> System:
    dev = load_device(device_file)
    observer: SimTwin | SimMotor
    if driver == "twin":
        observer = SimTwin(dev.chart, delay=LONG, delays={"Movement": 1.0})
    else:
        observer = SimMotor(speed=0.01)  # 1 unit takes 100 s
    setup = DeviceSetup("Motor", dev.chart, dev.rules, str(device_file), observer)
    return System((setup,), SimClock(), Journal(db))


def api_calls(system: System) -> list[str]:
    driver = system.setups[0].driver
    assert isinstance(driver, SimTwin | SimMotor)
    return [c.function for c in driver.api_log]


def leave_returning(db: Path, device_file: Path, entered_by: str, driver: str = "twin") -> None:
    """Run a Motor into Returning through ``entered_by`` and close before the motor is back."""
    first = make_system(db, device_file, driver)
    first.start()
    first.post(None, "Movement", {"amount": 1})
    first.drain()
    if entered_by == "Error":
        first.post(None, "Error", {"detail": "stalled"})
    else:
        first.advance(LONG)  # the movement completes: Blocked, previous Moving
        first.post(None, "Initialization")
    first.drain()
    assert first.subjects["Motor"].configuration == {"Returning"}
    first.close()  # the "crash": the return's completion never came


# (the event that entered Returning, the observer method redone)
ENTERED_BY = [("Error", "Error"), ("Initialization", "Initialization")]


@pytest.mark.parametrize(("entered_by", "method"), ENTERED_BY)
def test_a_resumed_returning_motor_gets_its_call_again_and_completes(
    tmp_path: Path, device_file: Path, entered_by: str, method: str
) -> None:
    """The redo re-issues the entering call; after the twin's delay the Motor is Blocked."""
    db = tmp_path / "run.db"
    leave_returning(db, device_file, entered_by)
    second = make_system(db, device_file)
    try:
        assert second.start(resume=True) == {"Motor": True}
        assert second.bound["Motor"].recovered == (f"redo {method}()",)
        assert api_calls(second) == [method]
        assert second.subjects["Motor"].configuration == {"Returning"}
        second.advance(LONG)
        assert second.subjects["Motor"].configuration == {"Blocked"}
    finally:
        second.close()


def test_a_real_motor_driver_returns_again_too(tmp_path: Path, device_file: Path) -> None:
    """With SimMotor the redone Error() calls return_to, and Error completion follows."""
    db = tmp_path / "run.db"
    leave_returning(db, device_file, "Error", driver="motor")
    second = make_system(db, device_file, driver="motor")
    try:
        second.start(resume=True)
        assert api_calls(second) == ["return_to"]
        second.advance(LONG)
        assert second.subjects["Motor"].configuration == {"Blocked"}
    finally:
        second.close()


def test_without_the_redo_rule_the_motor_stays_returning(tmp_path: Path, device_file: Path) -> None:
    """The problem the rule solves: no rule, no call, no completion, Returning for good."""
    text = device_file.read_text(encoding="utf-8")
    device_file.write_text(text.split("  # Returning waits")[0], encoding="utf-8")
    db = tmp_path / "run.db"
    leave_returning(db, device_file, "Error")
    second = make_system(db, device_file)
    try:
        second.start(resume=True)
        assert (second.bound["Motor"].recovered, api_calls(second)) == ((), [])
        second.advance(LONG * 2)
        assert second.subjects["Motor"].configuration == {"Returning"}
    finally:
        second.close()


@pytest.mark.parametrize(("entered_by", "method"), ENTERED_BY)
def test_the_redo_is_journalled_and_replays(
    tmp_path: Path, device_file: Path, entered_by: str, method: str
) -> None:
    """A recovery step with outcome redo and the redone event; replay finds no mismatch."""
    db = tmp_path / "run.db"
    leave_returning(db, device_file, entered_by)
    second = make_system(db, device_file)
    second.start(resume=True)
    second.advance(LONG)
    second.close()
    with JournalReader(db) as reader:
        rows = [(s.kind, s.event, s.outcome) for s in reader.steps()]
        result = replay(reader, {"Motor": load_device(device_file).chart})
    restore = rows.index((StepKind.RESTORE, None, ""))
    assert rows[restore + 1 : restore + 3] == [
        (StepKind.RECOVERY, entered_by, REDO),
        (StepKind.EVENT, f"{method} completion", "handled"),
    ]
    assert result.ok, [str(m) for m in result.mismatches]
    assert sorted(result.final["Motor"].active) == ["Blocked"]


def test_replay_does_not_post_the_redone_event(tmp_path: Path, device_file: Path) -> None:
    """Replay runs the journalled events only: the redo step re-issued calls, it ran no event."""
    db = tmp_path / "run.db"
    leave_returning(db, device_file, "Error")
    second = make_system(db, device_file)
    second.start(resume=True)
    second.advance(LONG)
    second.close()
    received: list[str] = []

    def hear(record: Record) -> None:
        if isinstance(record, EventReceived):
            received.append(record.event)

    with JournalReader(db) as reader:
        replay(reader, {"Motor": load_device(device_file).chart}, listener=hear)
    assert received == ["Movement", "Error", "Error completion"]


def test_replay_still_reports_a_redo_row_whose_snapshot_differs(
    tmp_path: Path, device_file: Path
) -> None:
    """A redo changes no state: a redo row claiming another snapshot is a mismatch."""
    db = tmp_path / "run.db"
    leave_returning(db, device_file, "Error")
    second = make_system(db, device_file)
    second.start(resume=True)
    second.close()
    with sqlite3.connect(db) as con:
        changed = con.execute(
            "UPDATE steps SET active = ? WHERE outcome = ?", ('["Blocked"]', REDO)
        ).rowcount
    assert changed == 1
    with JournalReader(db) as reader:
        result = replay(reader, {"Motor": load_device(device_file).chart})
    assert [m.expected for m in result.mismatches][:1] == [("Blocked",)]


def test_the_trace_shows_the_redone_call(tmp_path: Path, device_file: Path) -> None:
    """Listeners see InvokeIssued and ObserverCalled for the redo, and no state change."""
    db = tmp_path / "run.db"
    leave_returning(db, device_file, "Error")
    second = make_system(db, device_file)
    seen: list[Record] = []
    second.listen(seen.append)
    try:
        second.start(resume=True)
    finally:
        second.close()
    kinds = [type(r).__name__ for r in seen if type(r).__name__ != "Finished"]
    assert kinds == ["Started", "MicrostepTaken", "InvokeIssued", "ObserverCalled"]
    issued = next(r for r in seen if isinstance(r, InvokeIssued))
    called = next(r for r in seen if isinstance(r, ObserverCalled))
    assert (issued.method, issued.event, called.api) == ("Error", "Error", "SimTwin.Error()")


def test_a_second_crash_redoes_the_recovery_event_that_entered(
    tmp_path: Path, device_file: Path
) -> None:
    """Crash Moving, resume (Error rule: Returning), crash again: the redo redoes that Error."""
    db = tmp_path / "run.db"
    first = make_system(db, device_file)
    first.start()
    first.post(None, "Movement", {"amount": 1})
    first.drain()
    first.close()  # crash while Moving
    second = make_system(db, device_file)
    second.start(resume=True)
    assert second.bound["Motor"].recovered == ("Error",)
    assert second.subjects["Motor"].configuration == {"Returning"}
    second.close()  # crash while Returning: the entering step is the recovery's Error
    third = make_system(db, device_file)
    try:
        third.start(resume=True)
        assert third.bound["Motor"].recovered == ("redo Error()",)
        third.advance(LONG)
        assert third.subjects["Motor"].configuration == {"Blocked"}
    finally:
        third.close()


def test_a_journal_that_begins_inside_the_state_has_nothing_to_redo(
    tmp_path: Path, device_file: Path
) -> None:
    """Without the entering step in the journal the rule is skipped, and recovered says so."""
    db = tmp_path / "run.db"
    leave_returning(db, device_file, "Error")
    with sqlite3.connect(db) as con:  # keep only the last step: Returning, entered before it
        con.execute("DELETE FROM steps WHERE id < (SELECT max(id) FROM steps)")
        # and the accepted events those steps processed: a journal pruned, not damaged
        con.execute("DELETE FROM inbox WHERE seq < (SELECT max(inbox) FROM steps)")
    second = make_system(db, device_file)
    try:
        second.start(resume=True)
        assert second.bound["Motor"].recovered == ("redo Returning: nothing to redo",)
        assert api_calls(second) == []
    finally:
        second.close()


@pytest.mark.parametrize(
    ("kept", "entering"),
    [
        ("all", "Error"),  # walks back over the restore to the Error step
        ("none", None),  # no step at all
    ],
)
def test_entering_step_walks_back_over_restores(
    tmp_path: Path, device_file: Path, kept: str, entering: str | None
) -> None:
    """JournalReader.entering_step finds the event step whose predecessor lacked the state."""
    db = tmp_path / "run.db"
    leave_returning(db, device_file, "Error")
    second = make_system(db, device_file)
    second.start(resume=True)
    second.post(None, "Movement")  # declared ignored in Returning: does not leave it
    second.drain()
    second.close()
    if kept == "none":
        with sqlite3.connect(db) as con:
            con.execute("DELETE FROM steps")
    with JournalReader(db) as reader:
        found = reader.entering_step("Motor", "Returning")
    if entering is None:
        assert found is None
    else:
        assert found is not None
        before, step_row = found
        assert (step_row.kind, step_row.event, sorted(before.snapshot.active)) == (
            StepKind.EVENT,
            entering,
            ["Moving"],
        )


# --- Subject.reissue ----------------------------------------------------------------------


class Recorder:
    """An observer that remembers what it was told."""

    def __init__(self) -> None:
        self.notes: list[Notification] = []

    def update(self, notification: Notification) -> None:
        self.notes.append(notification)


def test_reissue_notifies_again_without_a_state_change() -> None:
    """reissue(step, data) calls the observer with the step's invoke and leaves the snapshot."""
    chart = load_device(MOTOR).chart
    subject = Subject(chart, clock=SimClock())
    observer = Recorder()
    subject.attach(observer)
    subject.start()
    subject.dispatch("Movement")
    before = subject.snapshot
    assert before is not None
    decision = step(subject.machine, before, "Error", {}, {"detail": "x"})
    issued = subject.reissue(decision, {"detail": "x"})
    assert [a.method for a in issued] == ["Error"]
    assert subject.snapshot == before
    assert [(n.method, n.data) for n in observer.notes] == [
        ("Movement", None),
        ("Error", {"detail": "x"}),
    ]


def test_reissue_takes_a_list_of_actions_and_issues_only_notifications() -> None:
    """Given actions, only the Notify ones are issued, in order."""
    chart = load_device(MOTOR).chart
    subject = Subject(chart, clock=SimClock())
    observer = Recorder()
    subject.attach(observer)
    subject.start()
    invoke = next(i for i in chart.invokes if i.method == "Initialization")
    notify = Notify(invoke.number, invoke.name, invoke.method, "Initialization")
    assert subject.reissue([notify]) == (notify,)
    assert [n.invoke for n in observer.notes] == [invoke.number]


# --- J607 / J608 --------------------------------------------------------------------------

WAITING = """\
device: Press
states:
  - state: Idle
    control: default
  - state: Pressing
    control: event trigger required
  - state: Open
    control: event trigger required
events:
  - {event: Press, old: Idle, new: Pressing, kind: command, api: Press}
  - {event: Pressed, old: Pressing, new: Idle, kind: completion, api: Press}
  - {event: Unlock, old: Idle, new: Open, kind: command}
  - {event: Lock, old: Open, new: Idle, kind: completion}
"""


@pytest.mark.parametrize(
    ("recovery", "codes"),
    [
        ("", ["J608", "J608"]),  # Pressing and Open wait for their device
        ("recovery:\n  - {state: Pressing, redo: yes}\n", ["J608"]),
        # Open is entered by Unlock, which has no api: nothing to redo
        ("recovery:\n  - {state: Pressing, redo: yes}\n  - {state: Open, redo: yes}\n", ["J607"]),
        ("recovery:\n  - {state: Pressing, redo: yes}\n  - {state: Open, event: Lock}\n", []),
    ],
)
def test_states_waiting_for_their_device_need_a_rule(
    tmp_path: Path, recovery: str, codes: list[str]
) -> None:
    """J608 for each state left only by completions without a rule; J607 for a redo of nothing."""
    path = tmp_path / "press.yaml"
    path.write_text(WAITING + recovery, encoding="utf-8")
    tables, diags = load(path)
    assert tables is not None and diags == []
    chart = load_chart(path)
    assert [d.code for d in check_recovery(chart, tables.recovery)] == codes


def test_a_substate_left_through_its_superstate_by_a_command_does_not_wait() -> None:
    """The gantry's Traversing completes by itself, but Pause leaves it from Running: no J608."""
    dev = load_device(ROOT / "examples" / "gantry" / "gantry.yaml")
    assert "J608" not in {d.code for d in check_recovery(dev.chart, dev.rules)}


#: The press of tests/support.py, its ram's Pressing resumed by a redo.
PARALLEL = PARALLEL_PRESS + "recovery:\n  - {state: Pressing, redo: yes}\n"


def test_a_redo_in_a_region_of_a_parallel_state_is_not_a_j607(tmp_path: Path) -> None:
    """Start enters Work and so both regions' defaults: redoing Pressing has Start's Go()."""
    path = tmp_path / "press.yaml"
    path.write_text(PARALLEL, encoding="utf-8")
    tables, diags = load(path)
    assert tables is not None and diags == []
    chart = load_chart(path)
    assert [d.code for d in check_recovery(chart, tables.recovery)] == []


def test_a_journalled_press_resumed_in_a_parallel_region_redoes_its_call(tmp_path: Path) -> None:
    """Closed while Pressing, the resumed press gets Go() again and its Done takes it to Idle."""
    path = tmp_path / "press.yaml"
    path.write_text(PARALLEL, encoding="utf-8")
    db = tmp_path / "run.db"

    def system() -> System:
        dev = load_device(path)
        twin = SimTwin(dev.chart, delay=LONG)
        return System(
            (DeviceSetup("Press", dev.chart, dev.rules, str(path), twin),), SimClock(), Journal(db)
        )

    first = system()
    first.start()
    first.post(None, "Start")
    first.drain()
    assert "Pressing" in first.subjects["Press"].configuration
    first.close()
    second = system()
    try:
        assert second.start(resume=True) == {"Press": True}
        assert second.bound["Press"].recovered == ("redo Go()",)
        assert api_calls(second) == ["Go"]
        second.advance(LONG)
        assert second.subjects["Press"].configuration == {"Idle"}
    finally:
        second.close()


#: CiA 402 style: Fault leaves Operation from whichever substate is active.
INHERITED = """\
device: Drive
states:
  - state: Operation
  - state: Enabled
    parent: Operation
    control: monitoring required
  - state: Faulted
    control: default
events:
  - {event: Enable, old: Faulted, new: Operation, kind: command}
  - {event: Fault, old: Operation, new: Faulted, kind: fault}
recovery:
  - {state: Enabled, event: Fault}
"""


def test_a_recovery_event_inherited_from_the_superstate_leaves_the_state(tmp_path: Path) -> None:
    """Fault is Operation's transition, so it leaves Enabled: no J604 for Enabled's rule."""
    path = tmp_path / "drive.yaml"
    path.write_text(INHERITED, encoding="utf-8")
    tables, diags = load(path)
    assert tables is not None and diags == []
    chart = load_chart(path)
    assert [d.code for d in check_recovery(chart, tables.recovery)] == []
