"""The kernel's executor hooks: content runs at the spec's points, in order, one semantics."""

from __future__ import annotations

from typing import Any

import pytest

from statectl.kernel.model import Action, Chart, Log, Raise, State, StateKind, Transition
from statectl.kernel.semantics import (
    Event,
    Machine,
    Run,
    enter_initial_states,
    initial,
    macrostep,
    process_event,
    step,
)


class Recorder:
    """An executor that records every call and performs ``Raise`` itself."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def condition(self, run: Run, transition: Transition) -> bool:
        self.calls.append(f"cond {transition.guard}")
        return transition.guard == "yes"

    def execute(self, run: Run, actions: tuple[Action, ...]) -> None:
        for a in actions:
            if isinstance(a, Log):
                self.calls.append(a.label)
            elif isinstance(a, Raise):
                run.raise_event(Event(a.event))

    def state_entered(self, run: Run, state: State) -> None:
        self.calls.append(f"enter {state.name}")

    def state_exited(self, run: Run, state: State) -> None:
        self.calls.append(f"exit {state.name}")

    def done_data(self, run: Run, state: State) -> Any:
        return {"from": state.name}


CHART = Chart(
    name="k",
    states=(
        State("a", StateKind.COMPOUND, on_exit=(Log("a.onexit"),), initial_actions=()),
        State("a1", parent="a", on_exit=(Log("a1.onexit"),)),
        State(
            "b",
            StateKind.COMPOUND,
            on_entry=(Log("b.onentry"), Raise("r")),
            initial_actions=(Log("b.initial"),),
        ),
        State("bf", StateKind.FINAL, parent="b", on_entry=(Log("bf.onentry"),)),
    ),
    transitions=(
        Transition("a1", ("go",), ("b",), guard="yes", actions=(Log("t.content"),)),
        Transition("b", ("r",), (), actions=(Log("saw r"),)),
        Transition("b", ("done.state.b",), (), actions=(Log("saw done"),)),
    ),
    initial=("a",),
    datamodel="python",
)


def test_executor_sees_the_spec_order() -> None:
    """Exit (deepest first), transition content, then per entered state: onentry, initial."""
    rec = Recorder()
    m = Machine(CHART)
    run = Run(set(), {}, None, {}, executor=rec)
    enter_initial_states(m, run)
    rec.calls.clear()
    process_event(m, run, Event("go", type="external"))
    assert rec.calls == [
        "cond yes",
        "a1.onexit",
        "exit a1",
        "a.onexit",
        "exit a",
        "t.content",
        "enter b",
        "b.onentry",
        "b.initial",
        "enter bf",
        "bf.onentry",
    ]


def test_raise_in_onentry_precedes_done_state() -> None:
    """A <raise> in an onentry is queued before the done.state of a final entered later."""
    rec = Recorder()
    m = Machine(CHART)
    run = Run(set(), {}, None, {}, executor=rec)
    enter_initial_states(m, run)
    process_event(m, run, Event("go", type="external"))
    assert [(e.name, e.data) for e in run.internal] == [
        ("r", None),
        ("done.state.b", {"from": "bf"}),
    ]
    rec.calls.clear()
    macrostep(m, run, [])
    assert rec.calls == ["saw r", "saw done"]


@pytest.mark.parametrize(
    ("event", "entered"),
    [("go", ("b", "bf")), ("other", ())],
)
def test_device_charts_stay_pure_and_memoised(event: str, entered: tuple[str, ...]) -> None:
    """Without an executor, step() returns the actions and caches unguarded steps."""
    chart = Chart(
        name="dev",
        states=(State("a"), State("b", StateKind.COMPOUND), State("bf", StateKind.FINAL, "b")),
        transitions=(Transition("a", ("go",), ("b",), actions=(Log("moving"),)),),
        initial=("a",),
    )
    m = Machine(chart)
    start = initial(m).target
    first = step(m, start, event)
    assert first.entered == entered
    assert step(m, start, event) is first
