"""Static checks: each rule fires on its own small chart and stays quiet on a near miss."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from statectl.front.recovery import CODES as RECOVERY_CODES
from statectl.front.rules import CODES, check_chart, check_paths, guards_exclusive
from statectl.kernel.errors import Location, Severity
from statectl.kernel.model import (
    Chart,
    ControlKind,
    EventDef,
    EventKind,
    State,
    StateKind,
    Transition,
)

MOTOR = Path(__file__).resolve().parent.parent / "examples" / "motor" / "motor.yaml"

Row = tuple[str, str, str | None, str | None]  # source, event, target (None: targetless), guard


def make_chart(
    rows: Sequence[Row],
    *,
    extra_states: Sequence[str] = (),
    final: Sequence[str] = (),
    monitored: Sequence[str] = (),
    faults: Sequence[str] = (),
    extra_events: Sequence[str] = (),
    ignore: Sequence[tuple[str, str]] = (),
    auto_ignore: bool = True,
) -> Chart:
    """A flat chart from event rows; rows sit on lines 10, 11, ... of ``t.yaml``.

    ``auto_ignore`` lists every (state, event) the rows leave unhandled in the ignore
    column, so a case triggers only the rule it is about.
    """
    names: dict[str, None] = {}
    for src, _, dst, _ in rows:
        names.setdefault(src, None)
        if dst is not None:
            names.setdefault(dst, None)
    for name in extra_states:
        names.setdefault(name, None)
    states = tuple(
        State(
            n,
            kind=StateKind.FINAL if n in final else StateKind.ATOMIC,
            controls=frozenset({ControlKind.MONITORING}) if n in monitored else frozenset(),
            origin=Location("t.yaml", i + 1),
        )
        for i, n in enumerate(names)
    )
    transitions = tuple(
        Transition(
            src,
            (event,),
            (dst,) if dst is not None else (),
            guard=guard,
            origin=Location("t.yaml", 10 + i),
        )
        for i, (src, event, dst, guard) in enumerate(rows)
    )
    event_names = list(dict.fromkeys([r[1] for r in rows] + list(extra_events)))
    events = tuple(
        EventDef(
            e,
            EventKind.FAULT if e in faults else EventKind.COMMAND,
            origin=Location("t.yaml", 30 + i),
        )
        for i, e in enumerate(event_names)
    )
    ignored = set(ignore)
    if auto_ignore:
        handled = {(r[0], r[1]) for r in rows}
        ignored |= {(n, e) for n in names for e in event_names if (n, e) not in handled}
    return Chart(
        "T",
        states,
        transitions,
        initial=(next(iter(names)),),
        events=events,
        ignored=frozenset(ignored),
    )


LOOP: list[Row] = [("A", "go", "B", None), ("B", "back", "A", None)]

# (case, chart, expected codes)
CASES = [
    ("C401 unreachable", make_chart([*LOOP, ("C", "x", "A", None)]), {"C401"}),
    ("C401 near miss", make_chart([*LOOP, ("C", "x", "A", None), ("A", "y", "C", None)]), set()),
    ("C402 no way out", make_chart([("A", "go", "B", None)]), {"C402"}),
    ("C402 near miss: final", make_chart([("A", "go", "B", None)], final=["B"]), set()),
    ("C402 near miss: one state", make_chart([("A", "tick", None, None)]), set()),
    ("C403 both unguarded", make_chart([*LOOP, ("A", "go", "A", None)]), {"C403"}),
    ("C403 may both hold",
     make_chart([*LOOP[1:], ("A", "go", "B", "x > 1"), ("A", "go", "A", "x <= 1 or y")]),
     {"C403"}),
    ("C403 near miss: exclusive",
     make_chart([*LOOP[1:], ("A", "go", "B", "x"), ("A", "go", "A", "not x")]), set()),
    ("C404 missed", make_chart(LOOP, auto_ignore=False), {"C404"}),
    ("C404 near miss", make_chart(LOOP), set()),
    ("C405 unused event", make_chart(LOOP, extra_events=["spare"]), {"C405"}),
    ("C405 near miss", make_chart([*LOOP, ("B", "spare", "B", None)]), set()),
    ("C406 contradictory ignore", make_chart(LOOP, ignore=[("A", "go")]), {"C406"}),
    ("C406 near miss", make_chart(LOOP, ignore=[("B", "go")]), set()),
    ("C407 monitor raises nothing", make_chart(LOOP, monitored=["B"]), {"C407"}),
    ("C407 near miss",
     make_chart([*LOOP, ("B", "fail", "A", None)], monitored=["B"], faults=["fail"]), set()),
    ("C408 fault not monitored",
     make_chart([*LOOP, ("B", "fail", "A", None)], faults=["fail"]), {"C408"}),
    ("C408 near miss", make_chart([*LOOP, ("B", "fail", "A", None)]), set()),
    ("C419 may all be false",
     make_chart([*LOOP[1:], ("A", "go", "B", "previous == 'B'")]), {"C419"}),
    ("C419 two guards leave a gap",
     make_chart([*LOOP[1:], ("A", "go", "B", "x > 3"), ("A", "go", "A", "x < 3")]), {"C419"}),
    ("C419 near miss: the guards cover",
     make_chart([*LOOP[1:], ("A", "go", "B", "x > 3"), ("A", "go", "A", "x <= 3")]), set()),
    ("C419 near miss: a part and its negation",
     make_chart([*LOOP[1:], ("A", "go", "B", "ready(x)"), ("A", "go", "A", "not ready(x)")]),
     set()),
]  # fmt: skip


@pytest.mark.parametrize(("case", "chart", "expected"), CASES, ids=[c[0] for c in CASES])
def test_each_rule_fires_exactly_on_its_case(case: str, chart: Chart, expected: set[str]) -> None:
    """Each rule's chart triggers exactly that code; its near miss triggers nothing."""
    assert {d.code for d in check_chart(chart)} == expected


