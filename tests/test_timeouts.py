"""Per-state timeouts: the ``timeout`` cell in every format, build, check, runtime, verify."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from statectl.cell.explore import verify_cell
from statectl.front.builder.build import (
    build,
    chart_to_tables,
    load_and_build,
    load_chart,
    strip_origins,
)
from statectl.front.rules import check_paths
from statectl.front.tables import load, save, strip_locations
from statectl.front.tables.timeouts import format_timeout, parse_timeout
from statectl.kernel.errors import Severity
from statectl.kernel.model import Chart, Timeout
from statectl.kernel.semantics import Event
from statectl.out.scxml import Scheduler, Session, SimulatedClock
from statectl.out.scxml.reader import read_scxml
from statectl.out.scxml.writer import write_scxml
from statectl.run.runtime import SimClock, Subject
from statectl.run.runtime.clock import WallClock
from statectl.run.runtime.records import EventReceived, Record

ROOT = Path(__file__).resolve().parents[1]
CLAMP = ROOT / "examples" / "clamp" / "clamp.yaml"

#: A door that must close within 3 s (Jam otherwise); Open has a watchdog on a compound.
DOOR = """\
device: Door
states:
  - state: Open
    control: default
    ignore: [all others]
  - state: Closing
    timeout: {timeout}
    ignore: [Close]
  - state: Shut
    ignore: [all others]
  - state: Jammed
    ignore: [all others]
events:
  - {{event: Close, old: Open, new: Closing, api: Shut}}
  - {{event: Closed, old: Closing, new: Shut, kind: completion, api: Shut}}
  - {{event: Jam, old: Closing, new: Jammed}}
  - {{event: Open, old: Shut, new: Open}}
  - {{event: Clear, old: Jammed, new: Open}}
