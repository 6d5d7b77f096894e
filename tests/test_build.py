"""Step 2: device tables -> statechart, with merges, removals and their diagnostics."""

from __future__ import annotations

from pathlib import Path

import pytest

from statectl.front.builder.build import build, load_and_build, load_chart
from statectl.front.tables import DeviceTables
from statectl.front.tables.yaml_io import read_yaml
from statectl.kernel.errors import DiagnosticError, Severity
from statectl.kernel.model import Chart, ControlKind, EventKind, InvokeNumber, Notify, StateKind

MOTOR_YAML = Path(__file__).resolve().parent.parent / "examples" / "motor" / "motor.yaml"


def tables_of(text: str) -> DeviceTables:
    tables, diags = read_yaml(text, "t.yaml")
    assert tables is not None, [str(d) for d in diags]
    return tables


def motor() -> Chart:
    return load_chart(MOTOR_YAML)


BASE = """\
device: D
data:
  limit: 3
states:
  - state: A
    control: default
  - state: B
    control: event trigger required
events:
  - event: go
    old: A
    new: B
    api: Go
  - event: back
    old: B
    new: A
    kind: completion
    api: Go
"""


def with_rows(states: str = "", events: str = "") -> str:
    text = BASE
    if states:
        text = text.replace("events:\n", states + "events:\n")
    return text + events


# --- the Motor --------------------------------------------------------------------------


def test_motor_has_the_papers_states_and_transitions() -> None:
    """The Motor builds into 3 states and 6 transitions, starting Blocked."""
    chart = motor()
    assert [s.name for s in chart.states] == ["Blocked", "Moving", "Returning"]
    assert len(chart.transitions) == 6
    assert chart.initial == ("Blocked",)
    assert all(s.kind is StateKind.ATOMIC for s in chart.states)


def test_motor_invokes_are_the_papers() -> None:
    """Invoke numbers: Moving = 0, Returning = 1, Error = 2, as in the paper."""
    assert motor().invokes == (
        InvokeNumber(0, "Moving", "Movement"),
        InvokeNumber(1, "Returning", "Initialization"),
        InvokeNumber(2, "Error", "Error"),
    )


@pytest.mark.parametrize(
    ("event", "actions"),
    [
        ("Movement", (Notify(0, "Moving", "Movement", "Movement"),)),
        ("Movement completion", ()),
        ("Initialization", (Notify(1, "Returning", "Initialization", "Initialization"),)),
        ("Initialization completion", ()),
        ("Error", (Notify(2, "Error", "Error", "Error"),)),
        ("Error completion", ()),
    ],
)
def test_motor_driving_events_notify_their_invoke(event: str, actions: tuple[Notify, ...]) -> None:
    """Command and fault transitions notify one invoke; completions notify nothing."""
    t = next(t for t in motor().transitions if t.events == (event,))
    assert t.actions == actions


def test_motor_transition_keeps_guard_condition_and_row() -> None:
    """A transition carries the row's guard, condition and line."""
    t = next(t for t in motor().transitions if t.events == ("Initialization",))
    assert (t.source, t.targets, t.guard) == ("Blocked", ("Returning",), "previous == 'Moving'")
    assert t.condition == "the previous state was Moving"
    assert t.origin.line == 47


def test_motor_events_and_component() -> None:
    """One EventDef per event with kind and API; the state keeps component and API text."""
    chart = motor()
    error = chart.event("Error")
    assert error is not None
    assert (error.kind, error.api, error.description) == (
        EventKind.FAULT,
        "Error",
        "error during Moving",
    )
    assert chart.component == "Motor"
    assert chart.state("Returning").component == "Motor / Initialization(), Error()"
    assert chart.state("Moving").controls == frozenset(
        {ControlKind.TRIGGER, ControlKind.MONITORING}
    )


def test_motor_ignored_pairs() -> None:
    """The ignore cells become (state, event) pairs."""
    ignored = motor().ignored
    assert len(ignored) == 13
    assert ("Blocked", "Error") in ignored
    assert ("Blocked", "Initialization") in ignored  # when its guard is false
    assert ("Moving", "Error") not in ignored


