"""Consumers that hear steps (listen_steps) say what they said hearing every record.

The trace writer, ``statectl run``'s problem counter and the dashboard's counts read a
step record instead of the typed records one by one; what they write or count must
not change, however the device is wired and whatever the events do.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pytest

from statectl.cell.explore.replay import CellLinks
from statectl.cell.model import load_cell_or_raise
from statectl.channels.cli.problems import Problems as ProblemCounter  # statectl run's counter
from statectl.kernel.errors import UnhandledEventError
from statectl.kernel.model import Chart
from statectl.run.runner.cells import load_setups
from statectl.run.runtime import (
    MonitorStarted,
    MonitorStopped,
    ObserverCalled,
    Record,
    SimClock,
    StepRecord,
    Subject,
    TraceWriter,
)
from statectl.run.runtime.trace import format_data
from support import PAPER_CYCLE, wire_motor

EVENTS = (
    *PAPER_CYCLE,
    ("Movement completion", None),  # declared ignored in Blocked
    ("No such event", None),
    ("Initialization", None),  # declared ignored in Blocked when its guard is false
)
WIRINGS = ("bare", "monitor", "driver", "nobody")


def _run(
    chart: Chart, wiring: str, policy: str, steps: bool
) -> tuple[list[Record], list[StepRecord]]:
    """The events through a Motor wired so: every typed record, or every step record."""
    subject = Subject(chart, clock=SimClock(), policy=policy)  # type: ignore[arg-type]
    wire_motor(subject, wiring)
    typed: list[Record] = []
    heard: list[StepRecord] = []
    if steps:
        subject.listen_steps(heard.append)
    else:
        subject.listen(typed.append)
    subject.start()
    for event, data in EVENTS:
        with contextlib.suppress(UnhandledEventError):  # policy error: the run goes on
            subject.dispatch(event, data)
    subject.close()
    return typed, heard


@pytest.mark.parametrize("colour", [False, True])
@pytest.mark.parametrize("policy", ["ignore", "error"])
@pytest.mark.parametrize("wiring", WIRINGS)
def test_the_trace_of_steps_is_the_trace_of_records(
    motor: Chart, wiring: str, policy: str, colour: bool
) -> None:
    """TraceWriter.step writes the lines, and counts them, as the writer does per record."""
    typed, _ = _run(motor, wiring, policy, steps=False)
    _, steps = _run(motor, wiring, policy, steps=True)
    outs = (io.StringIO(), io.StringIO())
    per_record = TraceWriter(outs[0], device_width=7, colour=colour)
    per_step = TraceWriter(outs[1], device_width=7, colour=colour)
    for record in typed:
        per_record(record)
    for step in steps:
        per_step.step(step)
    assert outs[1].getvalue() == outs[0].getvalue()
    assert per_step.lines == per_record.lines == outs[0].getvalue().count("\n") > len(typed)


@pytest.mark.parametrize("policy", ["ignore", "error"])
@pytest.mark.parametrize("wiring", WIRINGS)
def test_a_step_counts_its_calls_and_monitor_records_as_its_records_do(
    motor: Chart, wiring: str, policy: str
) -> None:
    """api_calls and meanwhile agree with the step's typed records."""
    _, steps = _run(motor, wiring, policy, steps=True)
    for step in (s for s in steps if s.event is not None):
        calls = sum(type(r) is ObserverCalled for r in step.records)
        monitors = [r for r in step.records if type(r) in (MonitorStarted, MonitorStopped)]
        assert (step.api_calls, list(step.meanwhile)) == (calls, monitors), step
    if wiring == "monitor":
        assert any(s.meanwhile for s in steps)


@pytest.mark.parametrize("policy", ["ignore", "error"])
@pytest.mark.parametrize("wiring", WIRINGS)
def test_the_problem_counter_counts_steps_as_it_counts_records(
    motor: Chart, wiring: str, policy: str
) -> None:
    """ProblemCounter.step counts the refused and unknown events ProblemCounter.record does."""
    typed, _ = _run(motor, wiring, policy, steps=False)
    _, steps = _run(motor, wiring, policy, steps=True)
    by_record, by_step = ProblemCounter(), ProblemCounter()
    for record in typed:
        by_record.record(record)
    for step in steps:
        by_step.step(step)
    assert by_step.unknown == by_record.unknown
    assert by_step.unknown == 1  # "No such event"; the rest are handled or declared ignored


CELL = Path(__file__).parent.parent / "examples" / "pick-and-place" / "cell.yaml"


