"""``statectl run --driver none --json``: a model stepped by hand, one JSON object per line.

Scenarios are played on the shipped examples, line by line, as a user checking a
scenario in CI would: each expected step is (handled, why not, state after).
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from statectl.channels.cli.run import run

ROOT = Path(__file__).resolve().parents[1]
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"
PICK = ROOT / "examples" / "pick-and-place"
CONVEYOR = PICK / "conveyor.yaml"
GANTRY = ROOT / "examples" / "gantry" / "gantry.yaml"


def step(path: Path, lines: str, driver: str = "none") -> tuple[int, list[dict[str, Any]], str]:
    """Run ``path`` with ``lines`` on stdin and ``--json``: exit code, objects, stderr."""
    out, err = io.StringIO(), io.StringIO()
    code = run(str(path), driver=driver, events=io.StringIO(lines), out=out, err=err, as_json=True)
    return code, [json.loads(line) for line in out.getvalue().splitlines()], err.getvalue()


Step = tuple[bool, str | None, list[str]]  # handled, why not, state after

SCENARIOS: list[tuple[str, Path, list[str], list[Step]]] = [
    (
        "motor: a second Movement is ignored while Moving, Initialization only after Moving",
        MOTOR,
        ["Initialization", "Movement", "Movement", "Movement completion", "Initialization"],
        [
            (False, "declared ignored", ["Blocked"]),  # guard false: ignored as listed
            (True, None, ["Moving"]),
            (False, "declared ignored", ["Moving"]),
            (True, None, ["Blocked"]),
            (True, None, ["Returning"]),
        ],
    ),
    (
        "motor: nothing completes by itself without a driver, however long one waits",
        MOTOR,
        ["Movement", "Error", "Error completion"],
        [
            (True, None, ["Moving"]),
            (True, None, ["Returning"]),
            (True, None, ["Blocked"]),
        ],
    ),
    (
        "conveyor: Start is ignored once Arrived; Resume runs again; Jam is ignored when Stopped",
        CONVEYOR,
        ["Start", "Arrive", "Start", "Resume", "Stop", "Jam"],
        [
            (True, None, ["Running"]),
            (True, None, ["Arrived"]),
            (False, "declared ignored", ["Arrived"]),
            (True, None, ["Running"]),
            (True, None, ["Stopped"]),
            (False, "declared ignored", ["Stopped"]),
        ],
    ),
    (
        "motor: an event the chart does not know is not handled, and says why",
        MOTOR,
        ["Bogus"],
        [(False, "unknown event", ["Blocked"])],
    ),
]


@pytest.mark.parametrize(
    ("path", "lines", "expected"),
    [pytest.param(p, lines, want, id=name) for name, p, lines, want in SCENARIOS],
)
def test_scenario_step_by_step(path: Path, lines: list[str], expected: list[Step]) -> None:
    """Each event line gives one object: handled or why not, and the state after it."""
    _, objects, _ = step(path, "\n".join(lines) + "\n")
    assert [o["event"] for o in objects] == lines
    assert [(o["handled"], o["why"], o["state"]) for o in objects] == expected
    assert [o["line"] for o in objects] == list(range(1, len(lines) + 1))


def test_invokes_issued_are_listed_with_their_line() -> None:
    """An object lists the invokes its line issued (number, name, observer method), only those."""
    _, objects, _ = step(MOTOR, "Movement\nMovement\n")
    assert [[(i["invoke"], i["name"], i["method"]) for i in o["invokes"]] for o in objects] == [
        [(0, "Moving", "Movement")],
        [],
    ]


def test_no_driver_means_only_the_events_given() -> None:
    """With ``--driver none`` time passes and nothing happens: no completion, no step."""
    _, objects, _ = step(MOTOR, "Movement\n+30\n")
    assert objects[1] == {"line": 2, "t": 30.0, "advance": 30.0, "invokes": [], "steps": []}
    assert objects[0]["state"] == ["Moving"]


def test_with_a_twin_the_completion_appears_among_the_steps() -> None:
    """With the default twin a line's object also lists the completion its driver reported."""
    _, objects, _ = step(MOTOR, "Movement\n", driver="sim-twin")
    assert [(s["event"], s["outcome"]) for s in objects[0]["steps"]] == [
        ("Movement", "handled"),
        ("Movement completion", "handled"),
    ]
    assert objects[0]["state"] == ["Blocked"]


def test_bad_line_is_an_error_object_and_exit_1() -> None:
    """A malformed line gives ``{"line", "error"}``, the run goes on and exits 1."""
    code, objects, err = step(MOTOR, "Movement {amount: \nMovement\n")
    assert code == 1
    assert objects[0]["line"] == 1 and "error" in objects[0]
    assert objects[1]["state"] == ["Moving"]
    assert "line 1:" in err


def test_unknown_event_exits_1() -> None:
    """A line whose event the chart does not know makes the run exit 1 (batch runs in CI)."""
    code, _, err = step(MOTOR, "Bogus\n")
    assert code == 1 and "unknown" in err


def test_a_cell_reports_every_device_state() -> None:
    """A cell's objects add ``states``: every device's configuration after the line."""
    code, objects, _ = step(PICK / "cell.yaml", "conveyor: Start\n")
    assert code == 0
    assert objects[0]["state"] == ["Running"]
    assert objects[0]["states"]["conveyor"] == ["Running"]
    assert set(objects[0]["states"]) == {"conveyor", "arm", "gripper", "sensor"}


def test_hierarchy_state_lists_the_whole_configuration() -> None:
    """In a chart with parents and parallel regions the state is the sorted configuration."""
    _, objects, _ = step(GANTRY, "EStop\nReset\n")
    assert objects[0]["handled"] and "EStopped" in objects[0]["state"]
    assert objects[1]["handled"] and "Running" in objects[1]["state"]
    assert objects[1]["state"] == sorted(objects[1]["state"])


def cli(argv: list[str], stdin: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "statectl", *argv],
        input=stdin,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )


def test_command_line_writes_only_json_on_stdout() -> None:
    """``statectl run --driver none --json``: every stdout line is JSON; banners go to stderr."""
    done = cli(["run", str(MOTOR), "--driver", "none", "--json"], "Movement\n# note\n\n+1\n")
    assert done.returncode == 0, done.stderr
    objects = [json.loads(line) for line in done.stdout.splitlines()]
    assert [o["line"] for o in objects] == [1, 4]
    assert "the model alone" in done.stderr and "final state Moving" in done.stderr


@pytest.mark.parametrize(
    "extra",
    [["--dashboard"], ["--realtime"], ["--walk", "3"]],
)
def test_json_with_a_live_run_is_a_usage_error(extra: list[str]) -> None:
    """``--json`` steps a batch run: with a live run or a walk it is refused with exit 2."""
    done = cli(["run", str(PICK / "cell.yaml"), "--json", *extra], "")
    assert done.returncode == 2, done.stderr
    assert "--json" in done.stderr and "Traceback" not in done.stderr
