"""Data that changes: the Event Definition table's assign column, from tables to exports."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest

from statectl.channels.cli.run import run
from statectl.front.builder.build import build, chart_to_tables, strip_origins
from statectl.front.tables.yaml_io import read_yaml
from statectl.kernel.errors import Diagnostic, Severity
from statectl.kernel.model import Assign, Chart, Notify
from statectl.out.scxml import read_scxml, write_scxml
from statectl.run.runtime import Subject
from statectl.run.runtime.clock import SimClock
from statectl.run.runtime.eventdata import AssignError
from support import Recorder

INDEXER = """\
device: Indexer
data:
  indexed: 0
  limit: 3
  last: ''
states:
  - state: Idle
    control: default
  - state: Indexing
    control: event trigger required
events:
  - event: Index
    guard: indexed < limit
    old: Idle
    new: Indexing
    api: Index
    data: {{part: str}}
    assign: {assign}
  - event: Index completion
    old: Indexing
    new: Idle
    kind: completion
    api: Index
"""

GOOD = '"indexed = indexed + 1; last = _event.data.part"'


def _build(assign: str = GOOD) -> tuple[Chart | None, list[Diagnostic]]:
    tables, diags = read_yaml(INDEXER.format(assign=assign), "indexer.yaml")
    assert tables is not None, diags
    chart, more = build(tables)
    return chart, [*diags, *more]


def _indexer(assign: str = GOOD) -> Chart:
    chart, diags = _build(assign)
    assert chart is not None, diags
    return chart


def _cycle(subject: Subject, part: str) -> None:
    subject.dispatch("Index", {"part": part})
    subject.dispatch("Index completion")


def test_assignments_become_actions_before_the_notification() -> None:
    """An assign cell becomes Assign actions on the row's transition, before its Notify."""
    chart = _indexer()
    actions = chart.transitions[0].actions
    assert [type(a) for a in actions] == [Assign, Assign, Notify]
    assert [(a.location, a.expr) for a in actions if isinstance(a, Assign)] == [
        ("indexed", "indexed + 1"),
        ("last", "_event.data.part"),
    ]


def test_the_runtime_performs_assignments_and_guards_see_them() -> None:
    """A counter guard stops the fourth Index: data changes as the table says."""
    subject = Subject(_indexer(), clock=SimClock())
    seen = Recorder()
    subject.attach(seen)
    subject.start()
    for part in ("a", "b", "c", "d"):
        _cycle(subject, part)
    assert subject.data["indexed"] == 3
    assert subject.data["last"] == "c"
    assert len(seen.seen) == 3  # the fourth was refused by the guard: no device call


def test_assignments_read_the_data_before_the_step() -> None:
    """Assignments of one row all read the data as it was before the step."""
    subject = Subject(_indexer('"indexed = limit; limit = indexed"'), clock=SimClock())
    subject.start()
    subject.dispatch("Index", {"part": "x"})
    assert (subject.data["indexed"], subject.data["limit"]) == (3, 0)


def test_a_failing_assignment_refuses_the_whole_step() -> None:
    """An assignment that raises changes nothing: no state, no data, no device call."""
    subject = Subject(_indexer('"indexed = indexed + 1; last = 1 // 0"'), clock=SimClock())
    seen = Recorder()
    subject.attach(seen)
    subject.start()
    with pytest.raises(AssignError) as caught:
        subject.dispatch("Index", {"part": "x"})
    assert "indexer.yaml:12" in str(caught.value)
    assert "ZeroDivisionError" in str(caught.value)
    assert subject.configuration == {"Idle"}
    assert subject.data["indexed"] == 0
    assert seen.seen == []


@pytest.mark.parametrize(
    ("assign", "code", "word"),
    [
        ('"count = 1"', "B234", "not a data item"),
        ('"indexed = indexed + nothing"', "X303", "nothing"),
        ('"indexed = __import__"', "X302", "private"),
        ('"last = _event.data.bart"', "B232", "bart"),
        ('"last = event.part"', "B231", "_event.data.part"),
    ],
)
def test_assignments_are_checked_at_load(assign: str, code: str, word: str) -> None:
    """Targets must be data items; expressions are safe and read known names only."""
    chart, diags = _build(assign)
    errors = [d for d in diags if d.severity is Severity.ERROR]
    assert chart is None
    assert [d.code for d in errors] == [code], errors
    assert word in errors[0].message + errors[0].hint
    assert errors[0].where.line == 12