def test_load_and_build_reports_nothing_for_the_motor() -> None:
    """The Motor builds without a single diagnostic."""
    chart, diags = load_and_build(MOTOR_YAML)
    assert chart is not None
    assert diags == []


# --- diagnostics ------------------------------------------------------------------------

# (case, yaml text, code, severity, whether a chart is still built, a word in message or hint)
BUILD_CASES = [
    (
        "unknown-state",
        with_rows(events="  - event: x\n    old: A\n    new: Bb\n"),
        "B201",
        Severity.ERROR,
        "did you mean 'B'",
    ),
    (
        "no-default",
        BASE.replace("control: default", "control: trigger"),
        "B202",
        Severity.ERROR,
        "default",
    ),
    (
        "two-defaults",
        BASE.replace("control: event trigger required", "control: default"),
        "B203",
        Severity.ERROR,
        "A, B",
    ),
    (
        "identical-events",
        with_rows(events="  - event: go\n    old: A\n    new: B\n    api: Go\n"),
        "B204",
        Severity.INFO,
        "rows at t.yaml:10, t.yaml:19",
    ),
    (
        "state-rows-merged",
        with_rows(states="  - state: B\n    control: monitoring\n"),
        "B205",
        Severity.INFO,
        "rows at t.yaml:7, t.yaml:9",
    ),
    (
        "event-kind-disagrees",
        with_rows(events="  - event: go\n    old: B\n    new: B\n    kind: fault\n    api: Go\n"),
        "B206",
        Severity.ERROR,
        "kind",
    ),
    (
        "event-api-disagrees",
        with_rows(events="  - event: go\n    old: B\n    new: B\n    api: Other\n"),
        "B206",
        Severity.ERROR,
        "api",
    ),
    ("unused-state", with_rows(states="  - state: C\n"), "B207", Severity.WARNING, "removed"),
    (
        "ignore-unknown",
        BASE.replace("control: default", "control: default\n    ignore: [goo]"),
        "B208",
        Severity.ERROR,
        "did you mean 'go'",
    ),
    (
        "unknown-parent",
        BASE.replace("control: event trigger required", "control: trigger\n    parent: Z"),
        "B209",
        Severity.ERROR,
        "unknown parent",
    ),
    (
        "parent-cycle",
        with_rows(states="  - state: C\n    parent: E\n  - state: E\n    parent: C\n"),
        "B210",
        Severity.ERROR,
        "ancestor",
    ),
    (
        "two-invoke-names",
        with_rows(
            events="  - event: go2\n    old: A\n    new: B\n    api: Go\n    invoke: X\n"
        ).replace(
            "    new: B\n    api: Go\n  - event: back",
            "    new: B\n    api: Go\n    invoke: Y\n  - event: back",
        ),
        "B211",
        Severity.ERROR,
        "invoke",
    ),
    (
        "guard-syntax",
        with_rows(events="  - event: x\n    old: A\n    new: B\n    guard: limit >\n"),
        "X301",
        Severity.ERROR,
        "parse",
    ),
    (
        "guard-refused",
        with_rows(events="  - event: x\n    old: A\n    new: B\n    guard: limit ** 2\n"),
        "X302",
        Severity.ERROR,
        "**",
    ),
    (
        "guard-unknown-name",
        with_rows(events="  - event: x\n    old: A\n    new: B\n    guard: limt > 2\n"),
        "X303",
        Severity.ERROR,
        "limt",
    ),
]


@pytest.mark.parametrize(
    ("text", "code", "severity", "word"),
    [pytest.param(t, c, s, w, id=i) for i, t, c, s, w in BUILD_CASES],
)
def test_build_diagnostic(text: str, code: str, severity: Severity, word: str) -> None:
    """Each table problem or merge is reported with its code; errors give no chart."""
    chart, diags = build(tables_of(text))
    found = [d for d in diags if d.code == code]
    assert found, [str(d) for d in diags]
    assert found[0].severity is severity
    assert word in found[0].message + " " + found[0].hint, str(found[0])
    assert (chart is None) == (severity is Severity.ERROR)