SEVERITIES = [
    ("C401", make_chart([*LOOP, ("C", "x", "A", None)]), Severity.ERROR),
    ("C403", make_chart([*LOOP, ("A", "go", "A", None)]), Severity.ERROR),
    ("C403", make_chart([*LOOP[1:], ("A", "go", "B", None), ("A", "go", "A", "y")]),
     Severity.WARNING),
    ("C404", make_chart(LOOP, auto_ignore=False), Severity.WARNING),
]  # fmt: skip


@pytest.mark.parametrize(("code", "chart", "severity"), SEVERITIES)
def test_severity_of_each_code(code: str, chart: Chart, severity: Severity) -> None:
    """Unreachable states and unguarded duplicates are errors; a possible overlap warns."""
    assert {d.severity for d in check_chart(chart) if d.code == code} == {severity}


def test_every_code_has_a_hint_and_a_location() -> None:
    """Each diagnostic points at a file line and says what to do."""
    chart = make_chart(
        [*LOOP, ("A", "go", "A", None), ("C", "x", "A", None), ("B", "fail", "A", None)],
        monitored=["C"],
        faults=["fail"],
        extra_events=["spare"],
        ignore=[("A", "go")],
    )
    found = list(check_chart(chart))
    assert {d.code for d in found} == {"C401", "C403", "C405", "C406", "C407", "C408"}
    assert all(d.hint and d.where.file == "t.yaml" and d.where.line for d in found)


def test_all_problems_are_reported_not_the_first() -> None:
    """Several unreachable states each get a diagnostic in one run."""
    chart = make_chart([*LOOP, ("C", "x", "A", None), ("D", "y", "A", None)])
    assert [d.message.split("'")[1] for d in check_chart(chart) if d.code == "C401"] == ["C", "D"]


def test_overlap_names_both_rows() -> None:
    """C403 sits on the later row and names both rows' lines."""
    chart = make_chart([("A", "go", "B", "x > 1"), ("B", "back", "A", None), ("A", "go", "A", "y")])
    (diag,) = [d for d in check_chart(chart) if d.code == "C403"]
    assert diag.where.line == 12
    assert "line 10" in diag.message and "line 12" in diag.message