@pytest.mark.parametrize(
    ("assign", "word"),
    [
        ('"indexed + 1"', "not 'name = expression'"),
        ('"a.b = 1"', "not 'name = expression'"),
        ('"indexed = 1; indexed = 2"', "twice"),
        ('"indexed = "', "does not parse"),
    ],
)
def test_a_malformed_assign_cell_is_t123(assign: str, word: str) -> None:
    """An assign cell that is not 'name = expression; ...' is T123."""
    _, diags = read_yaml(INDEXER.format(assign=assign), "indexer.yaml")
    assert [d.code for d in diags] == ["T123"]
    assert word in diags[0].message


def test_a_step_with_assignments_is_never_a_plan() -> None:
    """The plan fast path never skips assignments (a second, memoised step assigns too)."""
    subject = Subject(_indexer('"indexed = indexed + 1"'), clock=SimClock())
    subject.start()
    for _ in range(2):
        _cycle(subject, "p")
    assert subject.data["indexed"] == 2


def test_scxml_export_writes_assign_and_import_gives_the_tables_back() -> None:
    """Export writes <assign> and the declared fields; import builds the same chart."""
    chart = _indexer()
    text = write_scxml(chart)
    assert '<assign location="indexed" expr="indexed + 1"/>' in text
    assert 'data="part: str"' in text
    again, diags = read_scxml(text, "indexer.scxml")
    assert again is not None and not diags
    tables, why = chart_to_tables(again)
    assert tables is not None, why
    assert tables.events[0].assign == (("indexed", "indexed + 1"), ("last", "_event.data.part"))
    rebuilt, problems = build(tables)
    assert rebuilt is not None, problems
    assert strip_origins(rebuilt) == strip_origins(chart)


def test_the_exported_document_runs_the_assignments_in_a_session() -> None:
    """Any SCXML processor performs the exported <assign>: statectl's session does."""
    from statectl.kernel.semantics import Event
    from statectl.out.scxml import Scheduler, Session, SimulatedClock

    chart = _indexer('"indexed = indexed + 1"')
    doc, diags = read_scxml(write_scxml(chart), "indexer.scxml")
    assert doc is not None, diags
    scheduler = Scheduler(SimulatedClock())
    session = Session(doc, scheduler)
    for _ in range(4):
        session.post(Event("Index", {"part": "p"}, type="external"))
        session.post(Event("Index completion", type="external"))
    scheduler.run_ready()
    assert session.datamodel.values["indexed"] == 3


@pytest.mark.parametrize(
    ("line", "code", "word"),
    [
        ("Index {part: a}\n", 0, ""),
        ("Index {prt: a}\n", 1, "no data field 'prt'"),
        ("Index {part: 3}\n", 1, "must be str"),
    ],
)
def test_run_refuses_a_stdin_line_with_data_the_event_does_not_declare(
    tmp_path: Path, line: str, code: int, word: str
) -> None:
    """statectl run reports a line whose data does not fit the declaration, and exits 1."""
    path = tmp_path / "indexer.yaml"
    path.write_text(INDEXER.format(assign=GOOD))
    out, err = io.StringIO(), io.StringIO()
    assert run(str(path), events=io.StringIO(line), out=out, err=err) == code, err.getvalue()
    assert word in err.getvalue()
    if code:
        assert "line 1:" in err.getvalue()


# --- generated C++ -------------------------------------------------------------------------

COUNTER = """\
device: Counter
data:
  count: 0
  limit: 3
  other: 10
states:
  - {state: Idle, control: default}
  - {state: Busy, control: event trigger required}
events:
  - {event: Go, guard: count < limit, old: Idle, new: Busy, api: Go, assign: "count = count + 1"}
  - {event: Go completion, old: Busy, new: Idle, kind: completion, api: Go}
  - {event: Swap, old: Idle, new: Idle, assign: "count = other; other = count"}
"""


def _counter(assign_swap: str = "count = other; other = count") -> Chart:
    text = COUNTER.replace("count = other; other = count", assign_swap)
    tables, diags = read_yaml(text, "counter.yaml")
    assert tables is not None, diags
    chart, more = build(tables)
    assert chart is not None, more
    return chart


