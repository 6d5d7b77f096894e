"""`statectl run --driver none`: time passes only on +SECONDS lines, and those are checked."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import statectl
from support import ROOT

CLAMP = ROOT / "examples" / "clamp" / "clamp.yaml"
SRC = str(os.path.dirname(os.path.dirname(statectl.__file__)))


def _run(lines: str) -> tuple[int, list[dict[str, object]], str]:
    done = subprocess.run(
        [sys.executable, "-m", "statectl", "run", str(CLAMP), "--driver", "none", "--json"],
        input=lines,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": SRC},
    )
    rows = [json.loads(line) for line in done.stdout.splitlines()]
    return done.returncode, rows, done.stderr


def test_a_timeout_waits_for_a_plus_line() -> None:
    """Close alone leaves the Clamp Closing at t=0; the timeout runs out on '+2' only."""
    code, rows, _ = _run("Close\n+2\n")
    assert code == 0
    assert (rows[0]["t"], rows[0]["state"]) == (0.0, ["Closing"])
    assert [s["event"] for s in rows[1]["steps"]] == ["Close timeout"]  # type: ignore[index]


def test_a_deferred_event_can_be_stepped_by_hand() -> None:
    """Release given while Closing is kept, and released when Closed is given."""
    code, rows, _ = _run("Close\nRelease\nClosed\n")
    assert code == 0
    assert rows[1]["why"] == "declared ignored"
    assert rows[2]["state"] == ["Released"]


@pytest.mark.parametrize("line", ["+1e400", "+inf", "+nan", "+-1"])
def test_a_plus_line_needs_finite_seconds(line: str) -> None:
    """A +SECONDS line that is not a finite number of seconds >= 0 is refused (exit 1)."""
    code, rows, err = _run(f"Close\n{line}\n")
    assert code == 1
    assert "finite number of seconds" in str(rows[1]["error"])
    assert "line 2:" in err and "Traceback" not in err


@pytest.mark.parametrize("argv", [["node", str(CLAMP), "--node", "a"], ["dashboard", str(CLAMP)]])
def test_node_and_dashboard_name_a_device_file_as_such(argv: list[str]) -> None:
    """A device file given to node or dashboard is one C416 saying to use check or run."""
    done = subprocess.run(
        [sys.executable, "-m", "statectl", *argv],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": SRC},
    )
    assert done.returncode == 1
    assert "C416 error: this is a device file" in done.stderr
    assert "V802" not in done.stderr and "Traceback" not in done.stderr


CELL = ROOT / "examples" / "clamp" / "cell.yaml"


@pytest.mark.parametrize(
    "argv",
    [
        ["render", str(CELL), "--format", "mermaid"],
        ["observers", str(CELL)],
        ["build", str(CELL)],
        ["codegen", str(CELL), "--out", "unused"],
    ],
)
def test_device_commands_name_a_cell_file_as_such(argv: list[str], tmp_path: Path) -> None:
    """A cell file given to a device command is C415 saying to use verify, not T102."""
    done = subprocess.run(
        [sys.executable, "-m", "statectl", *argv],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": SRC},
    )
    assert done.returncode == 1
    assert "C415 error: this is a cell file" in done.stderr
    assert "T102" not in done.stderr and "Traceback" not in done.stderr
    assert list(tmp_path.iterdir()) == []


NODES = ROOT / "examples" / "pick-and-place" / "cell-nodes.yaml"

USAGE_CASES = [
    (["node", str(NODES), "--node", "line", "--dashboard", "--port", "99999"], "--port must be"),
    (["dashboard", str(NODES), "--port", "99999"], "--port must be"),
    (["dashboard", str(NODES), "--connect", "bogus"], "is not a Zenoh endpoint"),
    (["dashboard", str(NODES), "--connect", "tcp/127.0.0.1:99999"], "a port is a number"),
]


@pytest.mark.parametrize(("argv", "said"), USAGE_CASES)
def test_node_and_dashboard_usage_errors_have_no_traceback(argv: list[str], said: str) -> None:
    """A port out of range or a --connect that is no endpoint is a usage error (exit 2)."""
    done = subprocess.run(
        [sys.executable, "-m", "statectl", *argv],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": SRC},
    )
    assert done.returncode == 2, done.stderr
    assert said in done.stderr and "Traceback" not in done.stderr


KEPT_CASES = [
    ("Close\nRelease\n", 1, True, 0),  # Closing defers Release: kept
    ("Close\nClose\n", 1, False, 0),  # Closing ignores Close: gone
    ("Close\n" + "Release\n" * 17, 17, False, 1),  # the 17th is dropped (16 kept at most)
]


@pytest.mark.parametrize(("lines", "index", "kept", "exit_code"), KEPT_CASES)
def test_json_says_when_an_ignored_event_is_kept(
    lines: str, index: int, kept: bool, exit_code: int
) -> None:
    """--json adds kept: true to a line whose event the active state defers and keeps."""
    code, rows, _ = _run(lines)
    assert code == exit_code
    assert rows[index]["why"] == "declared ignored"
    assert rows[index].get("kept", False) is kept


def test_a_plus_line_too_long_to_wait_is_a_bad_line_in_a_live_run() -> None:
    """`+1e308` in a --realtime run is reported and the next line still runs; time.sleep
    used to overflow, which killed the feeding thread with a traceback and left the run
    waiting forever for input it could no longer read."""
    import io
    import threading

    from statectl.channels.cli.run import run

    motor = ROOT / "examples" / "motor" / "motor.yaml"
    out, err = io.StringIO(), io.StringIO()
    lines = io.StringIO("+1e308\nMovement\n")
    stop = threading.Event()
    bound = threading.Timer(30.0, stop.set)  # a bound on a run that hangs, not a measurement
    bound.start()
    try:
        code = run(
            str(motor), driver="none", realtime=True, events=lines, out=out, err=err, stop=stop
        )
    finally:
        bound.cancel()
    assert (code, "line 1: '+' waits at most" in err.getvalue()) == (1, True), err.getvalue()
    assert "Blocked -> Moving" in out.getvalue()