def test_identical_event_rows_become_one_transition() -> None:
    """Merging identical rows leaves one transition per (event, old, new, guard)."""
    row = "  - event: go\n    old: A\n    new: B\n    api: Go\n"
    chart, _ = build(tables_of(with_rows(events=row)))
    assert chart is not None
    assert [t.events for t in chart.transitions] == [("go",), ("back",)]


def test_merged_state_unites_controls_and_joins_descriptions() -> None:
    """Several rows of a state give one state with every control and description."""
    text = with_rows(states="  - state: B\n    control: monitoring\n    description: two\n")
    text = text.replace("control: event trigger required", "control: trigger\n    description: one")
    chart, _ = build(tables_of(text))
    assert chart is not None
    b = chart.state("B")
    assert b.controls == frozenset({ControlKind.TRIGGER, ControlKind.MONITORING})
    assert b.description == "one\ntwo"
    assert [s.name for s in chart.states] == ["A", "B"]


def test_unused_state_is_removed() -> None:
    """A state with no control that no event touches is not in the chart."""
    chart, _ = build(tables_of(with_rows(states="  - state: C\n")))
    assert chart is not None
    assert not chart.has_state("C")


CHILD = "  - state: %s\n    parent: B\n    control: %s\n"


@pytest.mark.parametrize(
    ("children", "initial"),
    [
        (CHILD % ("C1", "trigger") + CHILD % ("C2", "trigger"), "C1"),
        (
            CHILD % ("C1", "trigger") + CHILD % ("C2", "default"),
            "C2",
        ),
    ],
)
def test_parent_rows_make_a_compound_state(children: str, initial: str) -> None:
    """A state named as parent is compound; its initial is the default child, else the first."""
    chart, diags = build(tables_of(with_rows(states=children)))
    assert chart is not None, [str(d) for d in diags]
    b = chart.state("B")
    assert b.kind is StateKind.COMPOUND
    assert b.initial == (initial,)
    assert [s.name for s in chart.states] == ["A", "B", "C1", "C2"]
    assert chart.state("C1").parent == "B"


def test_children_follow_their_parent_in_document_order() -> None:
    """States are listed parents first even if a child's row comes first."""
    text = BASE.replace("states:\n", "states:\n  - state: C\n    parent: B\n    control: trigger\n")
    chart, diags = build(tables_of(text))
    assert chart is not None, [str(d) for d in diags]
    assert [s.name for s in chart.states] == ["A", "B", "C"]


def test_explicit_invoke_name_wins() -> None:
    """An invoke cell names the invoke instead of the derived name."""
    chart, _ = build(
        tables_of(
            BASE.replace(
                "    api: Go\n  - event: back", "    api: Go\n    invoke: Start\n  - event: back"
            )
        )
    )
    assert chart is not None
    assert chart.invokes == (InvokeNumber(0, "Start", "Go"),)
    assert chart.transitions[0].actions == (Notify(0, "Start", "Go", "go"),)


@pytest.mark.parametrize(
    ("value", "expr"),
    [("3", "3"), ("'x'", "'x'"), ("[1, 2]", "(1, 2)"), ("null", "None"), (".inf", "float('inf')")],
)
def test_data_becomes_data_items(value: str, expr: str) -> None:
    """Data values become DataItems holding an expression of the value."""
    chart, _ = build(tables_of(BASE.replace("limit: 3", f"limit: {value}")))
    assert chart is not None
    assert [(d.name, d.expr) for d in chart.data] == [("limit", expr)]


def test_guard_may_read_data_and_previous() -> None:
    """Guards read data names, previous and _event."""
    text = with_rows(
        events="  - event: x\n    old: A\n    new: B\n    guard: limit > 2 and previous == 'B'\n"
    )
    chart, diags = build(tables_of(text))
    assert chart is not None, [str(d) for d in diags]


def test_load_chart_raises_with_every_diagnostic(tmp_path: Path) -> None:
    """load_chart raises DiagnosticError carrying all problems."""
    path = tmp_path / "d.yaml"
    path.write_text(
        BASE.replace("control: default", "control: trigger").replace("new: A", "new: Q")
    )
    with pytest.raises(DiagnosticError) as info:
        load_chart(path)
    assert sorted(d.code for d in info.value.diagnostics) == ["B201", "B202"]
