"""Fewer rows to write: ``ignore: all others``, the api column against the events, and
``event trigger required`` held to the event rows."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from statectl.front.builder.build import chart_to_tables, load_and_build
from statectl.front.rules import check_chart, check_paths
from statectl.kernel.errors import Diagnostic, Severity
from statectl.kernel.model import (
    Chart,
    ControlKind,
    EventDef,
    EventKind,
    State,
    StateKind,
    Transition,
)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = [
    ROOT / "examples" / "motor" / "motor.yaml",
    ROOT / "examples" / "gantry" / "gantry.yaml",
    ROOT / "examples" / "clamp" / "clamp.yaml",
    ROOT / "examples" / "pick-and-place" / "arm.yaml",
    ROOT / "examples" / "pick-and-place" / "conveyor.yaml",
]

#: A gripper: Idle handles Grip, Holding handles Release and (via its parent) Fault.
GRIPPER = """\
device: Gripper
states:
  - {{state: Idle, control: default, api: Grip(), ignore: [{idle}]}}
  - {{state: Busy, control: monitoring required}}
  - {{state: Holding, parent: Busy, control: default, api: {api}, ignore: [{holding}]}}
  - {{state: Broken, control: {broken}, ignore: [all others]}}
events:
  - {{event: Grip, old: Idle, new: Holding, kind: command, api: Grip}}
  - {{event: Release, old: Holding, new: Idle, kind: command, api: Release}}
  - {{event: Fault, old: Busy, new: Broken, kind: fault, api: Stop}}
  - {{event: Repair, old: Broken, new: Idle, kind: command}}
"""


def gripper(
    tmp_path: Path,
    *,
    idle: str = "all others",
    holding: str = "all others",
    api: str = "Release()",
    broken: str = "event trigger required",
) -> Path:
    path = tmp_path / "gripper.yaml"
    text = GRIPPER.format(idle=idle, holding=holding, api=api, broken=broken)
    path.write_text(text, encoding="utf-8")
    return path


def ignored_by(path: Path, state: str) -> list[str]:
    chart, diags = load_and_build(path)
    assert chart is not None, diags
    return sorted(e for s, e in chart.ignored if s == state)


def codes(diags: list[Diagnostic]) -> list[str]:
    return [d.code for d in diags]


@pytest.mark.parametrize("spelling", ["all others", "All Others", "'*'", "all  others"])
def test_all_others_stands_for_every_event_the_state_does_not_handle(
    tmp_path: Path, spelling: str
) -> None:
    """Idle handles Grip only: 'all others' ignores the three other events."""
    assert ignored_by(gripper(tmp_path, idle=spelling), "Idle") == ["Fault", "Release", "Repair"]


def test_all_others_leaves_out_what_an_ancestor_handles(tmp_path: Path) -> None:
    """Holding handles Release and its parent Busy handles Fault: neither is ignored."""
    assert ignored_by(gripper(tmp_path), "Holding") == ["Grip", "Repair"]


def test_named_items_may_stand_beside_all_others(tmp_path: Path) -> None:
    """'Fault, all others' is the same set, with no B208 for the 'all others' item."""
    path = gripper(tmp_path, idle="Fault, all others")
    assert ignored_by(path, "Idle") == ["Fault", "Release", "Repair"]


def test_all_others_silences_c404(tmp_path: Path) -> None:
    """Without 'all others' Idle misses three events (C404); with it, nothing."""
    assert "C404" not in codes(check_paths([str(gripper(tmp_path))]))
    missed = [d for d in check_paths([str(gripper(tmp_path, idle="Fault"))]) if d.code == "C404"]
    assert len(missed) == 1 and "'Idle'" in missed[0].message


def test_a_chart_written_back_lists_the_events_by_name() -> None:
    """The expansion is the chart's: tables made from it name each ignored event."""
    chart, _ = load_and_build(ROOT / "examples" / "clamp" / "clamp.yaml")
    assert chart is not None
    tables, diags = chart_to_tables(chart)
    assert tables is not None, diags
    released = next(s for s in tables.states if s.state == "Released")
    assert sorted(released.ignore) == ["Close timeout", "Closed", "Release", "Reset"]


# -- the api column against the events' APIs (B228) -----------------------------------------


@pytest.mark.parametrize(
    ("api", "expected"),
    [
        ("Release()", []),
        ("Release(), Grip()", []),  # Grip enters Holding
        ("Stop()", ["Stop() but no event entering or leaving it"]),  # Fault leaves Busy
        ("Relase()", ["no event row has that API"]),
    ],
)
def test_the_api_column_is_held_to_the_events_apis(
    tmp_path: Path, api: str, expected: list[str]
) -> None:
    """A method in a state's api cell is the API of an event entering or leaving it (B228)."""
    diags = [d for d in load_and_build(gripper(tmp_path, api=api))[1] if d.code == "B228"]
    assert all(d.severity is Severity.WARNING for d in diags)
    assert len(diags) == len(expected)
    for d, words in zip(diags, expected, strict=True):
        assert words in d.message and "'Holding'" in d.message


