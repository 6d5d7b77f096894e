"""Event data in device tables: one spelling that works, checked at load and when sent."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from statectl.front.builder.build import build, load_and_build
from statectl.front.tables import load, save, strip_locations
from statectl.front.tables.yaml_io import read_yaml
from statectl.kernel.errors import Diagnostic, Severity, StatectlError
from statectl.kernel.model import Chart
from statectl.kernel.semantics import Unhandled
from statectl.kernel.semantics.eventview import GuardError
from statectl.run.runtime import Subject
from statectl.run.runtime.clock import SimClock
from statectl.run.runtime.eventdata import EventDataError
from statectl.run.runtime.records import EventRejected

PRESS = """\
device: Press
data:
  indexed: 0
  limit: 2
states:
  - state: Idle
    control: default
  - state: Pressing
events:
  - event: Press
    guard: {guard}
    old: Idle
    new: Pressing
    data: {{pressure: float, part: str}}
  - event: Done
    old: Pressing
    new: Idle
    kind: completion
"""

GOOD_GUARD = "_event.data.pressure > 2.5"


def _build(text: str) -> tuple[Chart | None, list[Diagnostic]]:
    tables, diags = read_yaml(text, "press.yaml")
    assert tables is not None, diags
    chart, more = build(tables)
    return chart, [*diags, *more]


def _press(guard: str = GOOD_GUARD) -> Chart:
    chart, diags = _build(PRESS.format(guard=f'"{guard}"'))
    assert chart is not None, diags
    return chart


def _started(chart: Chart, policy: str = "ignore") -> Subject:
    subject = Subject(chart, clock=SimClock(), policy=policy)  # type: ignore[arg-type]
    subject.start()
    return subject


# --- the spelling, at load -------------------------------------------------------------


@pytest.mark.parametrize(
    ("guard", "code", "hint"),
    [
        ("_event.data.pressure > 2.5", None, ""),
        ("_event['data']['pressure'] > 2.5", None, ""),
        ("_event.data['pressure'] > 2.5", None, ""),
        ("_event.name == 'Press'", None, ""),
        ("_event['pressure'] > 2.5", "B231", "_event.data.pressure"),
        ("_event.pressure > 2.5", "B231", "_event.data.pressure"),
        ("event.pressure > 2.5", "B231", "_event.data.pressure"),
        ("event.data.pressure > 2.5", "B231", "_event.data.pressure"),
        ("data.pressure > 2.5", "B231", "_event.data.pressure"),
        ("payload['pressure'] > 2.5", "B231", "_event.data.pressure"),
        ("_event.data.presure > 2.5", "B232", "declared: {pressure: float, part: str}"),
        ("_event['data']['weight'] > 2.5", "B232", "add the field"),
        ("_event.data.pressure > 'high'", "X306", "declared float"),
        ("_event.data.part == 3", "X306", "declared str"),
        ("_event.data.part in ('A', 2)", "X306", "with 2"),
        ("3 < _event.data.pressure < 'x'", "X306", "with 'x'"),
        ("_event.data.part in ('A', 'B') and _event.data.pressure >= 2", None, ""),
        ("len(_event.data.part) == 3", None, ""),
    ],
)
def test_guard_spelling_of_event_data(guard: str, code: str | None, hint: str) -> None:
    """Only paths through _event.data load; others are refused with the working spelling."""
    chart, diags = _build(PRESS.format(guard=f'"{guard}"'))
    errors = [d for d in diags if d.severity is Severity.ERROR]
    if code is None:
        assert chart is not None and not errors, errors
        return
    assert chart is None
    assert [d.code for d in errors] == [code], errors  # one diagnostic, no X303 beside it
    assert hint in errors[0].message + errors[0].hint
    assert errors[0].where.line == 10


def test_reading_fields_of_an_event_without_declared_data_warns() -> None:
    """A guard reading fields of an event that declares none is B233, a warning."""
    text = PRESS.format(guard=f'"{GOOD_GUARD}"').replace(
        "    data: {pressure: float, part: str}\n", ""
    )
    chart, diags = _build(text)
    assert chart is not None
    assert [(d.code, d.severity) for d in diags] == [("B233", Severity.WARNING)]


def test_rows_of_one_event_declaring_different_data_are_refused() -> None:
    """Two rows of one event that declare different fields are B230."""
    text = PRESS.format(guard=f'"{GOOD_GUARD}"') + (
        "  - event: Press\n    old: Pressing\n    new: Pressing\n    data: {force: int}\n"
    )
    chart, diags = _build(text)
    assert chart is None
    assert [d.code for d in diags if d.severity is Severity.ERROR] == ["B230"]


@pytest.mark.parametrize(
    ("cell", "code", "word"),
    [
        ("'pressure: float, part: str'", None, ""),
        ("'pressure: real'", "T122", "unknown type"),
        ("'pressure'", "T122", "name: type"),
        ("'_secret: int'", "T122", "identifier"),
        ("'a: int, a: str'", "T122", "twice"),
    ],
)
def test_data_declaration_cell(cell: str, code: str | None, word: str) -> None:
    """A data cell is 'name: type, ...' with known types; anything else is T122."""
    text = PRESS.format(guard="null").replace("{pressure: float, part: str}", cell)
    tables, diags = read_yaml(text, "press.yaml")
    assert [d.code for d in diags] == ([code] if code else [])
    if code:
        assert word in diags[0].message
    else:
        assert tables is not None
        assert tables.events[0].fields == (("pressure", "float"), ("part", "str"))


# --- every table format -----------------------------------------------------------------


ASSIGNING = PRESS.format(guard=f'"{GOOD_GUARD} and indexed < limit"').replace(
    "    data: {pressure: float, part: str}\n",
    "    data: {pressure: float, part: str}\n    assign: {indexed: indexed + 1}\n",
)


@pytest.mark.parametrize("suffix", [".yaml", ".csv", ".xlsx", ".md"])
def test_data_and_assign_survive_every_format(tmp_path: Path, suffix: str) -> None:
    """The data and assign columns are written and read back by every table format."""
    tables, diags = read_yaml(ASSIGNING, "press.yaml")
    assert tables is not None and not diags
    assert tables.events[0].assign == (("indexed", "indexed + 1"),)
    save(tables, tmp_path / f"press{suffix}")
    again, more = load(tmp_path / f"press{suffix}")
    assert again is not None and not more, more
    assert strip_locations(again) == strip_locations(tables)


def test_hand_written_csv_cells_declare_data_and_assign(tmp_path: Path) -> None:
    """A CSV pair with data and assign cells builds the chart the YAML builds."""
    (tmp_path / "press.states.csv").write_text("state,control\nIdle,default\nPressing,\n")
    (tmp_path / "press.events.csv").write_text(
        "event,guard,old,new,kind,data,assign\n"
        "Press,_event.data.pressure > 2.5 and indexed < limit,Idle,Pressing,command,"
        '"pressure: float, part: str",indexed = indexed + 1\n'
        "Done,,Pressing,Idle,completion,,\n"
    )
    (tmp_path / "press.data.csv").write_text("name,value\nindexed,0\nlimit,2\n")
    chart, diags = load_and_build(tmp_path / "press.events.csv")
    assert chart is not None, diags
    assert chart.event("Press") is not None
    assert chart.event("Press").fields == (("pressure", "float"), ("part", "str"))  # type: ignore[union-attr]


# --- at run time -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("guard", "data", "state"),
    [
        ("_event.data.pressure > 2.5", {"pressure": 3.0}, "Pressing"),
        ("_event.data.pressure > 2.5", {"pressure": 1.0}, "Idle"),
        ("_event['data']['pressure'] > 2.5", {"pressure": 3.0}, "Pressing"),
        ("_event.data.part == 'A'", {"part": "A", "pressure": 1}, "Pressing"),
        ("_event.data.part == 'A'", {"part": "B"}, "Idle"),
    ],
)
def test_guard_reads_the_sent_data(guard: str, data: dict[str, Any], state: str) -> None:
    """The documented spelling reads the data sent with the event."""
    subject = _started(_press(guard))
    subject.dispatch("Press", data)
    assert subject.configuration == {state}


@pytest.mark.parametrize("policy", ["ignore", "error"])
def test_a_guard_that_raises_is_an_error_event_not_false(policy: str) -> None:
    """A failing guard refuses the event, records guard error and names the row's file:line."""
    subject = _started(_press(), policy)
    records: list[Any] = []
    subject.listen(records.append)
    with pytest.raises(GuardError) as caught:
        subject.dispatch("Press", {"part": "A"})  # no pressure sent
    assert "press.yaml:10" in str(caught.value)
    assert "pressure" in str(caught.value)
    assert subject.configuration == {"Idle"}
    rejected = [r for r in records if isinstance(r, EventRejected)]
    assert [r.reason for r in rejected] == [Unhandled.GUARD_ERROR]


