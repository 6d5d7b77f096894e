"""The shipped standard profiles: they check clean, carry the standards' numbers and
transitions, and agree with the code that speaks the same standard."""

from __future__ import annotations

from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import Any

import pytest

from statectl.front.builder.build import build
from statectl.front.profiles import PROFILES, find, profile_tables
from statectl.front.rules import check_chart, check_paths
from statectl.front.tables import load, strip_locations
from statectl.kernel.errors import Severity
from statectl.kernel.model import Chart, StateKind
from statectl.kernel.semantics import Machine, Snapshot, step
from statectl.out.render import render
from statectl.run.devices.cia402.profile import STATUS_MASKS, PowerState, drive_step

NAMES = [p.name for p in PROFILES]


def chart_of(name: str) -> Chart:
    profile = find(name)
    assert profile is not None
    chart, diags = build(profile_tables(profile))
    assert chart is not None, diags
    return chart


def shipped_path(name: str) -> str:
    return str(resources.files("statectl").joinpath("data", "profiles", f"{name}.yaml"))


@pytest.mark.parametrize("name", NAMES)
def test_profile_checks_clean(name: str) -> None:
    """A shipped profile passes statectl check with no error and no warning."""
    problems = [d for d in check_paths([shipped_path(name)]) if d.severity is not Severity.INFO]
    assert problems == []


@pytest.mark.parametrize("name", NAMES)
def test_profile_declares_itself(name: str) -> None:
    """A shipped profile's file declares its own profile name."""
    assert chart_of(name).profile == name


@pytest.mark.parametrize(
    ("name", "atomic"), [("cia402", 8), ("packml", 17), ("plcopen-axis", 8), ("motor", 3)]
)
def test_profile_has_the_standards_states(name: str, atomic: int) -> None:
    """Each profile has the standard's number of (atomic) states, each numbered if the
    standard numbers them."""
    states = [s for s in chart_of(name).states if s.kind is StateKind.ATOMIC]
    assert len(states) == atomic
    numbered = [s.name for s in states if s.number is not None]
    assert numbered == ([] if name == "motor" else [s.name for s in states])


STATE_NUMBERS = [
    ("packml", "Clearing", 1),
    ("packml", "Stopped", 2),
    ("packml", "Starting", 3),
    ("packml", "Idle", 4),
    ("packml", "Suspended", 5),
    ("packml", "Execute", 6),
    ("packml", "Stopping", 7),
    ("packml", "Aborting", 8),
    ("packml", "Aborted", 9),
    ("packml", "Holding", 10),
    ("packml", "Held", 11),
    ("packml", "Unholding", 12),
    ("packml", "Suspending", 13),
    ("packml", "Unsuspending", 14),
    ("packml", "Resetting", 15),
    ("packml", "Completing", 16),
    ("packml", "Complete", 17),
    ("plcopen-axis", "ErrorStop", 1),
    ("plcopen-axis", "Disabled", 2),
    ("plcopen-axis", "Stopping", 3),
    ("plcopen-axis", "Homing", 4),
    ("plcopen-axis", "Standstill", 5),
    ("plcopen-axis", "Discrete Motion", 6),
    ("plcopen-axis", "Continuous Motion", 7),
    ("plcopen-axis", "Synchronized Motion", 8),
]


@pytest.mark.parametrize(("name", "state", "number"), STATE_NUMBERS)
def test_state_numbers(name: str, state: str, number: int) -> None:
    """A profile state carries the standard's number (PackML StateCurrent, PLCopen's order)."""
    assert chart_of(name).state(state).number == number


def test_cia402_numbers_and_masks_are_the_drivers() -> None:
    """Each CiA 402 state's number is the statusword value the driver decodes it by, and
    the statusword masks in the profile's data are the driver's."""
    chart = chart_of("cia402")
    data = dict(profile_tables(find("cia402")).data)  # type: ignore[arg-type]
    for mask, value, state in STATUS_MASKS:
        assert chart.state(state.value).number == value
        key = "sw_" + state.value.lower().replace(" ", "_")
        assert data[key] == (mask, value)


#: The controlword each CiA 402 command event writes (the driver's constants' values).
CONTROLWORDS = {
    "Shutdown": 0x06,
    "Switch on": 0x07,
    "Enable operation": 0x0F,
    "Disable operation": 0x07,
    "Disable voltage": 0x00,
    "Quick stop": 0x02,
    "Fault reset": 0x80,
}


def test_cia402_command_rows_are_what_the_simulated_drive_does() -> None:
    """Every controlword row of the profile leads where the simulated drive goes on that
    controlword, and the profile's [mask, value] for the command matches the word."""
    chart = chart_of("cia402")
    data = dict(profile_tables(find("cia402")).data)  # type: ignore[arg-type]
    seen = 0
    for t in chart.transitions:
        event = t.events[0]
        if event not in CONTROLWORDS:
            continue
        cw = CONTROLWORDS[event]
        mask, value = data["cw_" + event.lower().replace(" ", "_")]  # type: ignore[misc]
        assert cw & mask == value, event
        assert drive_step(PowerState(t.source), cw, 0) is PowerState(t.targets[0]), t.condition
        seen += 1
    assert seen == 15