def test_missed_transition_hint_names_ignore_column() -> None:
    """C404 lists the missed events and suggests a row or the ignore column."""
    chart = make_chart(LOOP, auto_ignore=False)
    messages = {d.message for d in check_chart(chart)}
    assert messages == {
        "state 'A' neither handles nor ignores 'back' (missed transition)",
        "state 'B' neither handles nor ignores 'go' (missed transition)",
    }
    assert all("ignore column" in d.hint for d in check_chart(chart))


def test_ancestor_handles_event_for_children() -> None:
    """A compound state's transition handles the event for its substates (no C404)."""
    chart = Chart(
        "T",
        (
            State("P", kind=StateKind.COMPOUND, initial=("a",)),
            State("a", parent="P"),
            State("b", parent="P"),
            State("Off"),
        ),
        (
            Transition("P", ("stop",), ("Off",)),
            Transition("a", ("next",), ("b",)),
            Transition("b", ("next",), ("a",)),
            Transition("Off", ("start",), ("P",)),
        ),
        initial=("P",),
        ignored=frozenset({("P", "start"), ("Off", "stop"), ("Off", "next")}),
    )
    assert list(check_chart(chart)) == []


def test_parallel_regions_are_reachable() -> None:
    """Entering a parallel state enters every region's default state."""
    chart = Chart(
        "T",
        (
            State("Idle"),
            State("Run", kind=StateKind.PARALLEL),
            State("R1", kind=StateKind.COMPOUND, parent="Run"),
            State("x", parent="R1"),
            State("R2", kind=StateKind.COMPOUND, parent="Run"),
            State("y", parent="R2"),
            State("z", parent="R2"),
        ),
        (
            Transition("Idle", ("go",), ("x",)),
            Transition("Run", ("stop",), ("Idle",)),
        ),
        initial=("Idle",),
    )
    unreachable = [d.message for d in check_chart(chart) if d.code == "C401"]
    assert unreachable == ["state 'z' is unreachable from the initial state Idle"]


def test_a_fault_inherited_from_the_superstate_serves_a_monitored_child() -> None:
    """CiA 402 style: Fault leaves Operation from any substate, so monitored Enabled has one."""
    chart = Chart(
        "T",
        (
            State("Operation", kind=StateKind.COMPOUND, initial=("Enabled",)),
            State("Enabled", parent="Operation", controls=frozenset({ControlKind.MONITORING})),
            State("Faulted"),
        ),
        (
            Transition("Operation", ("Fault",), ("Faulted",)),
            Transition("Faulted", ("Enable",), ("Operation",)),
        ),
        initial=("Faulted",),
        events=(EventDef("Fault", EventKind.FAULT), EventDef("Enable", EventKind.COMMAND)),
        ignored=frozenset({("Faulted", "Fault"), ("Operation", "Enable")}),
    )
    assert [d.code for d in check_chart(chart) if d.code in ("C407", "C408")] == []


def test_unreachable_compound_is_reported_once() -> None:
    """An unreachable compound state is reported with its substates, not each of them."""
    chart = Chart(
        "T",
        (
            State("A"),
            State("P", kind=StateKind.COMPOUND),
            State("p1", parent="P"),
            State("p2", parent="P"),
        ),
        (Transition("A", ("tick",), ("A",)), Transition("p1", ("x",), ("p2",))),
        initial=("A",),
    )
    (diag,) = [d for d in check_chart(chart) if d.code == "C401"]
    assert diag.message.startswith("state 'P' (and its 2 substates)")


def test_codes_table_lists_every_code() -> None:
    """CODES documents exactly the C4 codes: the rules' (C401-C411, C413, C418-C421),
    verify's (C412) and check's file kinds (C415, C416)."""
    codes = [*(f"C4{i:02d}" for i in range(1, 14)), "C415", "C416", "C418", "C419"]
    codes += ["C420", "C421", "C422"]
    assert sorted(CODES) == codes


# -- the exclusive-guard decision procedure ------------------------------------------------