"""


def door(tmp_path: Path, timeout: str = "3s -> Jam") -> Path:
    path = tmp_path / "door.yaml"
    path.write_text(DOOR.format(timeout=timeout), encoding="utf-8")
    return path


def door_chart(tmp_path: Path, timeout: str = "3s -> Jam") -> Chart:
    chart, diags = load_and_build(door(tmp_path, timeout))
    assert chart is not None, diags
    return chart


def codes(diags: object) -> list[str]:
    return [d.code for d in diags]  # type: ignore[attr-defined]


# -- the cell -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "seconds", "event"),
    [
        ("5s -> Move timeout", 5.0, "Move timeout"),
        ("2.5 s->X", 2.5, "X"),
        ("250ms -> Y", 0.25, "Y"),
        ("1 min → Z", 60.0, "Z"),
        ("1MS -> a->b", 0.001, "a->b"),
        ("3 sec -> W", 3.0, "W"),
    ],
)
def test_timeout_cells_parse(text: str, seconds: float, event: str) -> None:
    """A timeout cell reads as seconds and the event after the arrow."""
    assert parse_timeout(text) == (seconds, event)


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("5s", "not DURATION -> EVENT"),
        ("5 parsecs -> X", "unknown unit"),
        ("0s -> X", "from 1 ms"),
        ("0.5ms -> X", "from 1 ms"),
        ("1.0005s -> X", "whole number of milliseconds"),
        ("40000min -> X", "from 1 ms"),
        ("-1s -> X", "not DURATION -> EVENT"),
        ("5s -> A, B", "comma"),
    ],
)
def test_bad_timeout_cells_are_refused(text: str, why: str) -> None:
    """A malformed timeout cell says what is wrong with it."""
    problem = parse_timeout(text)
    assert isinstance(problem, str) and why in problem


@pytest.mark.parametrize("ms", [1, 250, 1000, 2500, 60000, 90000, 2**31 - 1])
def test_format_timeout_reads_back(ms: int) -> None:
    """A written timeout cell parses back to the same duration and event."""
    assert parse_timeout(format_timeout(ms / 1000, "Ev")) == (ms / 1000, "Ev")


@pytest.mark.parametrize("fmt", ["yaml", "csv", "xlsx", "md"])
def test_timeout_and_defer_survive_every_format(tmp_path: Path, fmt: str) -> None:
    """Saving tables with timeout and defer cells and loading them back loses nothing."""
    tables, diags = load(CLAMP)
    assert tables is not None and not diags
    out = tmp_path / "clamp" / f"clamp.{fmt}"
    out.parent.mkdir()
    save(tables, out, fmt)
    again, more = load(out)
    assert again is not None and not more
    assert strip_locations(again) == strip_locations(tables)
    assert any(s.timeout for s in again.states) and any(s.defer for s in again.states)


@pytest.mark.parametrize(
    ("fmt", "content", "line"),
    [
        ("yaml", DOOR.format(timeout="3 parsecs -> Jam"), 7),
        (
            "csv",
            "state,control,timeout\nOpen,default,\nClosing,,3 -> Jam\n",
            3,
        ),
        (
            "md",
            "# Device: Door\n\n## States\n\n| state | control | timeout |\n|---|---|---|\n"
            "| Open | default | |\n| Closing | | 3x -> Jam |\n\n## Events\n\n"
            "| event | old | new |\n|---|---|---|\n| Close | Open | Closing |\n",
            8,
        ),
    ],
)
def test_malformed_timeout_is_t118_at_its_line(
    tmp_path: Path, fmt: str, content: str, line: int
) -> None:
    """A malformed timeout is T118 with the file and line of its row, in each text format."""
    if fmt == "csv":
        (tmp_path / "door.events.csv").write_text(
            "event,old,new\nClose,Open,Closing\nJam,Closing,Open\n", encoding="utf-8"
        )
        path = tmp_path / "door.states.csv"
    else:
        path = tmp_path / f"door.{fmt}"
    path.write_text(content, encoding="utf-8")
    diags = check_paths([str(path)])
    found = [d for d in diags if d.code == "T118"]
    assert len(found) == 1, diags
    assert found[0].where.file == str(path) and found[0].where.line == line


# -- build and check ------------------------------------------------------------------------


def test_build_puts_the_timeout_on_the_state(tmp_path: Path) -> None:
    """The chart state carries its timeout's seconds and event; others have none."""
    chart = door_chart(tmp_path, "1500ms -> Jam")
    timeout = chart.state("Closing").timeout
    assert timeout is not None and (timeout.seconds, timeout.event) == (1.5, "Jam")
    assert chart.state("Open").timeout is None


def test_chart_to_tables_keeps_the_timeout(tmp_path: Path) -> None:
    """A chart with a timeout goes back to tables that build the same chart."""
    chart = door_chart(tmp_path)
    tables, diags = chart_to_tables(chart)
    assert tables is not None, diags
    assert [s.timeout for s in tables.states if s.timeout] == ["3s -> Jam"]
    again, _ = build(tables)
    assert again is not None and again.state("Closing").timeout == Timeout(3.0, "Jam")


@pytest.mark.parametrize(
    ("timeout", "code"),
    [
        ("3s -> Jammmed", "B224"),  # unknown event
        ("3s -> Open", "C409"),  # known, not handled in Closing
        ("3s -> Jam", None),
    ],
)
def test_check_reports_timeout_events(tmp_path: Path, timeout: str, code: str | None) -> None:
    """An unknown timeout event is B224, one the state does not handle C409 (errors)."""
    diags = check_paths([str(door(tmp_path, timeout))])
    errors = [d.code for d in diags if d.severity is Severity.ERROR]
    assert errors == ([code] if code else [])


def test_timeout_on_a_final_state_is_b225(tmp_path: Path) -> None:
    """A final state is never active with a timer running: B225."""
    text = DOOR.format(timeout="3s -> Jam").replace(
        "  - state: Shut\n", "  - state: Shut\n    type: final\n    timeout: 1s -> Jam\n"
    )
    text = text.replace("  - {event: Open, old: Shut, new: Open}\n", "")
    path = tmp_path / "door.yaml"
    path.write_text(text, encoding="utf-8")
    assert "B225" in codes(load_and_build(path)[1])


