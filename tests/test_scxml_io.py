"""SCXML in and out of device tables, and the safe datamodel checked as a document loads."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from statectl.front.builder.build import build, chart_to_tables, load_chart, strip_origins
from statectl.front.tables import DeviceTables, EventRow, StateRow
from statectl.kernel.errors import DiagnosticError, Severity
from statectl.kernel.model import Chart, ControlKind, EventKind, StateKind
from statectl.out.scxml import read_scxml, write_scxml
from statectl.out.scxml.tables_io import export_file, import_file, import_text
from statectl.out.scxml.xmltree import SCXML_NS

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = [
    ROOT / "examples" / "motor" / "motor.yaml",
    ROOT / "examples" / "gantry" / "gantry.yaml",
]


def round_trip(chart: Chart) -> Chart:
    """Chart -> SCXML -> tables -> chart; fails if the import keeps it as SCXML."""
    tables, _, diagnostics = import_text(write_scxml(chart))
    assert tables is not None, [str(d) for d in diagnostics]
    built, diags = build(tables)
    assert built is not None, [str(d) for d in diags]
    return built


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_exported_and_imported_is_the_same_chart(path: Path) -> None:
    """Motor and gantry: export to SCXML, import back, build: the same chart, origins aside."""
    chart = load_chart(path)
    assert strip_origins(round_trip(chart)) == strip_origins(chart)


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_scxml_reader_reads_the_export_as_the_same_chart(path: Path) -> None:
    """The statectl namespace carries events, APIs, invokes, ignores and row order."""
    chart = load_chart(path)
    back, diagnostics = read_scxml(export_file(path))
    assert diagnostics == []
    assert back is not None
    assert strip_origins(back) == strip_origins(chart)


def test_import_file_writes_a_device_file(tmp_path: Path) -> None:
    """import_file converts a fitting document to YAML next to it, which loads as the chart."""
    doc = tmp_path / "gantry.scxml"
    doc.write_text(export_file(EXAMPLES[1]), encoding="utf-8")
    written, diagnostics = import_file(doc)
    assert diagnostics == []
    assert written == [tmp_path / "gantry.yaml"]
    assert strip_origins(load_chart(tmp_path / "gantry.yaml")) == strip_origins(
        load_chart(EXAMPLES[1])
    )


def test_import_file_honours_out_and_its_format(tmp_path: Path) -> None:
    """--out names the device file; its suffix picks the table format."""
    doc = tmp_path / "motor.scxml"
    doc.write_text(export_file(EXAMPLES[0]), encoding="utf-8")
    written, _ = import_file(doc, str(tmp_path / "m.md"))
    assert written == [tmp_path / "m.md"]
    assert strip_origins(load_chart(tmp_path / "m.md")) == strip_origins(load_chart(EXAMPLES[0]))


def doc(body: str, datamodel: str = "null", attrs: str = "") -> str:
    return f'<scxml xmlns="{SCXML_NS}" version="1.0" datamodel="{datamodel}"{attrs}>{body}</scxml>'


@pytest.mark.parametrize(
    ("body", "datamodel", "code"),
    [
        ('<state id="a"><onentry><log label="x"/></onentry></state>', "null", "B220"),
        ('<state id="a"><transition target="b"/></state><state id="b"/>', "null", "B221"),
        ('<state id="a"><transition event="e f" target="a"/></state>', "null", "B221"),
        ('<state id="a"><transition event="e"/></state>', "null", "B221"),
        ('<state id="a"><transition event="e" target="a" cond="x > 1"/></state>', "null", "B222"),
        ('<state id="a"><transition event="e" target="a"/></state>', "python", "B220"),
        ('<parallel id="p"><state id="r"/></parallel>', "null", "B223"),
        (
            '<datamodel><data id="x" expr="[1, 2]"/><data id="y" expr="x"/></datamodel>'
            '<state id="a"/>',
            "safe",
            "B220",
        ),
    ],
)
def test_import_keeps_what_tables_cannot_hold(body: str, datamodel: str, code: str) -> None:
    """A chart that does not fit stays SCXML, and an info diagnostic says why."""
    tables, chart, diagnostics = import_text(doc(body, datamodel))
    assert tables is None
    assert chart is not None
    assert code in [d.code for d in diagnostics]
    assert all(d.severity is Severity.INFO for d in diagnostics)


def test_import_file_keeps_the_document_text(tmp_path: Path) -> None:
    """When the chart does not fit, import_file writes nothing and returns the text."""
    path = tmp_path / "x.scxml"
    text = doc('<state id="a"><onentry><log label="x"/></onentry></state>')
    path.write_text(text, encoding="utf-8")
    kept, diagnostics = import_file(path)
    assert kept == text
    assert [d.code for d in diagnostics] == ["B220"]
    assert not (tmp_path / "x.yaml").exists()


def test_plain_scxml_that_fits_becomes_tables() -> None:
    """A hand-written null document: initial states become 'default', events commands."""
    text = doc(
        '<state id="idle"><transition event="go" target="run"/></state>'
        '<state id="run" initial="slow"><state id="fast"/><state id="slow">'
        '<transition event="up" target="fast"/></state>'
        '<transition event="stop" cond="In(\'fast\')" target="idle"/></state>',
        attrs=' initial="idle"',
    )
    tables, _, diagnostics = import_text(text)
    assert diagnostics == []
    assert tables is not None
    marked = [s.state for s in tables.states if ControlKind.DEFAULT in s.controls]
    assert marked == ["idle", "slow"]
    assert [(e.event, e.old, e.new, e.guard, e.kind) for e in tables.events] == [
        ("go", "idle", "run", "", EventKind.COMMAND),
        ("stop", "run", "idle", "In('fast')", EventKind.COMMAND),
        ("up", "slow", "fast", "", EventKind.COMMAND),
    ]


def test_import_of_a_bad_document_raises_every_diagnostic() -> None:
    """A document with errors is not imported: DiagnosticError carries the S6xx codes."""
    with pytest.raises(DiagnosticError) as caught:
        import_text(doc('<state id="a"><transition event="e" target="nowhere"/></state>'))
    assert [d.code for d in caught.value.diagnostics] == ["S605"]


def test_export_file_of_a_broken_device_raises(tmp_path: Path) -> None:
    """export_file refuses a device file that does not build, with its diagnostics."""
    path = tmp_path / "bad.yaml"
    path.write_text(
        "device: X\nstates:\n  - state: A\nevents:\n  - event: e\n    old: A\n    new: B\n",
        encoding="utf-8",
    )
    with pytest.raises(DiagnosticError) as caught:
        export_file(path)
    assert {d.code for d in caught.value.diagnostics} >= {"B201", "B202"}


def test_export_refuses_a_state_name_no_scxml_id_can_hold(tmp_path: Path) -> None:
    """A state 'Half open' is S624 at its row: as an id it would read as two states."""
    path = tmp_path / "valve.yaml"
    path.write_text(
        "device: Valve\nstates:\n  - {state: Shut, control: default}\n"
        "  - {state: Half open, control: event trigger required}\n"
        "events:\n  - {event: Open, old: Shut, new: Half open}\n",
        encoding="utf-8",
    )
    with pytest.raises(DiagnosticError) as caught:
        export_file(path)
    found = [(d.code, d.where.line) for d in caught.value.diagnostics]
    assert found == [("S624", 4)]
    assert "'Half open'" in caught.value.diagnostics[0].message


# --- random tables: export then import is the identity ------------------------------------

SIMPLE = st.text("abcdefgh", min_size=1, max_size=4)
GUARDS = ["", "limit > 1", "previous == 'x'", "limit > 0 and _event is not None"]


KINDS = [
    None,
    None,
    None,
    StateKind.PARALLEL,
    StateKind.FINAL,
    StateKind.HISTORY_SHALLOW,
    StateKind.HISTORY_DEEP,
]


@st.composite
def hierarchical_tables(draw: st.DrawFn) -> DeviceTables:
    """Tables that build: a forest of states (some parallel, final or history), one default
    per level, event rows that leave neither a final nor a history state."""
    names = draw(st.lists(SIMPLE, min_size=1, max_size=7, unique=True))
    parent: dict[str, str] = {}
    kind: dict[str, StateKind | None] = {}
    for i, name in enumerate(names):
        holders = [n for n in names[:i] if kind[n] in (None, StateKind.PARALLEL)]
        parent[name] = draw(st.sampled_from(["", *holders])) if holders else ""
        kind[name] = draw(st.sampled_from(KINDS))
    kids = {n: [c for c in names if parent[c] == n] for n in names}
    for n in names:
        k = kind[n]
        if (
            (k is StateKind.PARALLEL and len(kids[n]) < 2)
            or (k is not None and k is not StateKind.PARALLEL and kids[n])
            or (k is not None and k.is_history and not parent[n])
        ):
            kind[n] = None
    history = {n for n in names if kind[n] is not None and kind[n].is_history}  # type: ignore[union-attr]
    defaults = {next(n for n in names if not parent[n])}
    for n in names:
        entries = [c for c in kids[n] if c not in history]
        if entries and kind[n] is None and draw(st.booleans()):
            defaults.add(draw(st.sampled_from(entries)))
    events = draw(st.lists(SIMPLE.map(str.upper), min_size=1, max_size=4, unique=True))
    states = []
    for n in names:
        controls: list[ControlKind] = (
            []
            if n in history
            else draw(
                st.lists(
                    st.sampled_from([ControlKind.MONITORING, ControlKind.TRIGGER]), unique=True
                )
            )
        )
        states.append(
            StateRow(
                "Dev",
                draw(st.sampled_from(["", "Run()"])),
                n,
                (ControlKind.DEFAULT, *controls) if n in defaults else tuple(controls),
                draw(st.sampled_from(["", "some text"])),
                tuple(draw(st.lists(st.sampled_from(events), unique=True, max_size=2))),
                parent[n],
                type=kind[n],
            )
        )
    meta = {
        e: (draw(st.sampled_from(list(EventKind))), draw(st.sampled_from(["", "Run", "Stop"])))
        for e in events
    }
    sources = [n for n in names if n not in history and kind[n] is not StateKind.FINAL]
    rows = []
    for _ in range(draw(st.integers(1 if sources else 0, 8 if sources else 0))):
        event = draw(st.sampled_from(events))
        event_kind, api = meta[event]
        rows.append(
            EventRow(
                event,
                draw(st.sampled_from(["", "why"])),
                draw(st.sampled_from(GUARDS)),
                draw(st.sampled_from(sources)),
                draw(st.sampled_from(names)),
                event_kind,
                api,
            )
        )
    return DeviceTables("Dev", tuple(states), tuple(rows), (("limit", 2),))


@settings(max_examples=200, deadline=None)
@given(hierarchical_tables())
def test_random_tables_export_and_import_to_the_same_chart(tables: DeviceTables) -> None:
    """Any tables that build: their chart through SCXML and back to tables is the same chart."""
    chart, _ = build(tables)
    assume(chart is not None)
    assert chart is not None
    assert strip_origins(round_trip(chart)) == strip_origins(chart)


def test_strip_origins_ignores_only_locations() -> None:
    """Two builds of the Motor from different files compare equal once stripped, not before."""
    yaml_chart = load_chart(EXAMPLES[0])
    csv_chart = load_chart(ROOT / "examples" / "motor" / "motor.states.csv")
    assert yaml_chart != csv_chart
    assert strip_origins(yaml_chart) == strip_origins(csv_chart)


def test_chart_to_tables_of_the_motor_is_the_motor_rows() -> None:
    """The inverse of build gives the Motor's rows back (merged rows aside)."""
    chart = load_chart(EXAMPLES[0])
    tables, diagnostics = chart_to_tables(chart)
    assert diagnostics == []
    assert tables is not None
    assert [s.state for s in tables.states] == ["Blocked", "Moving", "Returning"]
    assert [s.api for s in tables.states] == [
        "Movement()",
        "Movement()",
        "Initialization(), Error()",
    ]