EXCLUSIVE = [
    ("x", "not x", True),
    ("x", "x", False),
    ("mode == 1", "mode == 2", True),
    ("mode == 1", "mode != 1", True),
    ("mode == 1", "mode == 1.0", False),
    ("x < 3", "x >= 3", True),
    ("x < 3", "x > 3", True),
    ("x <= 3", "x >= 3", False),
    ("3 > x", "x >= 3", True),
    ("not (x < 3)", "x < 3", True),
    ("previous == 'Moving'", "previous != 'Moving'", True),
    ("previous == 'Moving'", "previous == 'Blocked'", True),
    ("x in (1, 2)", "x == 3", True),
    ("x in (1, 2)", "x not in (1, 2, 3)", True),
    ("x in (1, 2)", "x == 2", False),
    ("a and b", "not a", True),
    ("a or b", "not a", False),
    ("a or b", "not a and not b", True),
    ("not (a or b)", "b", True),
    ("0 < x < 5", "x > 10", True),
    ("x >= 1 and x <= 1", "x != 1", True),
    ("x is None", "x is not None", True),
    ("x is None", "x == None", False),
    ("x == 1", "x == True", False),
    ("x < 'm'", "x == 3", False),
    ("a < b", "a >= b", True),
    ("a < b", "b > a", False),
    ("x == -1", "x == 1", True),
    ("In('Moving')", "not In('Moving')", True),
    ("speed > limit", "speed < limit", False),
    (None, None, False),
    (None, "x", False),
    (None, "x and not x", True),
    ("f(", "x", False),
]


@pytest.mark.parametrize(("first", "second", "exclusive"), EXCLUSIVE)
def test_guards_exclusive(first: str | None, second: str | None, exclusive: bool) -> None:
    """The decision procedure proves the simple exclusive cases and nothing more."""
    assert guards_exclusive(first, second) is exclusive
    assert guards_exclusive(second, first) is exclusive


_atoms = st.one_of(
    st.sampled_from(["b", "not b"]),
    st.builds(
        lambda name, op, c: f"{name} {op} {c}",
        st.sampled_from(["x", "y"]),
        st.sampled_from(["==", "!=", "<", "<=", ">", ">="]),
        st.integers(-2, 2),
    ),
    st.builds(
        lambda name, op, cs: f"{name} {op} {tuple(cs)!r}",
        st.sampled_from(["x", "y"]),
        st.sampled_from(["in", "not in"]),
        st.lists(st.integers(-2, 2), max_size=3),
    ),
)
_guards = st.recursive(
    _atoms,
    lambda inner: st.one_of(
        st.builds(lambda g: f"not ({g})", inner),
        st.builds(lambda a, b: f"({a}) and ({b})", inner, inner),
        st.builds(lambda a, b: f"({a}) or ({b})", inner, inner),
    ),
    max_leaves=6,
)
_ENVS = [{"x": x, "y": y, "b": b} for x in range(-3, 4) for y in range(-3, 4) for b in (0, 1)]


@settings(max_examples=300, deadline=None)
@given(_guards, _guards)
def test_exclusive_guards_never_both_hold(first: str, second: str) -> None:
    """Soundness: when the procedure says exclusive, no assignment satisfies both guards."""
    if guards_exclusive(first, second):
        for env in _ENVS:
            assert not (eval(first, {}, env) and eval(second, {}, env)), env  # test-made guards


# -- against the builder -------------------------------------------------------------------


def test_motor_checks_clean() -> None:
    """The paper's Motor builds and checks with no errors or warnings: Initialization in
    Blocked, taken only when previous == 'Moving', is listed as ignored otherwise (no C419,
    and no C406 since every row for it is guarded)."""
    found = [d for d in check_paths([str(MOTOR)]) if d.severity is not Severity.INFO]
    assert found == []


def test_ignoring_a_guarded_event_is_the_fallback_and_silences_c419(tmp_path: Path) -> None:
    """Without the ignore entry the Motor's Initialization gap is C419; with it, nothing."""
    text = MOTOR.read_text(encoding="utf-8")
    with_ignore = "[Movement completion, Initialization, Initialization completion"
    assert with_ignore in text
    bare = tmp_path / "motor.yaml"
    bare.write_text(
        text.replace(with_ignore, "[Movement completion, Initialization completion"),
        encoding="utf-8",
    )
    found = [d for d in check_paths([str(bare)]) if d.severity is not Severity.INFO]
    assert [(d.code, d.message.split(":")[0]) for d in found] == [("C419", "state 'Blocked'")]