def test_rows_disagreeing_on_timeout_are_t109(tmp_path: Path) -> None:
    """Two rows of one state with different timeouts contradict each other (T109)."""
    text = DOOR.format(timeout="3s -> Jam").replace(
        "  - state: Shut\n", "  - state: Closing\n    timeout: 4s -> Jam\n  - state: Shut\n"
    )
    path = tmp_path / "door.yaml"
    path.write_text(text, encoding="utf-8")
    assert "T109" in codes(load_and_build(path)[1])


def test_a_compound_timeout_must_be_handled_in_every_substate(tmp_path: Path) -> None:
    """A timeout on a compound state is C409 unless every substate (or the state) handles it."""
    text = """\
device: Cycle
states:
  - {state: Idle, control: default, ignore: [all others]}
  - {state: Run, timeout: 10s -> Late}
  - {state: A, parent: Run, control: default}
  - {state: B, parent: Run}
events:
  - {event: Go, old: Idle, new: Run}
  - {event: Next, old: A, new: B}
  - {event: Late, old: A, new: Idle}
  - {event: Done, old: B, new: Idle}
"""
    path = tmp_path / "cycle.yaml"
    path.write_text(text, encoding="utf-8")
    found = [d for d in check_paths([str(path)]) if d.code == "C409"]
    assert len(found) == 1 and "'B'" in found[0].message
    path.write_text(text.replace("old: A, new: Idle", "old: Run, new: Idle"), encoding="utf-8")
    assert "C409" not in codes(check_paths([str(path)]))


#: A parallel Cell with a timeout; {rows} are the event rows for its timeout event Late.
PARALLEL = """\
device: Cell
states:
  - {{state: Idle, control: default, ignore: [all others]}}
  - {{state: Top}}
  - {{state: P, parent: Top, type: parallel, timeout: 10s -> Late}}
  - {{state: R1, parent: P}}
  - {{state: r1a, parent: R1, control: default}}
  - {{state: r1b, parent: R1}}
  - {{state: R2, parent: P}}
  - {{state: r2a, parent: R2, control: default}}
  - {{state: r2b, parent: R2}}
{more}events:
  - {{event: Go, old: Idle, new: P}}
  - {{event: N1, old: r1a, new: r1b}}
  - {{event: N2, old: r2a, new: r2b}}
  - {{event: Done, old: P, new: Idle}}
{rows}"""


def c409(tmp_path: Path, rows: str, more: str = "") -> list[str]:
    """The C409 messages ``statectl check`` gives the parallel Cell with these rows."""
    path = tmp_path / "cell.yaml"
    path.write_text(PARALLEL.format(rows=rows, more=more), encoding="utf-8")
    return [d.message for d in check_paths([str(path)]) if d.code == "C409"]


def late(*olds: str) -> str:
    return "".join(f"  - {{event: Late, old: {o}, new: Idle}}\n" for o in olds)


