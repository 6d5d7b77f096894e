"""Completions follow calls: the twin and the explorer share one model (issue 27)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from statectl.cell.explore import LocalSpace, explore
from statectl.cell.explore.replay import ReplayStep, run_cell
from statectl.cell.model import InputKind, load_cell_or_raise
from statectl.front.builder.build import build
from statectl.front.rules import check_paths
from statectl.front.tables import DeviceTables, EventRow, StateRow, load
from statectl.kernel.model import Chart, ControlKind, EventKind
from statectl.kernel.semantics import Snapshot
from statectl.run.devices.twin import SimTwin
from statectl.run.runtime import SimClock, Subject

CELLS = Path(__file__).parent / "data" / "cells"
GRIPPER = CELLS / "motor-gripper" / "cell.yaml"
NAMES = st.text("abcde", min_size=1, max_size=3)


@st.composite
def device_charts(draw: st.DrawFn) -> Chart:
    """Flat devices whose commands and faults call APIs that completions answer."""
    names = draw(st.lists(NAMES, min_size=2, max_size=4, unique=True))
    states = [
        StateRow(
            "Dev",
            "",
            n,
            (ControlKind.DEFAULT,)
            if i == 0
            else draw(st.sampled_from([(), (ControlKind.MONITORING,)])),
            "",
            (),
        )
        for i, n in enumerate(names)
    ]
    apis = ["Run", "Stop", "Halt"]
    rows = []
    for k in range(draw(st.integers(2, 9))):
        kind = draw(st.sampled_from([EventKind.COMMAND, EventKind.COMPLETION, EventKind.FAULT]))
        api = draw(st.sampled_from(apis))
        event = f"{api} {kind.value}" if kind is not EventKind.COMMAND else f"{api}{k % 2}"
        guard = draw(st.sampled_from(["", "", "previous == " + repr(names[0])]))
        old, new = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        rows.append(EventRow(event, "", guard, old, new, kind, api))
    chart, diags = build(DeviceTables("Dev", tuple(states), tuple(rows)))
    assert chart is not None, [str(d) for d in diags]
    return chart


def _run(chart: Chart) -> tuple[Subject, SimTwin]:
    clock = SimClock()
    subject = Subject(chart, clock=clock, name="dev")
    twin = SimTwin(chart, delay=1e9)  # reports only when the test says so
    twin.bind(subject.post, clock)
    subject.attach(twin)
    subject.start()
    subject.run_until_idle()
    return subject, twin


def _lid(space: LocalSpace, subject: Subject, twin: SimTwin) -> int:
    assert space.calls is not None
    calls = tuple(k for k in twin.pending_calls if space.calls.tracked(space.calls.call(*k)))
    lid = space.lookup(subject.snapshot or Snapshot(frozenset()), subject.data, calls)
    assert lid is not None, f"the explorer never has {subject.configuration} with calls {calls}"
    return lid


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(device_charts(), st.lists(st.integers(0, 30), max_size=14))
def test_twin_and_explorer_offer_the_same_completions(chart: Chart, moves: list[int]) -> None:
    """On random devices and runs, the explorer offers exactly the completions the twin
    would report, and every step (a command, a fault or the twin's report) reaches a
    local state, calls included, that the explorer predicts."""
    space = LocalSpace("dev", chart, calls=True)
    subject, twin = _run(chart)
    driving = [e.name for e in chart.events if e.kind is not EventKind.COMPLETION]
    completions = [e.name for e in chart.events if e.kind is EventKind.COMPLETION]
    for move in moves:
        lid = _lid(space, subject, twin)
        offered = {c for c in completions if space.reports(lid, c)}
        assert offered == {c for c in completions if twin.would_report(c)}
        options = [(False, e) for e in driving] + [(True, c) for c in sorted(offered)]
        if not options:
            return
        report, event = options[move % len(options)]
        expected = {o.target for o in (space.reports if report else space.outcomes)(lid, event)}
        if report:
            assert twin.complete_now(event)
        else:
            subject.post(event)
        subject.run_until_idle()
        assert _lid(space, subject, twin) in expected | ({lid} if not report else set())


def test_motor_and_gripper_do_not_deadlock() -> None:
    """Issue 27's cell: the Motor answers Initialization() with Initialization completion,
    never Error completion, so the gripper always opens again: every property holds."""
    report = explore(load_cell_or_raise(GRIPPER))
    assert report.findings == ()
    assert report.verdict == "holds"


def test_replay_refuses_a_completion_no_twin_reports() -> None:
    """The trace verify used to print (an Error completion answering Initialization())
    stops at its step 3 with the twin's reason, instead of being injected."""
    steps = [
        ReplayStep(InputKind.COMMAND, "motor", "Movement"),
        ReplayStep(InputKind.COMPLETION, "motor", "Movement completion"),
        ReplayStep(InputKind.COMPLETION, "motor", "Error completion"),
    ]
    result = run_cell(load_cell_or_raise(GRIPPER), replay=steps)
    assert result.steps == 2
    assert any(
        d.startswith("step 3: motor's twin would not report Error completion")
        and "Initialization() for Initialization" in d
        for d in result.divergences
    ), result.divergences


def test_replay_plays_the_twins_completions() -> None:
    """A real run replays with no divergence: each completion is the twin's report."""
    steps = [
        ReplayStep(InputKind.COMMAND, "motor", "Movement"),
        ReplayStep(InputKind.COMPLETION, "motor", "Movement completion"),
        ReplayStep(
            InputKind.COMPLETION,
            "motor",
            "Initialization completion",
            (("motor", "Blocked"), ("gripper", "Open")),
        ),
    ]
    result = run_cell(load_cell_or_raise(GRIPPER), replay=steps)
    assert (result.steps, result.divergences) == (3, ())


DOOR = """\
device: Door
states:
  - {state: Shut, control: default}
  - {state: Open}
events:
  - {event: Push, old: Shut, new: Open, kind: command, api: Swing}
  - {event: Kick, old: Shut, new: Open, kind: command}
  - {event: Swung shut, old: Open, new: Shut, kind: completion, api: Swing%s}
"""


def _door_cell(tmp_path: Path, unasked: str) -> Path:
    (tmp_path / "door.yaml").write_text(DOOR % unasked, encoding="utf-8")
    cell = tmp_path / "cell.yaml"
    cell.write_text(
        "cell: Doors\ndevices:\n  door: door.yaml\n"
        "environment:\n  - {send: Push, to: door}\n  - {send: Kick, to: door}\n",
        encoding="utf-8",
    )
    return cell


def test_a_completion_comes_only_after_its_call(tmp_path: Path) -> None:
    """A door kicked open was never called, so no Swung shut comes: a real deadlock."""
    report = explore(load_cell_or_raise(_door_cell(tmp_path, "")))
    assert [f.kind.value for f in report.findings] == ["deadlock"]
    assert report.findings[0].trace is not None
    assert [s.event for s in report.findings[0].trace.steps] == ["Kick"]


def test_an_unasked_completion_is_offered_without_a_call(tmp_path: Path) -> None:
    """``unasked: yes`` says the door may swing shut by itself: no deadlock."""
    report = explore(load_cell_or_raise(_door_cell(tmp_path, ", unasked: yes")))
    assert report.findings == ()


def test_bad_unasked_cells_are_t125(tmp_path: Path) -> None:
    """A value other than yes/no, or unasked on a command, is T125 at its row."""
    bad = DOOR.replace("kind: command, api: Swing}", "kind: command, api: Swing, unasked: yes}")
    for text in (DOOR % ", unasked: maybe", bad % ""):
        path = tmp_path / "door.yaml"
        path.write_text(text, encoding="utf-8")
        _, diags = load(path)
        assert [d.code for d in diags] == ["T125"], [str(d) for d in diags]


VALVE = """\
device: Valve
states:
  - {state: Shut, control: default}
  - {state: Open}
events:
  - {event: Go, old: Shut, new: Open, guard: "_event.data.ok", data: {ok: bool}}
  - {event: Stop, old: Open, new: Shut}
"""


def test_verdicts_that_rely_on_an_over_approximation_say_so(tmp_path: Path) -> None:
    """A counterexample through a free choice over untracked data is marked "may not be
    reproducible" (text and JSON); a deadlock verdict that holds on such a model is
    marked over-approximated; a cell without free choices or deferred events has no mark."""
    (tmp_path / "valve.yaml").write_text(VALVE, encoding="utf-8")
    (tmp_path / "cell.yaml").write_text(
        "cell: V\ndevices:\n  valve: valve.yaml\n"
        "environment:\n  - {send: Go, to: valve}\n  - {send: Stop, to: valve}\n"
        "invariants:\n  - {name: shut, holds: \"In('valve.Shut')\"}\n",
        encoding="utf-8",
    )
    report = explore(load_cell_or_raise(tmp_path / "cell.yaml"))
    (finding,) = report.failures
    assert finding.assumed == ("a free choice over data verify does not track",)
    text = report.to_text()
    assert "shortest trace (1 steps; may not be reproducible: assumes a free choice" in text
    assert "FAILS      invariant shut: In('valve.Shut') [may not be reproducible:" in text
    assert "HOLDS      no deadlock [over-approximated: a free choice" in text
    doc = report.to_json()
    assert doc["findings"][0]["reproducible"] is False
    assert doc["properties"][0]["assumes"] == list(finding.assumed)
    clean = explore(load_cell_or_raise(GRIPPER))
    assert clean.relies == () and "over-approximated" not in clean.to_text()


def test_a_completion_that_answers_no_call_is_c422(tmp_path: Path) -> None:
    """Kick opens the door with no call, and Swung shut names no API: C422 (warning),
    unless the row says unasked: yes."""
    path = tmp_path / "door.yaml"
    path.write_text((DOOR % "").replace(', api: Swing}\n"""', "}"), encoding="utf-8")
    text = (DOOR % "").replace("kind: completion, api: Swing", "kind: completion")
    path.write_text(text, encoding="utf-8")
    found = [d for d in check_paths([str(path)]) if d.code == "C422"]
    assert [(d.severity.value, d.where.line) for d in found] == [("warning", 8)]
    assert "it names no API" in found[0].message
    unasked = text.replace("kind: completion", "kind: completion, unasked: yes")
    path.write_text(unasked, encoding="utf-8")
    assert [d for d in check_paths([str(path)]) if d.code == "C422"] == []
    path.write_text(DOOR % "", encoding="utf-8")  # Push calls Swing(): answered
    assert [d for d in check_paths([str(path)]) if d.code == "C422"] == []


def test_run_replay_exits_1_naming_the_step(tmp_path: Path) -> None:
    """``statectl run CELL --replay TRACE`` with the old impossible trace exits 1 and
    names step 3 (it exited 0 after injecting the completion)."""
    trace = tmp_path / "old.trace.yaml"
    trace.write_text(
        "steps:\n"
        "  - {source: environment, to: motor, event: Movement}\n"
        "  - {source: completion, to: motor, event: Movement completion}\n"
        "  - {source: completion, to: motor, event: Error completion}\n",
        encoding="utf-8",
    )
    src = str(Path(__file__).parents[1] / "src")
    done = subprocess.run(
        [sys.executable, "-m", "statectl", "run", str(GRIPPER), "--replay", str(trace)],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": src},
        timeout=120,
    )
    assert done.returncode == 1, done.stdout[-2000:] + done.stderr[-2000:]
    assert "diverged: step 3: motor's twin would not report Error completion" in done.stdout


ARM = """\
device: Arm
states:
  - {state: Work, control: default}
  - {state: Reaching, parent: Work, control: [default, monitoring required]}
  - {state: Stopped}
  - {state: Dropped}
events:
  - {event: Overload, old: Reaching, new: Stopped, kind: fault, api: Halt}
  - {event: Power loss, old: Work, new: Dropped, kind: fault, api: Halt}
"""


def test_a_fault_is_offered_where_an_active_monitor_raises_it(tmp_path: Path) -> None:
    """Reaching's monitor raises Overload (a row leaving Reaching), not Power loss (a row
    of its superstate, which no monitor watches): verify offers what the runtime's
    monitors raise, so Dropped is never reached."""
    (tmp_path / "arm.yaml").write_text(ARM, encoding="utf-8")
    (tmp_path / "cell.yaml").write_text(
        "cell: A\ndevices:\n  arm: arm.yaml\n"
        "environment:\n  - {fault: Overload, to: arm}\n  - {fault: Power loss, to: arm}\n",
        encoding="utf-8",
    )
    report = explore(load_cell_or_raise(tmp_path / "cell.yaml"))
    unreached = [f.name for f in report.findings if f.kind.value == "unreached state"]
    assert unreached == ["arm.Dropped"]