def test_check_paths_includes_build_diagnostics(tmp_path: Path) -> None:
    """An undefined guard name is reported by the builder (X303) through check_paths."""
    bad = tmp_path / "motor.yaml"
    bad.write_text(
        MOTOR.read_text(encoding="utf-8").replace("previous == 'Moving'", "prevous == 'Moving'"),
        encoding="utf-8",
    )
    codes = {d.code for d in check_paths([str(bad)])}
    assert "X303" in codes


def test_check_paths_checks_each_built_chart(tmp_path: Path) -> None:
    """A Motor without its ignore column reports the missed transitions (C404)."""
    text = MOTOR.read_text(encoding="utf-8")
    lines = [ln for ln in text.splitlines() if not ln.strip().startswith("ignore:")]
    path = tmp_path / "motor.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    found = [d for d in check_paths([str(path)]) if d.severity is not Severity.INFO]
    assert {d.code for d in found} == {"C404", "C419"}  # C419: see test_motor_checks_clean
    assert {d.where.file for d in found} == {str(path)}


MOTOR_TABLES = MOTOR.read_text(encoding="utf-8").split("\nrecovery:\n")[0] + "\n"
MOVING = "  - {state: Moving, event: Error}\n"
RETURNING = "  - {state: Returning, redo: yes}\n"


@pytest.mark.parametrize(
    ("recovery", "found"),
    [
        ("recovery:\n" + MOVING + RETURNING, []),
        ("recovery:\n" + MOVING, [("J608", Severity.INFO)]),
        ("", [("J606", Severity.INFO), ("J608", Severity.INFO)]),
        (
            "recovery:\n  - {state: Flying, event: Error}\n" + RETURNING,
            [("J603", Severity.ERROR), ("J606", Severity.INFO)],
        ),
        (
            "recovery:\n  - {state: Moving, event: Movement}\n" + RETURNING,
            [("J604", Severity.ERROR)],
        ),
        ("recovery:\n" + MOVING + MOVING + RETURNING, [("J605", Severity.ERROR)]),
        ("recovery:\n" + MOVING + RETURNING + RETURNING, [("J605", Severity.ERROR)]),
        # Blocked is entered only by completions: no device call to issue again
        (
            "recovery:\n" + MOVING + RETURNING + "  - {state: Blocked, redo: yes}\n",
            [("J607", Severity.ERROR)],
        ),
    ],
)
def test_check_paths_checks_the_recovery_table(
    tmp_path: Path, recovery: str, found: list[tuple[str, Severity]]
) -> None:
    """J603-J605, J607 are errors; a state without a rule it needs (J606, J608) is info here."""
    path = tmp_path / "motor.yaml"
    path.write_text(MOTOR_TABLES + recovery, encoding="utf-8")
    diags = [d for d in check_paths([str(path)]) if d.code.startswith("J")]
    assert [(d.code, d.severity) for d in diags] == found


@pytest.mark.parametrize(("flags", "shown"), [((), False), (("-v",), True)])
def test_cli_check_shows_j606_only_when_verbose(
    tmp_path: Path, flags: tuple[str, ...], shown: bool
) -> None:
    """`statectl check` passes a Motor without a rule; -v shows the J606 info."""
    import io

    from statectl.channels.cli import main

    path = tmp_path / "motor.yaml"
    path.write_text(MOTOR_TABLES, encoding="utf-8")
    out = io.StringIO()
    assert main(["check", *flags, str(path)], out, io.StringIO()) == 0
    assert ("J606 info" in out.getvalue()) is shown


@pytest.mark.parametrize("code", sorted(CODES))
def test_docs_explain_every_code(code: str) -> None:
    """docs/check.md has a section for every code the checker reports."""
    docs = Path(__file__).resolve().parent.parent / "docs" / "check.md"
    assert f"## {code} — " in docs.read_text(encoding="utf-8")


@pytest.mark.parametrize("code", sorted(RECOVERY_CODES))
def test_docs_explain_every_recovery_code(code: str) -> None:
    """docs/check.md has a section for every code of the Recovery table's check."""
    docs = Path(__file__).resolve().parent.parent / "docs" / "check.md"
    assert f"## {code} — " in docs.read_text(encoding="utf-8")
