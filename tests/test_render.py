"""Diagrams: one neutral model, five formats, safe ids and escaped labels in each syntax."""

from __future__ import annotations

import html
import re
import shutil
from pathlib import Path

import pytest

from statectl.kernel.errors import StatectlError
from statectl.kernel.model import (
    Chart,
    ControlKind,
    EventDef,
    EventKind,
    State,
    StateKind,
    Transition,
)
from statectl.out.render import FORMATS, from_chart, render
from statectl.out.render import dot as dot_writer
from statectl.out.render import mermaid as mermaid_writer
from statectl.out.render.diagram import NodeKind, edge_label, safe_id
from statectl.out.render.svg import MISSING_DOT

MOTOR = Path(__file__).resolve().parent.parent / "examples" / "motor" / "motor.yaml"
HAS_DOT = shutil.which("dot") is not None
NEEDS_DOT = pytest.mark.skipif(not HAS_DOT, reason="Graphviz 'dot' is not installed")


def _formats() -> list[object]:
    return [pytest.param(f, marks=NEEDS_DOT) if f == "svg" else f for f in FORMATS]


def _visible(fmt: str, text: str) -> str:
    """The text as a reader of the format sees it (entities decoded)."""
    if fmt == "mermaid" or fmt == "md":
        return re.sub(r"#(\d+);", lambda m: chr(int(m.group(1))), text)
    if fmt == "svg":
        return html.unescape(text)
    return text


@pytest.mark.parametrize("fmt", _formats())
def test_every_format_shows_every_motor_state(motor: Chart, fmt: str) -> None:
    """Each format names each of the Motor's states."""
    text = _visible(fmt, render(motor, fmt))
    for state in ("Blocked", "Moving", "Returning"):
        assert state in text


@pytest.mark.parametrize("fmt", _formats())
def test_every_format_shows_every_motor_transition_label(motor: Chart, fmt: str) -> None:
    """Each format carries each transition's ``event [condition]`` label."""
    text = _visible(fmt, render(motor, fmt))
    for t in motor.transitions:
        assert edge_label(t) in text


MOTOR_LABELS = [
    ("Movement", "Movement [request from external inputs or sensors]"),
    ("Initialization", "Initialization [the previous state was Moving]"),
    ("Error", "Error [error during Moving]"),
]


@pytest.mark.parametrize(("event", "label"), MOTOR_LABELS)
def test_edge_label_is_event_and_condition(motor: Chart, event: str, label: str) -> None:
    """The paper's transition label is ``event [condition]``."""
    (t,) = [t for t in motor.transitions if t.events == (event,)]
    assert edge_label(t) == label


def test_motor_diagram_model(motor: Chart) -> None:
    """The Motor diagram: three states, six edges, Blocked initial, a note on Moving."""
    d = from_chart(motor)
    assert [n.id for n in d.nodes] == ["Blocked", "Moving", "Returning"]
    assert len(d.edges) == 6
    assert d.initial == ("Blocked",)
    assert [(n.node, n.text) for n in d.notes] == [("Moving", "monitor raises Error")]


ACTIVE_MARKS = [
    ("mermaid", "class Moving active"),
    ("dot", '"Moving" [label="Moving", style="rounded,filled,bold"'),
    ("plantuml", 'state "Moving" as Moving #FFD54F'),
]


@pytest.mark.parametrize(("fmt", "mark"), ACTIVE_MARKS)
def test_active_state_is_highlighted(motor: Chart, fmt: str, mark: str) -> None:
    """An active state is highlighted, and nothing is when no state is active."""
    assert mark in render(motor, fmt, active=frozenset({"Moving"}))
    assert mark not in render(motor, fmt)


def test_unknown_active_state_is_refused(motor: Chart) -> None:
    """Highlighting a state the chart does not have is misuse, named in the error."""
    with pytest.raises(StatectlError, match="'Flying' are not states of 'Motor'"):
        render(motor, "mermaid", active=frozenset({"Flying"}))


def test_unknown_format_lists_formats(motor: Chart) -> None:
    """An unknown format names the available ones."""
    with pytest.raises(StatectlError, match="Available formats: mermaid, dot, plantuml, svg, md"):
        render(motor, "png")