def test_codegen_turns_assignments_into_assign_effects() -> None:
    """Each transition's assignments become one ASSIGN effect, first in its step."""
    from statectl.out.codegen.flat import EffectKind, FlatStep
    from statectl.out.codegen.flatten import flatten

    flat, diags = flatten(_counter())
    assert flat is not None and not diags, diags
    assert [g.source for g in flat.assignments] == [
        "count = count + 1",
        "count = other; other = count",
    ]
    assert flat.assignments[1].stores == (("count", "c.other"), ("other", "c.count"))
    go = flat.dispatch[0][flat.events.index("Go")]
    leaves = [go] if isinstance(go, FlatStep) else [go.if_true, go.if_false]
    taken = next(o for o in leaves if isinstance(o, FlatStep) and o.handled)
    assert taken.effects[0].kind is EffectKind.ASSIGN


@pytest.mark.parametrize(
    ("swap", "word"),
    [
        ("count = count / 2", "does not translate"),
        ("count = _event.data.n", "_event"),
        ("count = 1 if previous == 'Busy' else 0", "previous"),
    ],
)
def test_codegen_refuses_an_assignment_it_cannot_perform(swap: str, word: str) -> None:
    """An assignment C++ cannot perform is G713 at the row, not dropped."""
    from statectl.out.codegen.flatten import flatten

    _, diags = flatten(_counter(swap))
    g713 = [d for d in diags if d.code == "G713"]
    assert g713, diags
    assert word in g713[0].message
    assert g713[0].where.line == 12


def test_generated_cpp_performs_the_assignments_as_python_does(tmp_path: Path) -> None:
    """The generated device counts and swaps as the Python runtime does (same traces)."""
    from codegen_support import CppDevice, assert_equivalent, needs_gxx

    if needs_gxx.args[0]:
        pytest.skip("no g++ on this machine")
    device = CppDevice(_counter(), tmp_path)
    go = ["Go", "Go completion"]
    assert_equivalent(
        device,
        [
            ({}, go * 4),
            ({"limit": 1}, go * 2),
            ({}, ["Swap", *go * 2, "Swap", *go]),  # count = 10 after Swap: Go is refused
        ],
    )


# --- verify tracks the data -----------------------------------------------------------------

BATCH = """\
device: Batch
data:
  count: 0
  limit: 3
states:
  - {state: Idle, control: default, ignore: [Done]}
  - {state: Full, control: event trigger required, ignore: [Add]}
events:
  - {event: Add, guard: count < limit, old: Idle, new: Idle, api: Add, assign: "count = count + 1"}
  - {event: Add, guard: count >= limit, old: Idle, new: Full, api: Add}
  - {event: Done, old: Full, new: Idle, api: Add, assign: "count = 0"}
"""


def _verify(tmp_path: Path, device: str) -> object:
    from statectl.cell.explore import explore
    from statectl.cell.model import load_cell_or_raise

    (tmp_path / "d.yaml").write_text(device)
    cell = tmp_path / "cell.yaml"
    cell.write_text(
        "cell: C\ndevices:\n  d: d.yaml\n"
        "environment:\n  - {send: Add, to: d}\n  - {send: Done, to: d}\n"
    )
    return explore(load_cell_or_raise(cell))


def test_verify_tracks_assigned_data_as_the_runtime_runs_it(tmp_path: Path) -> None:
    """A counter's values are local states: Full is reached only after three Adds."""
    from statectl.cell.explore import LocalSpace

    chart = _chart_of(BATCH)
    space = LocalSpace("d", chart)
    assert space.tracker.dynamic == ("count",)
    assert sorted(set(space.valuations)) == [(0,), (1,), (2,), (3,)]
    full = [i for i, s in enumerate(space.snapshots) if "Full" in s.active]
    assert [space.valuations[i] for i in full] == [(3,)]
    report = _verify(tmp_path, BATCH)
    assert report.free_guards == ()  # type: ignore[attr-defined]
    assert report.verdict == "holds"  # type: ignore[attr-defined]