@pytest.mark.parametrize(
    ("rows", "more", "named"),
    [
        # one region handling it in every state is enough: the kernel offers the event to
        # every active state of every region
        (late("r1a", "r1b"), "", None),
        (late("R1"), "", None),
        (late("r2a", "r2b"), "", None),
        # the parallel state itself or an ancestor handles it
        (late("P"), "", None),
        (late("Top"), "", None),
        # no region handles it everywhere: r1b beside r2a loses it
        (late("r1a", "r2b"), "", ("r1b", "r2a")),
        (late("r1a"), "", ("r1b", "r2a")),
        # no row at all: the first configuration is named
        ("  - {event: Late, old: Idle, new: Idle}\n", "", ("r1a", "r2a")),
        # a region waiting in its final state is a configuration too
        (
            late("r1a", "r1b"),
            "  - {state: f1, parent: R1, type: final}\n",
            ("f1", "r2a"),
        ),
        # ... unless every region is final and done.state.P leaves P
        (
            late("r1a", "r1b", "r2a", "r2b")
            + "  - {event: done.state.P, old: P, new: Idle, kind: internal}\n",
            "  - {state: f1, parent: R1, type: final}\n  - {state: f2, parent: R2, type: final}\n",
            None,
        ),
        (
            late("r1a", "r1b", "r2a", "r2b"),
            "  - {state: f1, parent: R1, type: final}\n  - {state: f2, parent: R2, type: final}\n",
            ("f1", "f2"),
        ),
    ],
)
def test_a_parallel_timeout_needs_one_handling_state_in_every_configuration(
    tmp_path: Path, rows: str, more: str, named: tuple[str, ...] | None
) -> None:
    """A parallel state's timeout is C409 only where some configuration inside it has no
    active state (or ancestor) handling it; the message names that configuration."""
    found = c409(tmp_path, rows, more)
    if named is None:
        assert found == []
        return
    assert len(found) == 1, found
    listed = " and ".join(repr(n) for n in named)
    assert f"state 'P' times out with 'Late', which none of {listed}" in found[0], found


@pytest.mark.parametrize(
    ("olds", "named"),
    [
        (("A",), "B"),  # as before: every substate must handle it
        (("B",), "A"),
        (("A", "B"), None),
        (("Run",), None),
        (("Top",), None),  # an ancestor's row counts
        ((), "A"),  # the first substate losing it is named
    ],
)
def test_a_compound_timeout_needs_every_substate(
    tmp_path: Path, olds: tuple[str, ...], named: str | None
) -> None:
    """A compound state's timeout is C409 naming a substate that does not handle it."""
    text = (
        "device: Cycle\nstates:\n"
        "  - {state: Idle, control: default, ignore: [all others]}\n"
        "  - {state: Top}\n"
        "  - {state: Run, parent: Top, timeout: 10s -> Late}\n"
        "  - {state: A, parent: Run, control: default}\n"
        "  - {state: B, parent: Run}\n"
        "events:\n"
        "  - {event: Go, old: Idle, new: Run}\n"
        "  - {event: Next, old: A, new: B}\n"
        "  - {event: Done, old: Run, new: Idle}\n"
        "  - {event: Late, old: Idle, new: Idle}\n" + late(*olds)
    )
    path = tmp_path / "cycle.yaml"
    path.write_text(text, encoding="utf-8")
    found = [d.message for d in check_paths([str(path)]) if d.code == "C409"]
    if named is None:
        assert found == []
        return
    assert found == [
        f"state 'Run' times out with 'Late', which {named!r} does not handle: "
        "the timeout would be lost"
    ]


# -- the runtime ----------------------------------------------------------------------------


def run(chart: Chart) -> tuple[Subject, SimClock, list[Record]]:
    clock = SimClock()
    subject = Subject(chart, clock=clock, policy="error")
    records: list[Record] = []
    subject.listen(records.append)
    subject.start()
    return subject, clock, records


def test_the_timeout_fires_after_its_duration(tmp_path: Path) -> None:
    """The timeout event is processed exactly its duration after the state was entered."""
    subject, clock, records = run(door_chart(tmp_path))
    clock.advance(1.0)
    subject.dispatch("Close")
    subject.advance(2.999)
    assert subject.configuration == {"Closing"}
    subject.advance(0.001)
    assert subject.configuration == {"Jammed"}
    received = [r for r in records if isinstance(r, EventReceived) and r.event == "Jam"]
    assert [r.time for r in received] == [4.0]


def test_leaving_the_state_cancels_the_timeout(tmp_path: Path) -> None:
    """A state left before its deadline raises nothing later, even on re-entry's old timer."""
    subject, _, records = run(door_chart(tmp_path))
    subject.dispatch("Close")
    subject.advance(2.0)
    subject.dispatch("Closed")
    subject.advance(10.0)
    assert subject.configuration == {"Shut"}
    subject.dispatch("Open")
    subject.dispatch("Close")  # re-entered at t=12: a fresh 3 s
    subject.advance(2.5)
    assert subject.configuration == {"Closing"}
    subject.advance(0.5)
    assert subject.configuration == {"Jammed"}
    assert sum(1 for r in records if isinstance(r, EventReceived) and r.event == "Jam") == 1