def test_markdown_page_has_tables_diagram_and_invokes(motor: Chart) -> None:
    """The Markdown page holds both definition tables, a mermaid block and the invoke table."""
    page = render(motor, "md")
    for needle in (
        "## State Definition",
        "| Motor / Movement() | Blocked | default |",
        "## Event Definition",
        "| Initialization | the previous state was Moving | previous == 'Moving' | Blocked "
        "| Returning | command | Initialization |",
        "```mermaid\n%% Motor\nstateDiagram-v2\n",
        "## Invoke table",
        "| 0 | Moving | Movement() | Movement, Movement completion |",
        "| 2 | Error | Error() | Error, Error completion |",
    ):
        assert needle in page


# -- safe ids and escaping -----------------------------------------------------------------

SAFE_IDS = [
    ("Blocked", (), "Blocked"),
    ("Movement completion", (), "Movement_completion"),
    ("a-1", (), "a_1"),
    ("end", (), "s_end"),
    ("Node", (), "s_Node"),
    ("1st", (), "s_1st"),
    ("ünïcode", (), "n_code"),
    ("???", (), "s_state"),
    ("a b", ("a_b",), "a_b_2"),
    ("a b", ("a_b", "a_b_2"), "a_b_3"),
]


@pytest.mark.parametrize(("name", "taken", "expected"), SAFE_IDS)
def test_safe_id(name: str, taken: tuple[str, ...], expected: str) -> None:
    """Ids are ASCII identifiers, never a keyword, unique among those taken."""
    assert safe_id(name, taken) == expected


AWKWARD = ('Say "hi"', "end", "x:y;z", "100% {sure} #1", "a<b>", "back\\slash")


def _awkward_chart() -> Chart:
    states = tuple(State(n) for n in AWKWARD)
    transitions = tuple(
        Transition(a, (f"go {a}",), (b,), guard=f"v == {a!r}")
        for a, b in zip(AWKWARD, AWKWARD[1:] + AWKWARD[:1], strict=True)
    )
    return Chart('Odd: "name"', states, transitions, initial=(AWKWARD[0],))


