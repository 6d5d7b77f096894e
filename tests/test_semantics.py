"""The pure kernel: one external event in, one decision out, W3C SCXML rules."""

from __future__ import annotations

import re

import pytest

from statectl.kernel.model import Chart, EventDef, Notify, Raise, State, StateKind, Transition
from statectl.kernel.semantics import (
    LivelockError,
    Machine,
    Snapshot,
    Unhandled,
    initial,
    name_match,
    step,
)

A, CP, P, F = StateKind.ATOMIC, StateKind.COMPOUND, StateKind.PARALLEL, StateKind.FINAL
HS, HD = StateKind.HISTORY_SHALLOW, StateKind.HISTORY_DEEP


def chart(
    rows: str,
    states: list[State],
    initial_: tuple[str, ...] = (),
    ignored: frozenset[tuple[str, str]] = frozenset(),
) -> Chart:
    """Build a chart from Boost.SML-like rows: ``src + event [guard] / !raise = dst``."""
    transitions = []
    for line in rows.strip().splitlines():
        line = line.strip()
        left, _, dst = line.rpartition(" = ")
        src, _, rest = left.partition("+")
        guard = None
        if "[" in rest:
            rest, _, g = rest.partition("[")
            guard = g.rstrip("] /!").strip() or None
            g_tail = g.partition("]")[2]
        else:
            g_tail = rest
        actions = tuple(Raise(a.strip()) for a in g_tail.split("!")[1:])
        event = rest.split("/")[0].strip()
        transitions.append(
            Transition(
                src.strip(),
                (event,) if event else (),
                tuple(dst.split()),
                guard=guard,
                actions=actions,
            )
        )
    return Chart("t", tuple(states), tuple(transitions), initial_, ignored=ignored)


def run(c: Chart, events: list[str]) -> list[frozenset[str]]:
    m = Machine(c)
    snap = initial(m).target
    out = [snap.active]
    for e in events:
        snap = step(m, snap, e).target
        out.append(snap.active)
    return out


def motor() -> Chart:
    rows = """
        Blocked + Movement = Moving
        Moving + Movement completion = Blocked
        Blocked + Initialization [previous == 'Moving'] = Returning
        Returning + Initialization completion = Blocked
        Moving + Error = Returning
        Returning + Error completion = Blocked
    """
    c = chart(
        rows,
        [State("Blocked"), State("Moving"), State("Returning")],
        ("Blocked",),
        ignored=frozenset({("Moving", "Movement")}),
    )
    return c


@pytest.mark.parametrize(
    ("events", "final"),
    [
        ([], "Blocked"),
        (["Movement"], "Moving"),
        (["Movement", "Movement completion"], "Blocked"),
        (["Initialization"], "Blocked"),  # guard: previous state was not Moving
        (["Movement", "Movement completion", "Initialization"], "Returning"),
        (["Movement", "Error", "Error completion", "Initialization"], "Blocked"),
        (["Movement", "Error", "Error completion"], "Blocked"),
        (["Movement", "Movement"], "Moving"),
    ],
)
def test_motor_sequences(events: list[str], final: str) -> None:
    """The paper's Motor follows its Event Definition table, guard included."""
    assert run(motor(), events)[-1] == {final}


def test_unhandled_event_reports_ignored_flag() -> None:
    """An unhandled event leaves the snapshot unchanged and says whether it was declared ignored."""
    m = Machine(motor())
    moving = step(m, initial(m).target, "Movement").target
    declared = step(m, moving, "Movement")
    undeclared = step(m, moving, "Initialization completion")
    assert (declared.handled, declared.ignored, declared.target) == (False, True, moving)
    assert (undeclared.handled, undeclared.ignored) == (False, False)


def test_previous_is_the_atomic_state_left() -> None:
    """``previous`` records the state the last transition left, for guards."""
    m = Machine(motor())
    s = initial(m).target
    s = step(m, s, "Movement").target
    assert s.previous == "Blocked"
    s = step(m, s, "Movement completion").target
    assert s.previous == "Moving"


def test_steps_decided_by_the_snapshot_are_memoised() -> None:
    """A step that consulted no guard, or only ``previous``/``In()``, is cached as a value."""
    m = Machine(motor())
    s0 = initial(m).target
    assert step(m, s0, "Movement") is step(m, s0, "Movement")
    after_moving = Snapshot(frozenset({"Blocked"}), (), "Moving")
    g = step(m, after_moving, "Initialization")
    assert (g.guarded, g.handled) == (False, True)
    assert step(m, after_moving, "Initialization") is g
    refused = step(m, Snapshot(frozenset({"Blocked"}), (), "Blocked"), "Initialization")
    assert (refused.handled, refused.unhandled) == (False, Unhandled.GUARD_FALSE)