def test_the_timeout_is_delivered_before_later_queued_events(tmp_path: Path) -> None:
    """At the deadline the timeout goes first: an event queued meanwhile meets the new state."""
    subject, clock, _ = run(door_chart(tmp_path))
    subject.dispatch("Close")
    clock.call_later(3.0, lambda: subject.post("Closed"))  # due at the same instant, later
    subject.advance(3.0)
    assert subject.configuration == {"Jammed"}


def test_a_timer_that_fired_while_its_state_was_left_does_nothing(tmp_path: Path) -> None:
    """A firing queued before the exit step ran is dropped (no Jam in Shut)."""
    subject, clock, records = run(door_chart(tmp_path))
    subject.dispatch("Close")
    subject.post("Closed")  # queued, not yet processed, before the timer's callback
    clock.advance(3.0)  # fires: its callback is queued behind Closed
    subject.run_until_idle()
    assert subject.configuration == {"Shut"}
    assert not any(isinstance(r, EventReceived) and r.event == "Jam" for r in records)


def test_a_restored_device_rearms_its_timeout(tmp_path: Path) -> None:
    """Restoring into a state with a timeout counts the timeout from the restore."""
    chart = door_chart(tmp_path)
    first, _, _ = run(chart)
    first.dispatch("Close")
    snapshot = first.snapshot
    assert snapshot is not None
    clock = SimClock(100.0)
    again = Subject(chart, clock=clock)
    again.restore(snapshot)
    again.advance(3.0)
    assert again.configuration == {"Jammed"}


def test_closing_the_subject_cancels_its_timers(tmp_path: Path) -> None:
    """A closed device leaves no live timer on the clock."""
    subject, clock, _ = run(door_chart(tmp_path))
    subject.dispatch("Close")
    assert clock.pending == 1
    subject.close()
    assert clock.pending == 0


def test_the_timeout_fires_on_a_wall_clock(tmp_path: Path) -> None:
    """On a WallClock the timeout fires by itself and the worker processes it."""
    chart = door_chart(tmp_path, "50ms -> Jam")
    clock = WallClock()
    subject = Subject(chart, clock=clock)
    jammed = threading.Event()
    subject.on_step(lambda event, _data, _outcome: jammed.set() if event == "Jam" else None)
    subject.start()
    subject.start_worker()
    try:
        subject.post("Close")
        assert jammed.wait(5.0)
    finally:
        subject.close()
        clock.stop()
    assert subject.configuration == {"Jammed"}


def test_a_chart_without_timeouts_arms_nothing(tmp_path: Path) -> None:
    """Only states with a timeout cell get a timer: Motor's clock stays empty."""
    chart, _ = load_and_build(ROOT / "examples" / "motor" / "motor.yaml")
    assert chart is not None
    clock = SimClock()
    subject = Subject(chart, clock=clock)
    subject.start()
    subject.dispatch("Movement")
    assert clock.pending == 0


# -- verify ---------------------------------------------------------------------------------


def failures(cell: Path) -> list[str]:
    report, diags = verify_cell(cell)
    assert report is not None, diags
    return [f.name for f in report.failures]


def test_verify_offers_the_timeout_where_it_can_happen(tmp_path: Path) -> None:
    """The explorer reaches Jammed through the timeout; without the timeout it cannot."""
    device = tmp_path / "door.yaml"
    device.write_text(DOOR.format(timeout="3s -> Jam"), encoding="utf-8")
    cell = tmp_path / "cell.yaml"
    cell.write_text(
        "cell: C\ndevices:\n  door: door.yaml\nenvironment:\n"
        "  - {send: Close, to: door}\n  - {send: Open, to: door}\n  - {send: Clear, to: door}\n"
        "invariants:\n  - {name: never-jammed, holds: \"not In('door.Jammed')\"}\n",
        encoding="utf-8",
    )
    assert failures(cell) == ["never-jammed"]
    device.write_text(
        DOOR.format(timeout="3s -> Jam").replace("    timeout: 3s -> Jam\n", ""),
        encoding="utf-8",
    )
    assert failures(cell) == []