def test_cia402_transitions_zero_to_sixteen() -> None:
    """The CiA 402 rows name the standard's transitions 1-16 (0 is the initial state), and
    transition 13, a fault from any state, is one row on a superstate."""
    chart = chart_of("cia402")
    numbers = {int(t.condition[1 : t.condition.index(")")]) for t in chart.transitions}
    assert numbers == set(range(1, 17))
    assert chart.initial == ("Fault free",)
    assert chart.state("Fault free").initial == ("Not ready to switch on",)
    faults = [t for t in chart.transitions if t.condition.startswith("(13)")]
    assert [(t.source, t.targets) for t in faults] == [("Fault free", ("Fault reaction active",))]


def _lineage(chart: Chart, state: str) -> frozenset[str]:
    names = {state}
    parent = chart.state(state).parent
    while parent is not None:
        names.add(parent)
        parent = chart.state(parent).parent
    return frozenset(names)


SUPERSTATE_ROWS = [
    # profile, event, superstate whose every atomic state it leaves, target
    ("cia402", "Fault occurred", "Fault free", "Fault reaction active"),
    ("packml", "Stop", "Running", "Stopping"),
    ("packml", "Abort", "Cleared", "Aborting"),
    ("plcopen-axis", "Axis error", "No error", "ErrorStop"),
    ("plcopen-axis", "MC_Power off", "Enabled", "Disabled"),
]


@pytest.mark.parametrize(("name", "event", "superstate", "target"), SUPERSTATE_ROWS)
def test_from_any_state_rows(name: str, event: str, superstate: str, target: str) -> None:
    """A "from any state" event, one row on a superstate, takes every state in it to the
    same target (stepped by the kernel)."""
    chart = chart_of(name)
    m = Machine(chart)
    inside = [
        s.name
        for s in chart.states
        if s.kind is StateKind.ATOMIC and superstate in _lineage(chart, s.name)
    ]
    assert len(inside) >= 3
    for state in inside:
        after = step(m, Snapshot(_lineage(chart, state)), event).target
        assert target in after.active, state


def test_packml_hierarchy_is_opc_30050s() -> None:
    """PackML's states nest as OPC 30050 has them: Aborting and Aborted at the top, the
    machine states in Cleared, the execute states in Running."""
    chart = chart_of("packml")
    parents = {s.name: s.parent for s in chart.states}
    assert [n for n, p in parents.items() if p is None] == ["Cleared", "Aborting", "Aborted"]
    assert sorted(n for n, p in parents.items() if p == "Cleared") == [
        "Clearing",
        "Running",
        "Stopped",
        "Stopping",
    ]
    assert len([n for n, p in parents.items() if p == "Running"]) == 12


def test_motor_profile_is_the_shipped_motor() -> None:
    """The motor profile holds the same tables as the package's Motor (only the profile key
    differs)."""
    ours = profile_tables(find("motor"))  # type: ignore[arg-type]
    theirs, diags = load(str(resources.files("statectl").joinpath("data", "motor.yaml")))
    assert theirs is not None, diags
    assert strip_locations(replace(ours, profile="")) == strip_locations(theirs)


@pytest.mark.parametrize(
    ("given", "found"),
    [("packml", "packml"), ("PackML", "packml"), ("plcopen_axis", "plcopen-axis"), ("x", None)],
)
def test_find_is_lenient_about_spelling(given: str, found: str | None) -> None:
    """A profile is found by name whatever its case and whether '_' or '-' joins it."""
    profile = find(given)
    assert (profile.name if profile else None) == found


DOCS = Path(__file__).resolve().parents[1] / "docs" / "profiles.md"


@pytest.mark.parametrize("name", NAMES)
def test_docs_show_the_current_diagram(name: str) -> None:
    """docs/profiles.md embeds each profile's diagram exactly as `statectl render
    --format mermaid` draws it now."""
    drawn = render(chart_of(name), "mermaid").rstrip("\n")
    assert f"```mermaid\n{drawn}\n```" in DOCS.read_text(encoding="utf-8")


def test_docs_show_the_current_listing() -> None:
    """docs/profiles.md shows `statectl profiles` as it prints now."""
    import io

    from statectl.channels.cli import main

    out = io.StringIO()
    assert main(["profiles"], out, io.StringIO()) == 0
    assert f"$ statectl profiles\n{out.getvalue()}" in DOCS.read_text(encoding="utf-8")


def test_a_monitored_child_inherits_its_superstates_fault_row() -> None:
    """Moving 'monitoring required' from CiA 402's Fault free to one of its children
    still checks clean: the superstate's fault row leaves the child (no C407), and the
    child's monitor raises it for the superstate (no C408)."""
    from statectl.kernel.model import ControlKind

    tables = profile_tables(find("cia402"))  # type: ignore[arg-type]

    def controls(row: Any) -> Any:
        if row.state == "Fault free":
            return replace(row, controls=(ControlKind.DEFAULT,))
        if row.state == "Operation enabled":
            return replace(row, controls=(*row.controls, ControlKind.MONITORING))
        return row

    chart, _ = build(replace(tables, states=tuple(controls(s) for s in tables.states)))
    assert chart is not None
    assert ControlKind.MONITORING in chart.state("Operation enabled").controls
    assert ControlKind.MONITORING not in chart.state("Fault free").controls
    codes = [d.code for d in check_chart(chart) if d.severity is not Severity.INFO]
    assert codes == []
