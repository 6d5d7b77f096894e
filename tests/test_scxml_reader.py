"""Reading SCXML: the chart model it builds, and diagnostics for malformed documents."""

from __future__ import annotations

import pytest

from statectl.kernel.model import Block, If, Raise, Send, StateKind
from statectl.out.scxml import read_scxml
from statectl.out.scxml.writer import write_scxml
from statectl.out.scxml.xmltree import SCXML_NS

HEAD = f'<scxml xmlns="{SCXML_NS}" version="1.0" datamodel="python"'


@pytest.mark.parametrize(
    ("text", "code", "line"),
    [
        (f"{HEAD}>\n<state id='a'>\n</scxml>", "S601", 3),
        ('<foo xmlns="urn:x"/>', "S602", 1),
        (f"{HEAD}>\n<state id='a'><onentry><raise/></onentry></state></scxml>", "S603", 2),
        (f"{HEAD}>\n<state id='a'/>\n<state id='a'/></scxml>", "S604", 3),
        (f"{HEAD}>\n<state id='a'>\n<transition target='nowhere'/></state></scxml>", "S605", 3),
        (f"{HEAD} initial='zz'><state id='a'/></scxml>", "S605", 1),
        (f"{HEAD}>\n<state id='a' initial='q'/></scxml>", "S605", 2),
        (f"{HEAD}><script src='file:/no/such/file.py'/></scxml>", "S607", 1),
    ],
)
def test_malformed_documents_get_diagnostics(text: str, code: str, line: int) -> None:
    """Each malformed document is refused with its stable code and the offending line."""
    chart, diagnostics = read_scxml(text, "doc.scxml")
    assert chart is None
    assert (diagnostics[0].code, diagnostics[0].where.line) == (code, line)


def test_every_problem_is_reported() -> None:
    """Reading goes on after the first problem: two bad targets give two diagnostics."""
    text = f"{HEAD}><state id='a'><transition target='x'/><transition target='y'/></state></scxml>"
    _, diagnostics = read_scxml(text)
    assert [d.code for d in diagnostics] == ["S605", "S605"]


def test_unknown_executable_content_is_a_warning() -> None:
    """An unknown element in executable content is skipped with a warning, not refused."""
    chart, diagnostics = read_scxml(
        f"{HEAD}><state id='a'><onentry><blink/></onentry></state></scxml>"
    )
    assert chart is not None
    assert [(d.code, d.severity.value) for d in diagnostics] == [("S606", "warning")]


@pytest.mark.parametrize(
    ("body", "kinds"),
    [
        ("<state id='a'/>", {"a": StateKind.ATOMIC}),
        ("<state id='a'><state id='b'/></state>", {"a": StateKind.COMPOUND, "b": StateKind.ATOMIC}),
        (
            "<parallel id='p'><state id='x'/></parallel>",
            {"p": StateKind.PARALLEL, "x": StateKind.ATOMIC},
        ),
        (
            "<state id='a'><history id='h' type='deep'/><final id='f'/></state>",
            {"a": StateKind.COMPOUND, "h": StateKind.HISTORY_DEEP, "f": StateKind.FINAL},
        ),
    ],
)
def test_state_kinds(body: str, kinds: dict[str, StateKind]) -> None:
    """Element names and children decide the state kind."""
    chart, _ = read_scxml(f"{HEAD}>{body}</scxml>")
    assert chart is not None
    assert {s.name: s.kind for s in chart.states} == kinds


def test_executable_content_and_locations() -> None:
    """Content becomes model actions; several handlers stay separate blocks; lines are kept."""
    text = (
        f"{HEAD}>\n<state id='a'>\n<onentry><raise event='x'/></onentry>\n"
        "<onentry><if cond='1'><send event='y' delay='1s'/><else/><raise event='z'/></if>"
        "</onentry>\n"
        "<transition event='e f' cond='True' target='a' type='internal'/>\n</state></scxml>"
    )
    chart, _ = read_scxml(text, "doc.scxml")
    assert chart is not None
    state = chart.state("a")
    first, second = state.on_entry
    assert isinstance(first, Block) and first.actions == (Raise("x"),)
    assert isinstance(second, Block) and isinstance(second.actions[0], If)
    (cond, then), (other, otherwise) = second.actions[0].branches
    assert (cond, other, otherwise) == ("1", None, (Raise("z"),))
    assert isinstance(then[0], Send) and then[0].delay == "1s"
    (t,) = chart.transitions
    assert (t.events, t.internal, t.origin.line, state.origin.line) == (("e", "f"), True, 5, 2)


def test_written_document_reads_back_the_same() -> None:
    """write_scxml then read_scxml gives the same states and transitions."""
    text = (
        f"{HEAD} name='m'><datamodel><data id='n' expr='1'/></datamodel>"
        "<state id='a' initial='b'><onexit><log label='l' expr='n'/></onexit>"
        "<state id='b'><transition event='go' cond='n &lt; 2' target='f'>"
        "<assign location='n' expr='2'/>"
        "</transition></state><history id='h'><transition target='b'/></history></state>"
        "<final id='f'><donedata><param name='p' expr='n'/></donedata></final></scxml>"
    )
    chart, _ = read_scxml(text)
    assert chart is not None
    again, diagnostics = read_scxml(write_scxml(chart))
    assert again is not None, diagnostics
    assert write_scxml(again) == write_scxml(chart)
    assert [s.name for s in again.states] == [s.name for s in chart.states]
    assert [(t.source, t.events, t.guard) for t in again.transitions] == [
        (t.source, t.events, t.guard) for t in chart.transitions
    ]