def _links_fired(steps: bool) -> list[list[int]]:
    """Every event of every device of the pick-and-place cell, twice over; the links
    each event fired, heard by record (watch) or by step (watch_step)."""
    cell = load_cell_or_raise(CELL)
    setups, _ = load_setups(cell, journalled=False)
    subjects = {s.name: Subject(s.chart, clock=SimClock(), name=s.name) for s in setups}
    links = CellLinks(cell, subjects)
    for subject in subjects.values():
        if steps:
            subject.listen_steps(links.watch_step)
        else:
            subject.listen(links.watch)
        subject.start()
    fired: list[list[int]] = []
    for _ in range(2):
        for subject in subjects.values():
            for event in subject.chart.event_names:
                links.fired.clear()
                subject.dispatch(event)
                fired.append(sorted(links.fired))
    return fired


def test_cell_links_fire_the_same_by_step_as_by_record() -> None:
    """CellLinks.watch_step fires, per event, the links CellLinks.watch fires."""
    by_record = _links_fired(steps=False)
    assert _links_fired(steps=True) == by_record
    assert any(by_record)  # some event fired a link


def test_the_trace_writes_each_event_with_its_own_data_however_often_it_repeats() -> None:
    """Event lines are kept per event and data: data that compares equal but prints
    differently (1 and True, 1 and 1.5) or cannot be a key still prints as format_record."""
    from statectl.run.runtime import EventReceived
    from statectl.run.runtime.trace import format_record

    datas: list[Any] = [
        None,
        {"amount": 1},
        {"amount": True},
        {"amount": 1.5},
        {"amount": 1},
        {"amount": [1, {"a": "b"}]},
        {"amount": {1, 2}},
        {"amount": {1, 2}},
        [1, 2],
        None,
    ]
    out = io.StringIO()
    writer = TraceWriter(out, device_width=5)
    records = [EventReceived("Motor", float(i), "Movement", d) for i, d in enumerate(datas)]
    for record in records:
        writer(record)
    want = "".join(format_record(r, device_width=5) + "\n" for r in records)
    assert out.getvalue() == want


class TickingClock(SimClock):
    """Every reading is a quarter second later, so a record made meanwhile (a monitor
    starting) has a time of its own, not its step's."""

    def now(self) -> float:
        self._now += 0.25
        return self._now


@pytest.mark.parametrize("clock", [SimClock, TickingClock])
@pytest.mark.parametrize("wiring", WIRINGS)
def test_a_steps_trace_puts_what_was_recorded_meanwhile_in_place(
    motor: Chart, wiring: str, clock: type[SimClock]
) -> None:
    """TraceWriter.step writes a monitor's lines where its records are, each with its
    own time: what the writer writes for the step's typed records one by one."""
    subject = Subject(motor, clock=clock())
    wire_motor(subject, wiring)
    steps: list[StepRecord] = []
    subject.listen_steps(steps.append)
    subject.start()
    for event, data in EVENTS:
        subject.dispatch(event, data)
    subject.close()
    outs = (io.StringIO(), io.StringIO())
    per_record = TraceWriter(outs[0], device_width=7)
    per_step = TraceWriter(outs[1], device_width=7)
    for step in steps:
        for record in step.records:
            per_record(record)
        per_step.step(step)
    assert outs[1].getvalue() == outs[0].getvalue()
    assert per_step.lines == per_record.lines == outs[0].getvalue().count("\n")
    apart = [r for s in steps for r in s.meanwhile if r.time != s.time]
    assert bool(apart) == (wiring in ("monitor", "driver") and clock is TickingClock)


@pytest.mark.parametrize(
    ("data", "text"),
    [
        ({"amount": 10}, "{amount: 10}"),
        ({"on": True, "off": None, "gain": 2.50}, "{on: True, off: None, gain: 2.5}"),
        ({"at": [1, 2.0, (3, "x")]}, "{at: [1, 2.0, [3, x]]}"),
        (
            {"to": 123456789.0, "by": 0.1, "far": 1.0000001},
            "{to: 123456789.0, by: 0.1, far: 1.0000001}",
        ),
        ({"name": "a, b", "empty": "", "pad": " x"}, "{name: 'a, b', empty: '', pad: ' x'}"),
        (MappingProxyType({"n": {"m": -1}}), "{n: {m: -1}}"),
        (7, "7"),
        (False, "False"),
        (1e-7, "1e-07"),
        ("plain", "plain"),
        (b"raw", "b'raw'"),
    ],
)
def test_event_data_reads_like_yaml_flow_style(data: Any, text: str) -> None:
    """format_data: mappings and sequences in flow style, numbers exact, strings bare
    unless they would read wrongly, anything else as its repr."""
    assert format_data(data) == text
