"""Step 3 of the method: grouping events by API into observer methods and invoke numbers."""

from __future__ import annotations

import pytest

from statectl.front.observers import EventSpec, derive_invokes
from statectl.kernel.model import EventKind

C, D, F = EventKind.COMMAND, EventKind.COMPLETION, EventKind.FAULT

MOTOR = [
    EventSpec("Movement", C, "Movement", "Moving"),
    EventSpec("Movement completion", D, "Movement", "Blocked"),
    EventSpec("Initialization", C, "Initialization", "Returning"),
    EventSpec("Initialization completion", D, "Initialization", "Blocked"),
    EventSpec("Error", F, "Error", "Returning"),
    EventSpec("Error completion", D, "Error", "Blocked"),
]


def test_motor_gives_the_papers_three_invokes() -> None:
    """The Motor yields Moving=0, Returning=1, Error=2 for Movement(), Initialization(), Error()."""
    apis, invokes = derive_invokes(MOTOR)
    assert [(i.number, i.name, i.method) for i in invokes] == [
        (0, "Moving", "Movement"),
        (1, "Returning", "Initialization"),
        (2, "Error", "Error"),
    ]
    assert [a.events for a in apis] == [
        ("Movement", "Movement completion"),
        ("Initialization", "Initialization completion"),
        ("Error", "Error completion"),
    ]


@pytest.mark.parametrize(
    ("rows", "expected"),
    [
        # an explicit invoke name wins
        ([EventSpec("Go", C, "Drive", "Run", invoke="DRIVE")], [(0, "DRIVE", "Drive")]),
        # a method with only completions is named after itself
        ([EventSpec("Done", D, "Drive", "Idle")], [(0, "Drive", "Drive")]),
        # events without an API get no observer method
        (
            [EventSpec("Tick", C, None, "Idle"), EventSpec("Go", C, "Drive", "Run")],
            [(0, "Run", "Drive")],
        ),
        # numbers follow the first appearance of each API
        (
            [
                EventSpec("B", C, "Beta", "S2"),
                EventSpec("A", C, "Alpha", "S1"),
                EventSpec("B2", D, "Beta", "S0"),
            ],
            [(0, "S2", "Beta"), (1, "S1", "Alpha")],
        ),
    ],
)
def test_invoke_naming_rules(rows: list[EventSpec], expected: list[tuple[int, str, str]]) -> None:
    """Invoke names: explicit, else the driven state, else the method; numbered by first use."""
    _, invokes = derive_invokes(rows)
    assert [(i.number, i.name, i.method) for i in invokes] == expected