# -- SCXML ----------------------------------------------------------------------------------


def test_scxml_export_writes_the_timeout_as_a_delayed_send_and_cancel() -> None:
    """The exported state sends its timeout event with a delay on entry and cancels on exit."""
    text = write_scxml(load_chart(CLAMP))
    state = text[text.index('<state id="Closing"') : text.index('<state id="Clamped"')]
    assert (
        '<send event="Close_timeout" statectl:event-name="Close timeout" delay="2000ms" '
        'id="statectl.timeout.Closing"/>' in state
    )
    assert '<cancel sendid="statectl.timeout.Closing"/>' in state
    assert state.index("<onentry") < state.index("<send") < state.index("<onexit")
    assert '<statectl:defer event="Release"/>' in state


def test_scxml_round_trip_keeps_timeout_and_defer() -> None:
    """Reading the export back gives the very chart, and tables with the same cells."""
    chart = load_chart(CLAMP)
    again, diags = read_scxml(write_scxml(chart))
    assert again is not None and not diags
    assert strip_origins(again) == strip_origins(chart)
    tables, info = chart_to_tables(again)
    assert tables is not None, info
    closing = next(s for s in tables.states if s.state == "Closing")
    assert (closing.timeout, closing.defer) == ("2s -> Close timeout", ("Release",))


def test_malformed_timeout_in_a_workbook_names_sheet_and_row(tmp_path: Path) -> None:
    """In XLSX a malformed timeout is T118 at the States sheet's row of the state."""
    import openpyxl  # type: ignore[import-untyped, unused-ignore]

    tables, _ = load(CLAMP)
    assert tables is not None
    path = tmp_path / "clamp.xlsx"
    save(tables, path)
    book = openpyxl.load_workbook(path)
    sheet = book["States"]
    header = [c.value for c in sheet[1]]
    row = next(r for r in range(2, sheet.max_row + 1) if sheet.cell(r, 3).value == "Closing")
    sheet.cell(row, header.index("timeout") + 1).value = "2 fortnights -> Close timeout"
    book.save(path)
    found = [d for d in load(path)[1] if d.code == "T118"]
    assert len(found) == 1
    assert (found[0].where.sheet, found[0].where.line) == ("States", row)


@pytest.mark.parametrize(
    ("closed_at", "expected"),
    [(None, ["Jammed"]), (1.0, ["Clamped"])],
)
def test_the_scxml_session_runs_an_exported_timeout(
    closed_at: float | None, expected: list[str]
) -> None:
    """`statectl scxml run` on the export: Closing times out at 2 s unless Closed came first."""
    chart, diags = read_scxml(write_scxml(load_chart(CLAMP)))
    assert chart is not None, diags
    clock = SimulatedClock()
    scheduler = Scheduler(clock)
    session = Session(chart, scheduler)
    session.post(Event("Close", type="external"))
    if closed_at is not None:
        scheduler.run(session, closed_at)
        session.post(Event("Closed", type="external"))
    scheduler.run(session, 10.0)
    assert sorted(session.run.active) == expected


@pytest.mark.parametrize(("limit", "expected"), [(2.0, {"Closing"}), (60.0, {"Jammed"})])
def test_a_system_settles_through_a_timeout(
    tmp_path: Path, limit: float, expected: set[str]
) -> None:
    """System.settle() waits for a timeout as for work in flight, within its limit."""
    from statectl.run.system import DeviceSetup, System

    system = System((DeviceSetup("D", door_chart(tmp_path)),), SimClock())
    system.start()
    system.post("D", "Close")
    system.settle(limit)
    assert system.subjects["D"].configuration == expected