def test_a_failing_guard_after_a_memoised_false_is_still_reported() -> None:
    """A guard memoised false for some data raises, not replays false, for data that fails."""
    subject = _started(_press())
    subject.dispatch("Press", {"pressure": 1.0})
    assert subject.configuration == {"Idle"}
    with pytest.raises(GuardError):
        subject.dispatch("Press", {"part": "A"})  # no pressure: the guard raises
    assert subject.configuration == {"Idle"}


@pytest.mark.parametrize(
    ("data", "word"),
    [
        ({"presure": 3.0}, "no data field 'presure'"),
        ({"pressure": "high"}, "must be float"),
        ({"pressure": True}, "must be float"),
        ({"part": 3}, "must be str"),
        (3.0, "not a float"),
    ],
)
def test_data_that_does_not_fit_the_declaration_is_refused(data: Any, word: str) -> None:
    """post() and dispatch() refuse unknown fields, wrong types and non-mappings at once."""
    subject = _started(_press())
    for send in (subject.dispatch, subject.post):
        with pytest.raises(EventDataError) as caught:
            send("Press", data)
        assert word in str(caught.value)
        assert "pressure: float, part: str" in str(caught.value) or "must be" in str(caught.value)
    assert subject.queued == 0
    assert subject.configuration == {"Idle"}