def test_awkward_names_get_distinct_safe_ids() -> None:
    """Every awkward name maps to its own identifier."""
    ids = [n.id for n in from_chart(_awkward_chart()).nodes]
    assert len(set(ids)) == len(ids)
    assert all(re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", i) for i in ids)


def test_mermaid_escapes_what_its_grammar_parses() -> None:
    """Mermaid labels carry no raw ``: ; " # { }`` after the writer, and decode back."""
    text = render(_awkward_chart(), "mermaid")
    for line in text.splitlines()[2:]:
        body = re.sub(r"#\d+;", "", line.split(" : ", 1)[1] if " : " in line else line)
        if line.strip().startswith('state "'):
            body = body.split('"')[1]
        assert not set(body) & set(':;"#{}'), line
    for name in AWKWARD:
        assert _visible("mermaid", mermaid_writer.escape(name)) == name


def test_markdown_tables_hold_no_raw_html_from_names() -> None:
    """A name like '<script>' is text in the md page's tables, not a tag a viewer runs."""
    states = (State("<script>alert(1)</script>"), State("a < b"))
    transitions = (Transition(states[0].name, ("<img src=x>",), (states[1].name,)),)
    page = render(Chart("<b>D</b>", states, transitions, initial=(states[0].name,)), "md")
    assert (
        re.search(r"<(?=[A-Za-z/!?])", page.split("```mermaid")[0] + page.split("```")[-1]) is None
    )
    assert "&lt;script>alert(1)&lt;/script>" in page and "a < b" in page


def test_plantuml_quoted_labels_have_no_inner_quote() -> None:
    """PlantUML has no escape inside a quoted label, so a double quote becomes ``'``."""
    text = render(_awkward_chart(), "plantuml")
    assert "state \"Say 'hi'\" as Say_hi" in text
    for line in text.splitlines():
        if line.startswith('state "'):
            assert line.count('"') == 2


DOT_QUOTES = [
    ("plain", '"plain"'),
    ('Say "hi"', '"Say \\"hi\\""'),
    ("back\\slash", '"back\\\\slash"'),
    ("two\nlines", '"two\\nlines"'),
]


@pytest.mark.parametrize(("text", "quoted"), DOT_QUOTES)
def test_dot_quote(text: str, quoted: str) -> None:
    """DOT strings escape backslash and quote and keep line breaks as ``\\n``."""
    assert dot_writer.quote(text) == quoted


@NEEDS_DOT
def test_awkward_names_survive_graphviz() -> None:
    """Graphviz parses the DOT of awkward names and draws each name unchanged."""
    svg = html.unescape(render(_awkward_chart(), "svg"))
    for name in AWKWARD:
        assert name in svg


# -- nesting ---------------------------------------------------------------------------------


def _nested_chart() -> Chart:
    return Chart(
        "Cell",
        (
            State("Idle"),
            State("Run", kind=StateKind.PARALLEL),
            State("Arm", kind=StateKind.COMPOUND, parent="Run", initial=("a1",)),
            State("a1", parent="Arm", controls=frozenset({ControlKind.MONITORING})),
            State("a2", parent="Arm"),
            State("Hist", kind=StateKind.HISTORY_DEEP, parent="Arm"),
            State("Belt", kind=StateKind.COMPOUND, parent="Run"),
            State("b1", parent="Belt"),
            State("Done", kind=StateKind.FINAL),
        ),
        (
            Transition("Idle", ("start",), ("Run",)),
            Transition("a1", ("step",), ("a2",)),
            Transition("a1", ("jam",), ("Done",)),
            Transition("Run", ("stop",), ("Idle",)),
            Transition("b1", ("tick",), ()),
        ),
        initial=("Idle",),
        events=(EventDef("jam", EventKind.FAULT),),
    )


def test_diagram_model_keeps_nesting() -> None:
    """Nodes keep their parent, kind and default children."""
    d = from_chart(_nested_chart())
    assert {n.id: n.parent for n in d.nodes}["a1"] == "Arm"
    assert d.node("Run").kind is NodeKind.PARALLEL
    assert d.node("Arm").initial == ("a1",)
    assert d.node("Belt").initial == ("b1",)
    assert d.node("Hist").label == "H*"
    assert [e.label for e in d.edges if e.internal] == ["tick (internal)"]


NESTED_MARKS = [
    ("mermaid", ["state Run {", "state Arm {", "        --", "[*] --> a1", "Done --> [*]"]),
    ("plantuml", ['state "Run" as Run {', "  --", "<<history*>>", "Done --> [*]"]),
    ("dot", ['subgraph "cluster_Run"', 'lhead="cluster_Run"', 'ltail="cluster_Run"',
             "peripheries=2"]),
]  # fmt: skip


@pytest.mark.parametrize(("fmt", "marks"), NESTED_MARKS)
def test_nested_states_render_nested(fmt: str, marks: list[str]) -> None:
    """Compound and parallel states render as nested blocks with regions and markers."""
    text = render(_nested_chart(), fmt)
    for mark in marks:
        assert mark in text


def test_mermaid_edge_sits_in_innermost_block() -> None:
    """An edge between two substates is written inside their compound state's block."""
    lines = render(_nested_chart(), "mermaid").splitlines()
    inner = lines.index("        state Arm {")
    close = lines.index("        }", inner)
    assert "            a1 --> a2 : step" in lines[inner:close]


@NEEDS_DOT
def test_nested_dot_is_valid_graphviz() -> None:
    """Graphviz lays out the nested chart without complaint."""
    assert "<svg" in render(_nested_chart(), "svg")


# -- svg without Graphviz --------------------------------------------------------------------


def test_svg_without_dot_says_how_to_install(motor: Chart, monkeypatch: pytest.MonkeyPatch) -> None:
    """With no ``dot`` on PATH, svg raises a StatectlError naming the install commands."""
    monkeypatch.setenv("PATH", "")
    with pytest.raises(StatectlError) as info:
        render(motor, "svg")
    assert str(info.value) == MISSING_DOT
    assert "apt-get install graphviz" in MISSING_DOT and "brew install graphviz" in MISSING_DOT


# -- docs that run ---------------------------------------------------------------------------

DOCS = Path(__file__).resolve().parent.parent / "docs" / "render.md"


@pytest.mark.parametrize("fmt", ["mermaid", "dot", "plantuml"])
def test_docs_show_the_current_motor_output(motor: Chart, fmt: str) -> None:
    """docs/render.md shows exactly what each text format renders for the Motor."""
    text = DOCS.read_text(encoding="utf-8")
    assert f"```{fmt}\n{render(motor, fmt)}```" in text