def estop() -> Chart:
    """An E-stop superstate that preempts everything inside Operating."""
    states = [
        State("Operating", CP, initial=("Idle",)),
        State("Idle", parent="Operating"),
        State("Working", CP, parent="Operating", initial=("Fast",)),
        State("Fast", parent="Working"),
        State("Slow", parent="Working"),
        State("H", HS, parent="Operating", history_default=("Idle",)),
        State("Stopped"),
    ]
    rows = """
        Operating + estop = Stopped
        Idle + go = Working
        Fast + slow = Slow
        Working + go = Idle
        Stopped + reset = Operating
        Stopped + resume = H
    """
    return chart(rows, states, ("Operating",))


@pytest.mark.parametrize(
    ("events", "expected"),
    [
        ([], {"Operating", "Idle"}),
        (["go"], {"Operating", "Working", "Fast"}),
        (["go", "slow", "estop"], {"Stopped"}),
        (["go", "slow", "estop", "reset"], {"Operating", "Idle"}),
        (["go", "slow", "estop", "resume"], {"Operating", "Working", "Fast"}),  # shallow
        (["resume"], {"Operating", "Idle"}),
        (["go", "go"], {"Operating", "Idle"}),  # parent handles what the child does not
    ],
)
def test_hierarchy_and_shallow_history(events: list[str], expected: set[str]) -> None:
    """A superstate's transition preempts its descendants; shallow history restores one level."""
    assert run(estop(), events)[-1] == expected


def test_deep_history_restores_leaves() -> None:
    """Deep history restores the atomic descendants, not only the child."""
    c = estop()
    states = tuple(
        State("H", HD, parent="Operating", history_default=("Idle",)) if s.name == "H" else s
        for s in c.states
    )
    c = Chart(c.name, states, c.transitions, c.initial)
    assert run(c, ["go", "slow", "estop", "resume"])[-1] == {"Operating", "Working", "Slow"}


def test_exit_and_entry_order() -> None:
    """Exit goes innermost first; entry outermost first (document order)."""
    m = Machine(estop())
    s = step(m, initial(m).target, "go").target
    st = step(m, s, "estop")
    assert st.exited == ("Fast", "Working", "Operating")
    back = step(m, st.target, "resume")
    assert back.entered == ("Operating", "Working", "Fast")


def cell() -> Chart:
    """Two regions working at once, each with a final state."""
    states = [
        State("Run", P),
        State("Arm", CP, parent="Run", initial=("ArmIdle",)),
        State("ArmIdle", parent="Arm"),
        State("ArmDone", F, parent="Arm"),
        State("Grip", CP, parent="Run", initial=("Open",)),
        State("Open", parent="Grip"),
        State("Closed", F, parent="Grip"),
        State("Done"),
    ]
    rows = """
        ArmIdle + place = ArmDone
        Open + close = Closed
        Run + done.state.Run = Done
    """
    return chart(rows, states, ("Run",))


def test_parallel_regions_and_done_events() -> None:
    """Both regions are active; when each reaches final, done.state of the parallel fires."""
    trace = run(cell(), ["place", "close"])
    assert trace[0] == {"Run", "Arm", "ArmIdle", "Grip", "Open"}
    assert trace[1] == {"Run", "Arm", "ArmDone", "Grip", "Open"}
    assert trace[2] == {"Done"}


def test_one_event_taken_in_both_regions() -> None:
    """An event handled in two regions fires both transitions in one microstep."""
    states = [
        State("R", P),
        State("A", CP, parent="R"),
        State("a1", parent="A"),
        State("a2", parent="A"),
        State("B", CP, parent="R"),
        State("b1", parent="B"),
        State("b2", parent="B"),
    ]
    c = chart("a1 + tick = a2\nb1 + tick = b2", states, ("R",))
    m = Machine(c)
    st = step(m, initial(m).target, "tick")
    assert len(st.microsteps) == 1 and len(st.transitions) == 2
    assert st.target.active == {"R", "A", "a2", "B", "b2"}


def test_conflict_descendant_preempts() -> None:
    """Of two conflicting transitions, the one from the descendant state wins."""
    states = [State("P", CP), State("c", parent="P"), State("x"), State("y")]
    c = chart("c + e = x\nP + e = y", states, ("P",))
    assert run(c, ["e"])[-1] == {"x"}