def test_an_event_without_declared_data_takes_any_data() -> None:
    """Data sent with an event that declares none is not checked (as before)."""
    subject = _started(_press())
    subject.dispatch("Press", {"pressure": 3.0})
    subject.dispatch("Done", {"anything": [1, 2]})
    assert subject.configuration == {"Idle"}


def test_event_data_errors_are_statectl_errors() -> None:
    """Refusals are StatectlErrors, so every host reports them as it reports bad input."""
    assert issubclass(EventDataError, StatectlError)
    assert issubclass(GuardError, StatectlError)


@pytest.mark.parametrize(
    ("data", "word"),
    [
        ("{detail: restarted}", None),
        ("{detial: restarted}", "'detial', which the event does not declare"),
        ("{detail: 3}", "which is no str"),
        ("restarted", "not a mapping"),
    ],
)
def test_recovery_data_must_fit_the_events_declared_fields(data: str, word: str | None) -> None:
    """A Recovery rule whose data its event would refuse on resume is C413."""
    from statectl.front.recovery import check_recovery

    text = (
        "device: M\nstates:\n  - {state: Idle, control: default}\n"
        "  - {state: Busy, control: monitoring required}\n"
        "events:\n  - {event: Go, old: Idle, new: Busy}\n"
        "  - {event: Error, old: Busy, new: Idle, kind: fault, data: {detail: str}}\n"
        f"recovery:\n  - {{state: Busy, event: Error, data: {data}}}\n"
    )
    tables, diags = read_yaml(text, "m.yaml")
    assert tables is not None and not diags, diags
    chart, more = build(tables)
    assert chart is not None, more
    found = [d for d in check_recovery(chart, tables.recovery) if d.code == "C413"]
    if word is None:
        assert found == []
    else:
        assert [d.where.line for d in found] == [9]
        assert word in found[0].message


def test_a_guard_over_data_of_an_event_sent_without_data_says_so() -> None:
    """The guard error of an event sent with no data says that no data was sent."""
    subject = _started(_press())
    with pytest.raises(GuardError) as caught:
        subject.dispatch("Press")
    assert "sent without data" in str(caught.value)


def test_codegen_refuses_a_guard_that_fails_when_evaluated() -> None:
    """A guard that raises at generation time is G714, not a silent 'guard false' table."""
    from statectl.kernel.model import ControlKind, State, Transition
    from statectl.out.codegen.flatten import flatten

    chart = Chart(
        "D",
        (State("A", controls=frozenset({ControlKind.DEFAULT})), State("B")),
        (Transition("A", ("go",), ("B",), guard="previous > 3"),),
        ("A",),
    )
    _, diags = flatten(chart)
    assert [d.code for d in diags] == ["G714"]
    assert "TypeError" in diags[0].message


ASSIGNS = PRESS.replace(
    "    data: {{pressure: float, part: str}}\n",
    "    data: {{pressure: float, part: str}}\n    assign: {{indexed: _event.data.part + 1}}\n",
)


@pytest.mark.parametrize("as_json", [False, True])
@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("Press", "guard '_event.data.pressure > 2.5' of event 'Press' failed"),
        ("Press {pressure: 3, part: a}", "assignment indexed = _event.data.part + 1"),
    ],
)
def test_a_guard_or_assignment_that_fails_counts_once_either_way(
    tmp_path: Path, as_json: bool, line: str, says: str
) -> None:
    """A guard or an assignment that raises is said and makes `statectl run` exit 1, with
    or without --json, counted once (the trace run exited 0: no record reached its count)."""
    import io

    from statectl.channels.cli.run import run

    device = tmp_path / "press.yaml"
    device.write_text(ASSIGNS.format(guard=f'"{GOOD_GUARD}"'), encoding="utf-8")
    out, err = io.StringIO(), io.StringIO()
    code = run(str(device), events=io.StringIO(line + "\n"), out=out, err=err, as_json=as_json)
    said = err.getvalue()
    assert (code, says in said) == (1, True), said
    assert "statectl run: 1 event(s) unknown to the device or rejected: exit 1" in said


def test_a_guard_that_raises_gives_step_listeners_the_records_listen_gets() -> None:
    """A step listener hears a guard error as a step record of its own (reason guard
    error, rejected), whose typed records are those a listen() listener gets."""
    steps: list[Any] = []
    typed: list[Any] = []
    for hear in ("steps", "typed"):
        subject = Subject(_press(), clock=SimClock())
        if hear == "steps":
            subject.listen_steps(steps.append)
        else:
            subject.listen(typed.append)
        subject.start()
        with pytest.raises(GuardError):
            subject.dispatch("Press", {"part": "A"})
    last = steps[-1]
    assert (last.event, last.reason, last.rejected) == ("Press", Unhandled.GUARD_ERROR, True)
    assert [r for s in steps for r in s.records] == typed
