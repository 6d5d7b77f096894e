"""examples/axis-drive: a PLCopen axis linked to its CiA 402 drive, both from the shipped
profiles, verified by `statectl verify`."""

from __future__ import annotations

import io
import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from statectl.channels.cli import main
from statectl.front.profiles import find, profile_tables
from statectl.front.tables import load, strip_locations

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "axis-drive"


def verify(cell: Path) -> dict[str, object]:
    out, err = io.StringIO(), io.StringIO()
    code = main(["verify", str(cell), "--json"], out, err)
    report: dict[str, object] = json.loads(out.getvalue())
    assert code == (0 if report["verdict"] == "holds" else 1), err.getvalue()
    return report


def failed(report: dict[str, object]) -> list[str]:
    props = report["properties"]
    assert isinstance(props, list)
    return [p["property"].split(":")[0] for p in props if p["verdict"] != "holds"]


def test_axis_drive_cell_holds() -> None:
    """Every property of the axis-drive cell holds, over the complete state space."""
    report = verify(EXAMPLE / "cell.yaml")
    assert report["verdict"] == "holds" and report["complete"] is True
    assert failed(report) == []
    # deadlock, link events, guard errors, livelock, and the cell's invariants and recovery
    assert len(report["properties"]) == 7  # type: ignore[arg-type]


@pytest.mark.parametrize(("device", "profile"), [("axis", "plcopen-axis"), ("drive", "cia402")])
def test_example_devices_are_the_profiles(device: str, profile: str) -> None:
    """The example's device files are the shipped profiles as `statectl new` writes them."""
    tables, diags = load(EXAMPLE / f"{device}.yaml")
    assert tables is not None, diags
    shipped = replace(profile_tables(find(profile)), device=device)  # type: ignore[arg-type]
    assert strip_locations(tables) == strip_locations(shipped)


def test_without_re_enabling_after_a_reset_motion_needs_a_powered_drive_fails(
    tmp_path: Path,
) -> None:
    """Leaving out the link that walks the drive back up after a fault reset lets the axis
    move on a drive without torque: verify finds it (the invariants can fail)."""
    for name in ("axis.yaml", "drive.yaml"):
        shutil.copy(EXAMPLE / name, tmp_path / name)
    text = (EXAMPLE / "cell.yaml").read_text(encoding="utf-8")
    link = (
        "  - {from: drive, enters: Switch on disabled, to: drive, send: Shutdown,\n"
        "     guard: \"In('axis.Enabled')\"}\n"
    )
    assert link in text
    (tmp_path / "cell.yaml").write_text(text.replace(link, ""), encoding="utf-8")
    report = verify(tmp_path / "cell.yaml")
    assert "invariant motion-needs-a-powered-drive" in failed(report)


def test_axis_drive_cell_runs_on_twins_through_power_move_fault_and_reset() -> None:
    """`statectl run` on the cell with simulated twins: MC_Power walks the drive up by
    Shutdown, Switch on, Enable operation; a drive fault stops the axis; MC_Reset resets
    the drive and walks it up again; MC_Power off disables the drive's voltage."""
    import os
    import subprocess
    import sys

    lines = (
        "drive: Initialized\naxis: MC_Power\n+2\naxis: MC_MoveAbsolute\n+2\n"
        "drive: Fault occurred\n+2\naxis: MC_Reset\n+2\naxis: MC_MoveVelocity\n+1\n"
        "axis: MC_Power off\n+1\n"
    )
    env = {
        **os.environ,
        "PYTHONPATH": f"{ROOT / 'src'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
    }
    done = subprocess.run(
        [sys.executable, "-m", "statectl", "run", str(EXAMPLE / "cell.yaml")],
        input=lines,
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    steps = [
        line.split(" on ")[-1] for line in done.stdout.splitlines() if "  drive  state " in line
    ]
    walk_up = ["Shutdown", "Switch on", "Enable operation"]
    assert steps == [
        "Initialized",
        *walk_up,
        "Fault occurred",
        "Fault reaction completed",
        "Fault reset",
        *walk_up,
        "Disable voltage",
    ]
    assert "final axis: Disabled, No error" in done.stdout
    assert "final drive: Fault free, Switch on disabled" in done.stdout
