"""C420/C421: a guard names only the states and events its device has (issue 27)."""

from __future__ import annotations

from pathlib import Path

import pytest

from statectl.cell.model import load_cell
from statectl.front.rules import check_paths

GRIPPER = """\
device: Gripper
states:
  - {state: Open, control: default}
  - {state: Closed}
events:
  - {event: Close, old: Open, new: Closed, kind: command, api: Grip, guard: "%s"}
  - {event: Open, old: Closed, new: Open, kind: command, api: Release}
"""


@pytest.mark.parametrize(
    ("guard", "code", "hint"),
    [
        ("In('Clsed')", "C420", "did you mean 'Closed'?"),
        ("previous == 'Clsed'", "C420", "did you mean 'Closed'?"),
        ("'Clsed' != previous", "C420", "did you mean 'Closed'?"),
        ("previous in ('Open', 'Clsed')", "C420", "did you mean 'Closed'?"),
        ("previous == 'Xyzzy'", "C420", "states: Open, Closed"),
        ("_event.name == 'Clse'", "C421", "did you mean 'Close'?"),
        ("_event['name'] not in ['Opn']", "C421", "did you mean 'Open'?"),
    ],
)
def test_a_guard_naming_what_the_device_lacks_is_an_error_at_its_row(
    tmp_path: Path, guard: str, code: str, hint: str
) -> None:
    """Each spelling is an error at the row, with the closest name when one is close."""
    path = tmp_path / "gripper.yaml"
    path.write_text(GRIPPER % guard, encoding="utf-8")
    found = [d for d in check_paths([str(path)]) if d.code.startswith("C42")]
    assert [(d.code, d.severity.value, d.where.line) for d in found] == [(code, "error", 6)]
    assert hint in (found[0].hint or "")


@pytest.mark.parametrize(
    "guard",
    [
        "In('Closed') or previous == 'Open'",
        "_event.name == 'Close'",
        "In('arm.Moving')",  # another device of a cell: the cell checks it (V831)
        "_event.name == 'done.state.Open'",
    ],
)
def test_names_the_device_has_pass(tmp_path: Path, guard: str) -> None:
    path = tmp_path / "gripper.yaml"
    path.write_text(GRIPPER % guard, encoding="utf-8")
    assert [d.code for d in check_paths([str(path)]) if d.code.startswith("C42")] == []


def test_a_cell_refuses_a_device_whose_guard_names_no_state(tmp_path: Path) -> None:
    """verify and run load the device through the cell: the same error stops them."""
    (tmp_path / "gripper.yaml").write_text(GRIPPER % "previous == 'Clsed'", encoding="utf-8")
    (tmp_path / "cell.yaml").write_text(
        "cell: C\ndevices:\n  gripper: gripper.yaml\n", encoding="utf-8"
    )
    cell, diags = load_cell(tmp_path / "cell.yaml")
    assert cell is None
    assert [d.code for d in diags] == ["V805", "C420"]


def test_a_cell_expression_naming_no_state_says_did_you_mean(tmp_path: Path) -> None:
    """An invariant's In('gripper.Opn') is V808 with the closest state."""
    (tmp_path / "gripper.yaml").write_text(GRIPPER % "In('Open')", encoding="utf-8")
    (tmp_path / "cell.yaml").write_text(
        "cell: C\ndevices:\n  gripper: gripper.yaml\n"
        "invariants:\n  - {name: x, holds: \"not In('gripper.Opn')\"}\n",
        encoding="utf-8",
    )
    cell, diags = load_cell(tmp_path / "cell.yaml")
    assert cell is None
    assert [d.code for d in diags] == ["V808"]
    assert (diags[0].hint or "").startswith("did you mean 'Open'?")