def test_raise_and_eventless_run_to_completion() -> None:
    """Raised events and eventless transitions settle inside one step, in order."""
    states = [State("s0"), State("s1"), State("s2"), State("s3")]
    c = chart("s0 + go / !next = s1\ns1 + next = s2\ns2 + [True] = s3", states, ("s0",))
    m = Machine(c)
    st = step(m, initial(m).target, "go")
    assert [ms.event for ms in st.microsteps] == ["go", "next", None]
    assert st.target.active == {"s3"}


def test_eventless_loop_is_a_livelock_error() -> None:
    """Eventless transitions that never settle raise LivelockError instead of hanging."""
    c = chart("a + [True] = b\nb + [True] = a", [State("a"), State("b")], ("a",))
    with pytest.raises(LivelockError, match="microsteps"):
        initial(Machine(c))


def test_top_level_final_ends_the_run() -> None:
    """Entering a top-level final state marks the step final."""
    c = chart("a + stop = end", [State("a"), State("end", F)], ("a",))
    m = Machine(c)
    assert step(m, initial(m).target, "stop").final


def test_notify_actions_are_returned_not_performed() -> None:
    """A transition's Notify action comes back in the step, in order, for the runtime."""
    n = Notify(0, "Moving", "Movement", "Movement")
    c = Chart(
        "m",
        (State("B"), State("M")),
        (Transition("B", ("Movement",), ("M",), actions=(n,)),),
        ("B",),
    )
    m = Machine(c)
    assert step(m, initial(m).target, "Movement").actions == (n,)


@pytest.mark.parametrize(
    ("descriptors", "event", "expected"),
    [
        (("error",), "error", True),
        (("error",), "error.execution", True),
        (("error",), "errors", False),
        (("error.*",), "error.execution", True),
        (("*",), "anything", True),
        (("a", "b"), "b", True),
        (("Movement",), "Movement completion", False),
    ],
)
def test_name_match(descriptors: tuple[str, ...], event: str, expected: bool) -> None:
    """SCXML event descriptors match by dotted prefix token, or '*'."""
    assert name_match(descriptors, event) is expected


@pytest.mark.parametrize(
    ("parent_kind", "entered"),
    [
        (StateKind.COMPOUND, {"P", "A"}),  # the compound's initial state
        (StateKind.PARALLEL, {"P", "A", "B"}),  # every region of the parallel state
    ],
)
def test_a_history_without_default_enters_what_its_parent_enters(
    parent_kind: StateKind, entered: set[str]
) -> None:
    """W3C requires a default transition on <history>; without one, the first entry of the
    history state enters the parent's default instead of no child at all."""
    chart = Chart(
        "H",
        (
            State("P", parent_kind, None, ("A",) if parent_kind is StateKind.COMPOUND else ()),
            State("A", parent="P"),
            State("B", parent="P"),
            State("H", StateKind.HISTORY_SHALLOW, "P"),
            State("Q"),
        ),
        (Transition("Q", ("go",), ("H",)),),
        ("Q",),
        events=(EventDef("go"),),
    )
    m = Machine(chart)
    after = step(m, initial(m, {}).target, "go", {}, None)
    assert set(after.target.active) == entered


def data_chart() -> Chart:
    """Blocked moves on Go when ``speed > 3``, else Idle handles it; ``_event`` picks Fast."""
    from statectl.kernel.model import DataItem

    rows = """
        Blocked + Go [speed > 3] = Moving
        Blocked + Go [previous == 'Moving'] = Idle
        Moving + Stop = Blocked
        Blocked + Jump [_event['data'] == 'fast'] = Fast
        Fast + Stop = Blocked
    """
    states = [State("Blocked"), State("Moving"), State("Idle"), State("Fast")]
    c = chart(rows, states, ("Blocked",))
    return Chart(c.name, c.states, c.transitions, c.initial, data=(DataItem("speed", "0"),))


# (speed, event, event data, previous, expected target atomic state or None: not handled)
DATA_CASES = [
    (5, "Go", None, None, "Moving"),
    (1, "Go", None, None, None),
    (1, "Go", None, "Moving", "Idle"),
    (5, "Go", None, "Moving", "Moving"),
    (5, "Go", None, None, "Moving"),  # the memoised path again, same answer
    (0, "Jump", "fast", None, "Fast"),
    (0, "Jump", "slow", None, None),
    (0, "Jump", "fast", None, "Fast"),
]


def test_data_guards_are_re_evaluated_on_every_memoised_step() -> None:
    """A step whose guards read data or event data answers each call by that call's values."""
    m = Machine(data_chart())
    got = []
    for speed, event, edata, previous, _ in DATA_CASES:
        snap = Snapshot(frozenset({"Blocked"}), (), previous)
        result = step(m, snap, event, {"speed": speed}, edata)
        got.append(next(iter(result.target.active)) if result.handled else None)
    assert got == [case[-1] for case in DATA_CASES]


