"""One behaviour suite, every backend: generated C++ traces exactly like the Python runtime.

Each chart is generated and compiled once; many event sequences run in that one binary.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from codegen_support import CppDevice, assert_equivalent, needs_gxx
from statectl.build import load_chart
from statectl.model import (
    Chart,
    DataItem,
    EventDef,
    Invoke,
    Notify,
    Raise,
    State,
    StateKind,
    Transition,
)

ROOT = Path(__file__).resolve().parent.parent
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"

pytestmark = needs_gxx

INVOKES = (Invoke(0, "Alpha", "Start"), Invoke(1, "Beta", "Stop"))
EVENTS = ("go", "stop", "tick", "go fast")
#: Guards over the int fields x and y, the previous state and In(); state names are S<n>.
GUARDS = (
    None, None, None,
    "x > 1", "y == 0", "x + y < 3", "not x", "x if y else 1", "x * 2 >= y - 1 > -1",
    "previous == 'S1'", "In('S2')", "x > 0 and In('S3')", "previous != 'S2' or y",
)


@st.composite
def charts(draw: st.DrawFn) -> Chart:
    """Small hierarchical/parallel charts with guards, Notify on transitions and entries."""
    states: list[State] = []

    def node(parent: str | None, depth: int) -> None:
        name = f"S{len(states)}"
        kinds = [StateKind.ATOMIC] if depth >= 2 else [
            StateKind.ATOMIC, StateKind.ATOMIC, StateKind.COMPOUND, StateKind.PARALLEL
        ]
        kind = draw(st.sampled_from(kinds))
        notify = draw(st.sampled_from([(), (), (Notify(0, "Alpha", "Start", "entry"),)]))
        index = len(states)
        states.append(State(name, kind, parent, on_entry=notify))
        if kind is not StateKind.ATOMIC:
            for _ in range(draw(st.integers(2, 3))):
                node(name, depth + 1)
            if kind is StateKind.COMPOUND:
                kids = [s.name for s in states if s.parent == name]
                first = draw(st.sampled_from(kids))
                s = states[index]
                states[index] = State(s.name, s.kind, s.parent, (first,), on_entry=s.on_entry)

    for _ in range(draw(st.integers(2, 3))):
        node(None, 0)
    names = [s.name for s in states]
    transitions = []
    for _ in range(draw(st.integers(3, 12))):
        source = draw(st.sampled_from(names))
        target = draw(st.sampled_from(names))
        targets = draw(st.sampled_from([(target,)] * 5 + [()]))
        event = draw(st.sampled_from(EVENTS))
        guard = draw(st.sampled_from(GUARDS))
        actions = draw(st.sampled_from([(), (Notify(1, "Beta", "Stop", event),)]))
        internal = draw(st.booleans())
        transitions.append(
            Transition(source, (event,), targets, guard, internal=internal, actions=actions)
        )
    ignored = frozenset(draw(st.lists(st.tuples(st.sampled_from(names), st.sampled_from(EVENTS)),
                                      max_size=3)))
    return Chart(
        "Random Dev",
        tuple(states),
        tuple(transitions),
        (draw(st.sampled_from([s.name for s in states if s.parent is None])),),
        events=tuple(EventDef(e) for e in EVENTS),
        invokes=INVOKES,
        ignored=ignored,
        data=(DataItem("x", "1"), DataItem("y", "0")),
    )


sequences = st.lists(
    st.tuples(
        st.fixed_dictionaries({"x": st.integers(-1, 3), "y": st.integers(-1, 3)}),
        st.lists(st.sampled_from(EVENTS), max_size=10),
    ),
    min_size=12,
    max_size=12,
)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chart=charts(), runs=sequences)
def test_random_charts_trace_like_python(chart: Chart, runs: list) -> None:  # type: ignore[type-arg]
    """For random charts and event sequences the C++ trace equals the Python runtime's."""
    with tempfile.TemporaryDirectory() as tmp:
        device = CppDevice(chart, Path(tmp))
        assert_equivalent(device, runs)


MOTOR_RUNS = [
    ({}, ["Movement", "Movement completion", "Initialization", "Initialization completion"]),
    ({}, ["Movement", "Error", "Error completion", "Initialization", "Movement"]),
    ({}, ["Initialization", "Error", "Movement completion", "Movement", "Movement",
          "Error completion", "Error"]),
    ({}, []),
]


def test_motor_traces_like_python(tmp_path: Path) -> None:
    """The Motor example: every scenario's C++ trace equals the Python runtime's."""
    device = CppDevice(load_chart(MOTOR), tmp_path)
    assert_equivalent(device, MOTOR_RUNS)


def _final_and_raise() -> Chart:
    """A compound whose final child raises done.state, and a transition that raises an event."""
    states = (
        State("Job", StateKind.COMPOUND, None, ("Work",)),
        State("Work", StateKind.ATOMIC, "Job"),
        State("Done", StateKind.FINAL, "Job"),
        State("Idle", StateKind.ATOMIC, None),
        State("End", StateKind.FINAL, None),
    )
    transitions = (
        Transition("Work", ("finish",), ("Done",), actions=(Raise("ping"),)),
        Transition("Job", ("done.state.Job",), ("Idle",), actions=(Notify(0, "Alpha", "Start",
                                                                          "done"),)),
        Transition("Idle", ("ping",), ("End",)),
        Transition("Idle", ("again",), ("Job",), guard="x > 2"),
    )
    return Chart("Job Runner", states, transitions, ("Job",),
                 events=(EventDef("finish"), EventDef("again")), invokes=INVOKES[:1],
                 data=(DataItem("x", "3"),))


@pytest.mark.parametrize(
    "runs",
    [
        [({"x": 3}, ["finish", "again", "finish"]), ({"x": 0}, ["again", "finish", "again"])],
    ],
)
def test_internal_events_and_final_states_trace_like_python(tmp_path: Path, runs: list) -> None:  # type: ignore[type-arg]
    """Raised events, done.state events and a top-level final state, as Python does them."""
    device = CppDevice(_final_and_raise(), tmp_path)
    assert_equivalent(device, runs)
