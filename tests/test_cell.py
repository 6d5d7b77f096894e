"""The cell file: schema, loading, and a V8xx diagnostic for every problem."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from statectl.cell.model import CODES, InputKind, Trigger, load_cell, load_cell_or_raise
from statectl.cell.options import foreign_in
from statectl.front.builder.build import load_chart
from statectl.kernel.errors import DiagnosticError, Severity

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
PICK = EXAMPLES / "pick-and-place"
MOTOR = (EXAMPLES / "motor" / "motor.yaml").as_posix()

GOOD = f"""\
cell: Two motors
devices:
  left: {MOTOR}
  right: {MOTOR}
links:
  - {{from: left, enters: Moving, to: right, send: Movement}}
  - {{from: left, raises: Error, to: right, send: Error, guard: "In('right.Moving')"}}
environment:
  - {{send: Movement, to: left, when: "In('right.Blocked')"}}
  - {{fault: Error, to: left}}
invariants:
  - {{name: calm, holds: "not (In('left.Returning') and In('right.Returning'))"}}
recovery:
  - {{name: home, to: "In('left.Blocked') and In('right.Blocked')"}}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cell.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def codes(tmp_path: Path, text: str) -> set[str]:
    cell, diags = load_cell(write(tmp_path, text))
    assert cell is None
    return {d.code for d in diags if d.severity is Severity.ERROR}


def test_same_device_file_twice(tmp_path: Path) -> None:
    """One device file may be instantiated under two names; both get the same chart."""
    cell = load_cell_or_raise(write(tmp_path, GOOD))
    assert [d.name for d in cell.devices] == ["left", "right"]
    assert cell.devices[0].chart == cell.devices[1].chart


def test_rules_are_read(tmp_path: Path) -> None:
    """Links, environment, invariants and recovery keep what the file says."""
    cell = load_cell_or_raise(write(tmp_path, GOOD))
    assert [(k.source, k.trigger, k.what, k.target, k.event) for k in cell.links] == [
        ("left", Trigger.ENTERS, "Moving", "right", "Movement"),
        ("left", Trigger.RAISES, "Error", "right", "Error"),
    ]
    assert cell.links[1].guard is not None and cell.links[1].guard.refs == (("right", "Moving"),)
    assert [(e.kind, e.device, e.event) for e in cell.environment] == [
        (InputKind.COMMAND, "left", "Movement"),
        (InputKind.FAULT, "left", "Error"),
    ]
    assert cell.invariants[0].name == "calm"
    assert cell.recovery[0].source is None


@pytest.mark.parametrize(
    ("change", "code"),
    [
        (("devices:\n  left:", "devices:\n  le.ft:"), "V806"),
        ((f"right: {MOTOR}", "right: nowhere.yaml"), "V805"),
        ((f"right: {MOTOR}", 'right: "motor\\0.yaml"'), "V805"),
        (("to: right, send: Movement}", "to: nobody, send: Movement}"), "V807"),
        (("enters: Moving", "enters: Flying"), "V808"),
        (("send: Movement}", "send: Jump}"), "V809"),
        (("In('right.Moving')", "speed > 3"), "V810"),
        (("In('right.Moving')", "In('right')"), "V807"),
        (("In('right.Moving')", "In(right)"), "V811"),
        (("enters: Moving, ", "enters: Moving, raises: Error, "), "V813"),
        (("name: calm", "name: home"), "V814"),
        (("cell: Two motors", "cell: Two motors\nspeed: 3"), "V802"),
        (("{send: Movement, to: left,", "{to: left,"), "V803"),
        (("links:\n", "links: 3\nx:\n"), "V804"),
        (("In('left.Returning')", "In('left.Flying')"), "V808"),
        (('holds: "not', 'holds: "1 +'), "V810"),
    ],
)
def test_problem_codes(tmp_path: Path, change: tuple[str, str], code: str) -> None:
    """Each kind of mistake in a cell file is reported with its stable code."""
    assert change[0] in GOOD
    assert code in codes(tmp_path, GOOD.replace(*change))


def test_every_problem_at_once(tmp_path: Path) -> None:
    """Loading collects all problems rather than stopping at the first."""
    text = GOOD.replace("enters: Moving", "enters: Flying").replace("send: Error,", "send: Oops,")
    assert {"V808", "V809"} <= codes(tmp_path, text)


@pytest.mark.parametrize(
    ("text", "code"),
    [
        ("", "V801"),
        ("- a list\n", "V801"),
        ("cell: [unclosed\n", "V801"),
        ("cell: x\n", "V803"),
        ("devices: {}\n", "V815"),
    ],
)
def test_not_a_cell(tmp_path: Path, text: str, code: str) -> None:
    """Files that are not cells give one clear diagnostic, never a traceback."""
    assert code in codes(tmp_path, text)


def test_missing_file() -> None:
    """A missing cell file is V801."""
    cell, diags = load_cell("/nonexistent/cell.yaml")
    assert cell is None and [d.code for d in diags] == ["V801"]


def test_fault_in_unmonitored_device(tmp_path: Path) -> None:
    """A fault on a device with no monitored state can never happen: V812."""
    device = tmp_path / "lamp.yaml"
    device.write_text(
        "device: Lamp\nstates:\n  - {state: Off, control: default}\n"
        "  - {state: On, control: event trigger required}\nevents:\n"
        "  - {event: Switch, old: Off, new: On, kind: command}\n"
        "  - {event: Burn, old: On, new: Off, kind: fault}\n",
        encoding="utf-8",
    )
    text = "devices:\n  lamp: lamp.yaml\nenvironment:\n  - {fault: Burn, to: lamp}\n"
    assert "V812" in codes(tmp_path, text)


def test_raise_carries_every_diagnostic(tmp_path: Path) -> None:
    """load_cell_or_raise raises DiagnosticError with all diagnostics."""
    with pytest.raises(DiagnosticError) as info:
        load_cell_or_raise(write(tmp_path, "devices: {}\n"))
    assert info.value.diagnostics[0].code == "V815"


@pytest.mark.parametrize("name", ["cell.yaml", "cell-buggy.yaml"])
def test_examples_load(name: str) -> None:
    """Both pick-and-place cells load without errors."""
    cell, diags = load_cell(PICK / name)
    assert cell is not None, [str(d) for d in diags]
    assert [d.name for d in cell.devices] == ["conveyor", "arm", "gripper", "sensor"]


def test_codes_documented() -> None:
    """Every code the loader can emit is in CODES."""
    package = Path(__file__).resolve().parents[1] / "src/statectl/cell"
    source = "".join(p.read_text(encoding="utf-8") for p in sorted(package.glob("*.py")))
    used = set(re.findall(r'"(V8[0-9][0-9])"', source))
    assert used, "the scan found no V8xx code: it no longer reads the loader"
    assert used <= set(CODES)


@pytest.mark.parametrize(
    ("source", "foreign"),
    [
        ("In('arm.Moving')", "arm.Moving"),  # another device's state
        ("In('Moving')", None),  # the Motor's own state
        ("In('Nowhere')", None),  # no dot: the device file's to report (C420)
        ("In(x)", None),
        ("'arm.Moving'", None),
    ],
)
def test_foreign_in_names_only_another_devices_state(source: str, foreign: str | None) -> None:
    """foreign_in: what cross_refs, the explorer's local space and its cross guards ask."""
    chart = load_chart(MOTOR)
    assert foreign_in(ast.parse(source, mode="eval").body, chart) == foreign