# --- the safe datamodel, checked at load time ---------------------------------------------

SAFE_DATA = '<datamodel><data id="x" expr="1"/></datamodel>\n'


@pytest.mark.parametrize(
    ("body", "codes"),
    [
        (
            '<state id="s">\n<transition event="e" cond="__import__(\'os\')" target="s"/></state>',
            [("X302", 3), ("X302", 3)],  # a private name, and a call to it
        ),
        ('<state id="s">\n<transition event="e" cond="x >" target="s"/></state>', [("X301", 3)]),
        ('<state id="s">\n<transition event="e" cond="y == 1" target="s"/></state>', [("X303", 3)]),
        (
            '<state id="s"><onentry>\n<assign location="x.real" expr="2"/></onentry></state>',
            [("X302", 3)],
        ),
        (
            '<state id="s"><onentry>\n<assign location="z" expr="2"/></onentry></state>',
            [("X303", 3)],
        ),
        ('<state id="s"><onentry>\n<log expr="x.__class__"/></onentry></state>', [("X302", 3)]),
        (
            '<state id="s"><onentry>\n<send eventexpr="open(\'f\')"/></onentry></state>',
            [("X302", 3)],
        ),
        (
            '<state id="s"><onentry>\n<assign location="_sessionid" expr="1"/></onentry></state>',
            [("X302", 3)],
        ),
        (
            '<state id="s"><onentry>\n<foreach array="[1, 2]" item="i">\n<assign location="x" '
            'expr="i + q"/></foreach></onentry></state>',
            [("X303", 4)],
        ),
        ('<state id="s"><onentry><script>\nx = 1</script></onentry></state>', [("X302", 2)]),
        (
            '<final id="f"><donedata>\n<param name="p" expr="x ** 99"/></donedata></final>',
            [("X302", 3), ("X302", 3)],  # '**' refused, and its operator node
        ),
    ],
)
def test_safe_documents_are_checked_when_they_load(body: str, codes: list[tuple[str, int]]) -> None:
    """What escapes the safe language is an X30x error from the reader, with its line."""
    chart, diagnostics = read_scxml(doc(SAFE_DATA + body, "safe"))
    assert chart is None
    assert [(d.code, d.where.line) for d in diagnostics] == codes


def test_safe_document_within_the_language_loads() -> None:
    """Declared names, In(), _event, foreach variables and whitelisted calls are fine."""
    body = (
        '<state id="s"><onentry><foreach array="[1, 2]" item="i" index="n">'
        '<assign location="x" expr="max(i, n, x)"/></foreach>'
        '<send event="go" delayexpr="str(x) + \'s\'"/></onentry>'
        '<transition event="go" cond="In(\'s\') and _event.name == \'go\'" target="s"/></state>'
    )
    chart, diagnostics = read_scxml(doc(SAFE_DATA + body, "safe"))
    assert diagnostics == []
    assert chart is not None


def test_python_datamodel_is_not_checked() -> None:
    """datamodel='python' is explicit trust: the reader leaves its expressions alone."""
    body = '<state id="s"><onentry><script>import os</script></onentry></state>'
    chart, diagnostics = read_scxml(doc(body, "python"))
    assert chart is not None
    assert diagnostics == []
