"""The Promela export, cross-checked with SPIN: same verdicts, same counterexample lengths."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from statectl.cell.explore import Composed, Kind, explore, export_promela
from statectl.cell.explore.promela import STEP_MARK
from statectl.cell.model import load_cell_or_raise

PICK = Path(__file__).resolve().parents[1] / "examples" / "pick-and-place"
HAVE_SPIN = shutil.which("spin") is not None and shutil.which("gcc") is not None
needs_spin = pytest.mark.skipif(not HAVE_SPIN, reason="SPIN (Debian package spin) or gcc absent")

ONESHOT = """\
device: OneShot
states:
  - {state: Idle, control: default}
  - {state: Done, control: event trigger required, ignore: [Go]}
events:
  - {event: Go, old: Idle, new: Done, kind: command, api: Go}
"""


def spin(text: str, folder: Path, flag: str) -> tuple[bool, int]:
    """Run SPIN breadth-first; (an error was found, stimuli in its trail)."""
    (folder / "m.pml").write_text(text, encoding="utf-8")
    subprocess.run(["spin", "-a", "m.pml"], cwd=folder, check=True, capture_output=True)
    subprocess.run(
        ["gcc", "-O2", "-DBFS", "-DSAFETY", "-DNOREDUCE", "-o", "pan", "pan.c"],
        cwd=folder,
        check=True,
        capture_output=True,
    )
    pan = subprocess.run(["./pan", flag], cwd=folder, capture_output=True, text=True)
    failed = "errors: 0" not in pan.stdout
    if not failed:
        return False, 0
    trail = subprocess.run(["spin", "-t", "m.pml"], cwd=folder, capture_output=True, text=True)
    return True, trail.stdout.count(STEP_MARK)


def test_export_names_every_device() -> None:
    """The export declares one variable per device and one option per stimulus."""
    model = Composed(load_cell_or_raise(PICK / "cell.yaml"))
    text = export_promela(model)
    for name in ("l_conveyor", "l_arm", "l_gripper", "l_sensor"):
        assert f"byte {name};" in text
    assert text.count(f'printf("{STEP_MARK}') == sum(
        1
        for s in model.stimuli
        if any(
            model.enabled_locally(s, lid)
            and any(o.handled for o in model.spaces[s.device].outcomes(lid, s.event))
            for lid in range(len(model.spaces[s.device].snapshots))
        )
    )


@needs_spin
@pytest.mark.parametrize(
    ("cell", "invariants", "unhandled", "kind"),
    [
        ("cell-buggy.yaml", True, False, Kind.INVARIANT),
        ("cell-buggy.yaml", False, True, Kind.UNHANDLED),
        ("cell.yaml", True, True, None),
    ],
)
def test_spin_agrees_on_safety(
    tmp_path: Path, cell: str, invariants: bool, unhandled: bool, kind: Kind | None
) -> None:
    """SPIN finds a safety violation exactly when statectl does, with a trail as short."""
    loaded = load_cell_or_raise(PICK / cell)
    model = Composed(loaded)
    report = explore(loaded, model=model)
    text = export_promela(model, invariants=invariants, unhandled=unhandled)
    failed, steps = spin(text, tmp_path, "-E")
    mine = [f for f in report.failures if f.kind is kind]
    assert failed == bool(mine)
    if mine:
        assert steps == min(len(f.trace) for f in mine if f.trace is not None)


@needs_spin
@pytest.mark.parametrize(("cell", "deadlock"), [("cell.yaml", False), ("oneshot", True)])
def test_spin_agrees_on_deadlock(tmp_path: Path, cell: str, deadlock: bool) -> None:
    """SPIN's invalid end state is statectl's deadlock."""
    if cell == "oneshot":
        (tmp_path / "shot.yaml").write_text(ONESHOT, encoding="utf-8")
        path = tmp_path / "cell.yaml"
        path.write_text(
            "devices: {shot: shot.yaml}\nenvironment:\n  - {send: Go, to: shot}\n", encoding="utf-8"
        )
    else:
        path = PICK / cell
    loaded = load_cell_or_raise(path)
    model = Composed(loaded)
    report = explore(loaded, model=model)
    failed, steps = spin(export_promela(model), tmp_path, "-A")
    assert failed == deadlock == any(f.kind is Kind.DEADLOCK for f in report.failures)
    if deadlock:
        assert steps == len(report.failures[0].trace or ())