def test_a_typo_in_the_api_column_gets_a_did_you_mean(tmp_path: Path) -> None:
    """An unknown API method is named with the closest one the events use."""
    diags = [d for d in load_and_build(gripper(tmp_path, api="Relase()"))[1] if d.code == "B228"]
    assert "did you mean 'Release'" in diags[0].hint


def test_an_api_column_is_free_text_when_no_event_names_an_api(tmp_path: Path) -> None:
    """Without any event API there is nothing to hold the column to: no B228."""
    text = GRIPPER.format(
        idle="all others", holding="all others", api="Whatever()", broken="default"
    )
    text = "\n".join(
        line.split(", api:")[0] + "}" if "event:" in line else line for line in text.splitlines()
    )
    path = tmp_path / "gripper.yaml"
    path.write_text(text + "\n", encoding="utf-8")
    assert "B228" not in codes(load_and_build(path)[1])


# -- event trigger required (C411) ----------------------------------------------------------


@pytest.mark.parametrize(
    ("broken", "warned"),
    [
        ("event trigger required", False),  # entered by the fault event Fault
        ("default", False),
    ],
)
def test_trigger_states_entered_by_a_command_or_fault_are_fine(
    tmp_path: Path, broken: str, warned: bool
) -> None:
    """Broken is entered by a fault event: 'event trigger required' holds (no C411)."""
    diags = check_paths([str(gripper(tmp_path, broken=broken))])
    assert ("C411" in codes(diags)) is warned


def test_a_trigger_state_entered_only_by_completions_is_c411(tmp_path: Path) -> None:
    """Idle marked 'event trigger required' but entered only by completion events: C411."""
    path = gripper(tmp_path)
    text = path.read_text(encoding="utf-8")
    text = text.replace(
        "{state: Idle, control: default,", "{state: Idle, control: [default, trigger],"
    )
    text = text.replace(
        "new: Idle, kind: command, api: Release", "new: Idle, kind: completion, api: Release"
    )
    text = text.replace(
        "{event: Repair, old: Broken, new: Idle, kind: command}",
        "{event: Repair, old: Broken, new: Idle, kind: completion}",
    )
    path.write_text(text, encoding="utf-8")
    found = [d for d in check_paths([str(path)]) if d.code == "C411"]
    assert len(found) == 1 and "'Idle'" in found[0].message
    assert found[0].severity is Severity.WARNING


def regions_c411(trigger: str, target: str, kind: EventKind) -> list[str]:
    """The states C411 names when ``trigger`` is 'event trigger required' and the only way
    into the parallel P (regions R1: r1a, r1b and R2: r2a, r2b) is a ``kind`` event from A
    to ``target``; every other event is a completion."""
    marked = frozenset({ControlKind.TRIGGER})

    def state(name: str, **more: Any) -> State:
        return State(name, controls=marked if name == trigger else frozenset(), **more)

    states = [state("A"), state("P", kind=StateKind.PARALLEL)]
    for region, kids in {"R1": ("r1a", "r1b"), "R2": ("r2a", "r2b")}.items():
        states.append(state(region, kind=StateKind.COMPOUND, parent="P", initial=kids[:1]))
        states.extend(state(k, parent=region) for k in kids)
    rows = (
        Transition("A", ("go",), (target,)),
        Transition("r1a", ("next",), ("r1b",)),
        Transition("r2a", ("next",), ("r2b",)),
        Transition("P", ("back",), ("A",)),
    )
    events = (
        EventDef("go", kind),
        EventDef("next", EventKind.COMPLETION),
        EventDef("back", EventKind.COMPLETION),
    )
    chart = Chart("T", tuple(states), rows, ("A",), events=events)
    found = [d for d in check_chart(chart) if d.code == "C411"]
    assert all(f"state {trigger!r} " in d.message for d in found), found
    return [trigger for _ in found]


@pytest.mark.parametrize(
    ("trigger", "target", "kind", "named"),
    [
        ("r2a", "r1a", EventKind.COMMAND, []),  # entering r1a enters R2's default r2a too
        ("R2", "r1a", EventKind.COMMAND, []),  # ...and the region R2 itself
        ("r1a", "r2a", EventKind.FAULT, []),
        ("r2a", "P", EventKind.COMMAND, []),  # the parallel state's default entry
        ("r1a", "r1a", EventKind.COMMAND, []),  # the target itself
        ("P", "r2a", EventKind.COMMAND, []),  # an ancestor of the target
        ("r2b", "r1a", EventKind.COMMAND, ["r2b"]),  # R2 starts in r2a, not r2b
        ("r2b", "P", EventKind.COMMAND, ["r2b"]),  # likewise through P's default entry
        ("r2a", "r1a", EventKind.COMPLETION, ["r2a"]),  # entered, but not by a command
    ],
)
def test_c411_asks_the_kernel_what_a_command_enters(
    trigger: str, target: str, kind: EventKind, named: list[str]
) -> None:
    """A trigger state counts as entered by a command when the kernel's entry set of a
    command (or fault) transition holds it: every region of a parallel state it enters."""
    assert regions_c411(trigger, target, kind) == named


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.name)
def test_the_examples_pass_the_new_rules(example: Path) -> None:
    """The shipped examples raise none of B228, C409-C411."""
    found = [d for d in check_paths([str(example)]) if d.code in ("B228", "C409", "C410", "C411")]
    assert found == []
