"""Writing charts as SCXML: device charts survive the round trip through the statectl namespace."""

from __future__ import annotations

import dataclasses

import pytest

from statectl.kernel.errors import Location
from statectl.kernel.model import Chart, ControlKind, Log, Notify, State, StateKind, Transition
from statectl.out.scxml import read_scxml, write_scxml

MOTOR = Chart(
    name="Motor",
    states=(
        State("Blocked", controls=frozenset({ControlKind.DEFAULT}), description="at rest"),
        State(
            "Moving",
            controls=frozenset({ControlKind.MONITORING, ControlKind.TRIGGER}),
            component="Motor/API",
            on_entry=(Log("entered", "moving now"),),
        ),
        State("Done", StateKind.FINAL),
    ),
    transitions=(
        Transition(
            "Blocked",
            ("Movement",),
            ("Moving",),
            condition="request from external inputs",
            actions=(Notify(0, "Moving", "Movement", "Movement"),),
        ),
        Transition("Moving", ("Stop",), ("Done",), guard="previous == 'Blocked'"),
    ),
    initial=("Blocked",),
)


def _without_locations(chart: Chart) -> Chart:
    nowhere = Location()
    return dataclasses.replace(
        chart,
        origin=nowhere,
        states=tuple(
            dataclasses.replace(
                s,
                origin=nowhere,
                on_entry=tuple(
                    dataclasses.replace(a, origin=nowhere) if isinstance(a, Log) else a
                    for a in s.on_entry
                ),
            )
            for s in chart.states
        ),
        transitions=tuple(dataclasses.replace(t, origin=nowhere) for t in chart.transitions),
    )


def test_device_chart_round_trips() -> None:
    """A device chart written and read back is equal to the original, locations aside."""
    chart, diagnostics = read_scxml(write_scxml(MOTOR))
    assert chart is not None, diagnostics
    assert _without_locations(chart) == dataclasses.replace(MOTOR, datamodel="safe")


@pytest.mark.parametrize(
    "fragment",
    [
        'xmlns="http://www.w3.org/2005/07/scxml"',
        '<statectl:notify invoke="0" name="Moving" method="Movement" event="Movement"/>',
        'statectl:controls="event-trigger-required monitoring-required"',
        "cond=\"previous == 'Blocked'\"",
        '<final id="Done"/>',
    ],
)
def test_written_text_uses_scxml_and_the_statectl_namespace(fragment: str) -> None:
    """SCXML words for what SCXML has; the statectl namespace for the paper's facts."""
    assert fragment in write_scxml(MOTOR)