def test_verify_refuses_data_that_grows_without_bound(tmp_path: Path) -> None:
    """A counter no guard stops is C412 naming the assignment, not an endless search."""
    from statectl.kernel.errors import DiagnosticError

    endless = BATCH.replace("guard: count < limit, ", "").replace(
        "  - {event: Add, guard: count >= limit, old: Idle, new: Full, api: Add}\n", ""
    )
    with pytest.raises(DiagnosticError) as caught:
        _verify(tmp_path, endless)
    (d,) = caught.value.diagnostics
    assert d.code == "C412"
    assert "count = count + 1" in d.message


def test_data_assigned_from_event_data_is_a_free_choice(tmp_path: Path) -> None:
    """An item assigned from _event is untracked: guards over it are chosen both ways."""
    from statectl.cell.explore import LocalSpace

    text = BATCH.replace('assign: "count = count + 1"', 'assign: "count = _event.data.n"')
    text = text.replace(
        'api: Add, assign: "count = _event', 'api: Add, data: {n: int}, assign: "count = _event'
    )
    space = LocalSpace("d", _chart_of(text))
    assert "count" in space.tracker.untracked
    assert space.tracker.dynamic == ()
    assert {g.guard for g in space.free_guards} == {"count < limit", "count >= limit"}


def _chart_of(text: str) -> Chart:
    tables, diags = read_yaml(text, "d.yaml")
    assert tables is not None, diags
    chart, more = build(tables)
    assert chart is not None, more
    return chart


# --- the journal brings the data back -----------------------------------------------------


def _journalled(db: Path, chart: Chart) -> object:
    from statectl.run.journal import Journal
    from statectl.run.runner import DeviceSetup, System

    return System((DeviceSetup("Indexer", chart),), SimClock(), Journal(db))


@pytest.mark.parametrize("cycles", [0, 1, 2])
def test_resume_brings_back_the_data_the_assignments_changed(tmp_path: Path, cycles: int) -> None:
    """After a restart the counter is where the run left it, not at its initial value."""
    db, chart = tmp_path / "j.db", _indexer()
    first: Any = _journalled(db, chart)
    try:
        first.start()
        for part in "abc"[:cycles]:
            first.post("Indexer", "Index", {"part": part})
            first.post("Indexer", "Index completion")
            first.quiesce()
        before = dict(first.subjects["Indexer"].data)
    finally:
        first.close()
    assert before["indexed"] == cycles
    again: Any = _journalled(db, chart)
    try:
        again.start(resume=True)
        assert dict(again.subjects["Indexer"].data) == before
    finally:
        again.close()


@pytest.mark.parametrize("guarantee", ["prompt", "durable-first"])
def test_a_journal_refuses_bad_data_before_it_accepts_the_event(
    tmp_path: Path, guarantee: str
) -> None:
    """Data that does not fit is refused before the journal's inbox holds the event."""
    from statectl.run.journal import Guarantee, Journal, JournalReader
    from statectl.run.runner import DeviceSetup, System
    from statectl.run.runtime.eventdata import EventDataError

    db = tmp_path / "j.db"
    journal = Journal(db, guarantee=Guarantee(guarantee))
    system = System((DeviceSetup("Indexer", _indexer()),), SimClock(), journal)
    try:
        system.start()
        with pytest.raises(EventDataError):
            system.post("Indexer", "Index", {"prt": "a"})
        system.quiesce()
    finally:
        system.close()
    with JournalReader(db) as reader:
        assert list(reader.inbox()) == []


def test_the_press_example_counts_its_strokes_and_resets() -> None:
    """examples/press: three strokes, the fourth refused by the count, Reset, one more."""
    path = Path(__file__).resolve().parents[1] / "examples" / "press" / "press.yaml"
    lines = "".join(
        f"Press {{pressure: {p}, part: {part}}}\n"
        for p, part in (("3.0", "A"), ("1.0", "B"), ("3.0", "C"), ("3.0", "D"), ("3.0", "E"))
    )
    out, err = io.StringIO(), io.StringIO()
    code = run(str(path), events=io.StringIO(lines + "Reset\nPress {pressure: 3, part: F}\n"),
               out=out, err=err)  # fmt: skip
    assert code == 0, err.getvalue()
    text = out.getvalue()
    assert text.count("Open -> Pressing") == 4
    assert text.count("ignored  Press (guard false)") == 2
    assert "final state Open" in text