def test_a_data_guarded_step_is_not_rebuilt_when_its_guards_answer_as_before() -> None:
    """The second call with the same guard outcomes returns the step already built."""
    m = Machine(data_chart())
    snap = Snapshot(frozenset({"Blocked"}), (), None)
    first = step(m, snap, "Go", {"speed": 5})
    assert first.guarded
    assert step(m, snap, "Go", {"speed": 9}) is first
    assert step(m, snap, "Go", {"speed": 1}) is not first


# (what the oracle answers for every guard, expected target of Go from Blocked or None)
ORACLE_CASES = [(True, "Moving"), (False, None), (None, None)]


@pytest.mark.parametrize(("forced", "expected"), ORACLE_CASES)
def test_a_guard_oracle_forces_outcomes_and_is_never_memoised(
    forced: bool | None, expected: str | None
) -> None:
    """The oracle's answer replaces the guard's value; ``None`` lets the kernel evaluate it."""
    m = Machine(data_chart())
    snap = Snapshot(frozenset({"Blocked"}), (), None)
    asked = []

    def oracle(run: object, t: Transition) -> bool | None:
        asked.append(t.guard)
        return forced

    result = step(m, snap, "Go", {"speed": 0}, oracle=oracle)
    assert (next(iter(result.target.active)) if result.handled else None) == expected
    assert asked and not m._memo and not m._guarded


def test_the_unhandled_reason_is_the_kernels() -> None:
    """Not handled: declared ignored, guard false or no transition, one enum, said by step."""
    m = Machine(motor())
    moving = Snapshot(frozenset({"Moving"}))
    blocked = Snapshot(frozenset({"Blocked"}), (), "Blocked")
    cases = [
        (moving, "Movement", Unhandled.DECLARED_IGNORED),
        (blocked, "Initialization", Unhandled.GUARD_FALSE),
        (moving, "Initialization completion", Unhandled.NO_TRANSITION),
        (blocked, "Movement", None),
    ]
    assert [step(m, s, e).unhandled for s, e, _ in cases] == [c[-1] for c in cases]
    assert Unhandled.GUARD_FALSE == "guard false"  # stored and shown as its value


def test_entry_set_enters_every_region_of_a_parallel_target() -> None:
    """The kernel's entry set of a transition into a parallel state holds each region's default."""
    from statectl.kernel.semantics import entry_set

    states = [
        State("Idle"),
        State("Run", kind=P),
        State("Axis", parent="Run", kind=CP, initial=("AxisHome",)),
        State("AxisHome", parent="Axis"),
        State("Gripper", parent="Run", kind=CP, initial=("Open",)),
        State("Open", parent="Gripper"),
    ]
    c = chart("Idle + Go = Run", states, ("Idle",))
    m = Machine(c)
    assert entry_set(m, list(c.transitions)) == (
        "Run",
        "Axis",
        "AxisHome",
        "Gripper",
        "Open",
    )
    assert entry_set(m, []) == ("Idle",)


def _with_data(*items: tuple[str, str]) -> Chart:
    from statectl.kernel.model import DataItem

    c = chart("Idle + Go = Idle", [State("Idle")], ("Idle",))
    return Chart(
        c.name, c.states, c.transitions, c.initial, data=tuple(DataItem(*i) for i in items)
    )


def test_initial_data_evaluates_each_item_over_the_earlier_ones_and_given_values_win() -> None:
    """One answer for every host: in order, an item may read the ones before it."""
    from statectl.kernel.semantics import initial_data

    c = _with_data(("speed", "2"), ("top", "speed * 10"), ("none", ""))
    assert initial_data(c) == {"speed": 2, "top": 20, "none": None}
    assert initial_data(c, {"speed": 5}) == {"speed": 5, "top": 50, "none": None}


@pytest.mark.parametrize(
    ("expr", "said"),
    [
        ("speed +", "data 'speed +' does not parse"),
        ("1 // 0", "data item 'top' = '1 // 0' fails: integer division"),
    ],
)
def test_initial_data_refuses_an_item_that_does_not_compile_or_evaluate(
    expr: str, said: str
) -> None:
    """A clear StatectlError, never a raw ZeroDivisionError from the runtime's start."""
    from statectl.kernel.errors import StatectlError
    from statectl.kernel.semantics import initial_data

    with pytest.raises(StatectlError, match=re.escape(said)):
        initial_data(_with_data(("speed", "1"), ("top", expr)))
