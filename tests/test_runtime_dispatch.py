"""Fast dispatch: Subject.dispatch, the plan path and the shared compiled machine.

The plan path must be invisible: the same configuration, counters, notifications
and device API calls as the full path, which runs whenever someone listens.
"""

from __future__ import annotations

import gc
from collections import deque
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from statectl.front.builder.build import load_chart
from statectl.kernel.errors import StatectlError, UnhandledEventError
from statectl.kernel.model import Chart, State, Transition
from statectl.kernel.semantics import Machine, Snapshot, compiled, initial, step
from statectl.run.devices import SimMotor
from statectl.run.runtime import Record, SimClock, StepRecord, Subject
from support import Recorder

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
EVENTS = (
    "Movement",
    "Movement completion",
    "Initialization",
    "Initialization completion",
    "Error",
    "Error completion",
    "Bogus",
)


def started(chart: Chart, *, listen: bool, **kw: Any) -> tuple[Subject, Recorder, list[Record]]:
    """A started Motor with a Recorder on every invoke; ``listen`` forces the full path."""
    subject = Subject(chart, clock=SimClock(), **kw)
    recorder = Recorder()
    subject.attach(recorder)
    records: list[Record] = []
    if listen:
        subject.listen(records.append)
    subject.start()
    return subject, recorder, records


def outcome(subject: Subject, recorder: Recorder) -> tuple[Any, ...]:
    return (
        subject.snapshot,
        subject.events_processed,
        subject.invokes_issued,
        subject.finished,
        recorder.seen,
    )


def test_dispatch_processes_the_event_before_returning(motor: Chart) -> None:
    """dispatch() commits the new state and calls the observer on the calling thread."""
    subject, recorder, _ = started(motor, listen=False)
    assert subject.dispatch("Movement", {"amount": 3}) == 1
    assert subject.configuration == {"Moving"}
    assert [(n.invoke, n.event, n.data) for n in recorder.seen] == [(0, "Movement", {"amount": 3})]


@pytest.mark.parametrize("listen", [False, True])
def test_dispatch_runs_after_what_is_queued(motor: Chart, listen: bool) -> None:
    """Events posted earlier run first, in order; the count covers them all."""
    subject, recorder, _ = started(motor, listen=listen)
    subject.post("Movement")
    assert subject.dispatch("Error") == 2
    assert subject.configuration == {"Returning"}
    assert [n.event for n in recorder.seen] == ["Movement", "Error"]


@pytest.mark.parametrize("warm", [False, True])
def test_events_an_observer_posts_run_to_completion_in_dispatch(motor: Chart, warm: bool) -> None:
    """An observer that posts a follow-up sees it processed within the same dispatch()."""
    subject = Subject(motor, clock=SimClock())
    subject.attach(Recorder(lambda n: subject.post("Movement completion")), invokes=[0])
    subject.start()
    if warm:  # plans exist for both events now
        subject.dispatch("Movement")
    assert subject.dispatch("Movement") == 2
    assert subject.configuration == {"Blocked"}


@pytest.mark.parametrize("warm", [False, True])
def test_dispatch_from_an_observer_is_refused(motor: Chart, warm: bool) -> None:
    """One owner, one event at a time: an observer must post(), not dispatch()."""
    subject = Subject(motor, clock=SimClock())
    subject.attach(Recorder(lambda n: subject.dispatch("Error")), invokes=[0])
    subject.start()
    if warm:  # a plan for Movement exists
        assert subject.snapshot is not None
        step(subject.machine, subject.snapshot, "Movement")
    with pytest.raises(StatectlError, match="while an event is being processed"):
        subject.dispatch("Movement")


@pytest.mark.parametrize(
    ("policy", "prefix", "event", "raises"),
    [
        ("ignore", (), "Bogus", None),
        ("ignore", (), "Movement completion", None),  # declared ignored in Blocked
        ("error", (), "Movement completion", None),  # declared ignored wins over the policy
        ("error", (), "Bogus", UnhandledEventError),
        ("ignore", (), 42, StatectlError),
        ("ignore", (), ["unhashable"], StatectlError),
    ],
)
def test_dispatch_reports_unhandled_events_as_post_does(
    motor: Chart, policy: str, prefix: tuple[str, ...], event: Any, raises: type | None
) -> None:
    """Unknown, ignored and rejected events behave the same, warm plans or not."""
    for _ in range(2):  # the second pass finds plans the first one left
        subject, _, _ = started(motor, listen=False, policy=policy)
        for e in prefix:
            subject.dispatch(e)
        before = subject.snapshot
        if raises is None:
            subject.dispatch(event)
        else:
            with pytest.raises(raises):
                subject.dispatch(event)
        assert subject.snapshot == before


@pytest.mark.parametrize(("policy", "raises"), [("ignore", None), ("error", UnhandledEventError)])
def test_an_event_without_transition_follows_the_policy_on_warm_plans(
    policy: str, raises: type | None
) -> None:
    """A memoised 'no transition' is dropped under ignore and raised under error, every time."""
    chart = Chart("ab", (State("a"), State("b")), (Transition("b", ("back",), ("a",)),), ("a",))
    for _ in range(3):
        subject = Subject(chart, clock=SimClock(), policy=policy)  # type: ignore[arg-type]
        subject.start()
        if raises is None:
            assert subject.dispatch("back") == 1
        else:
            with pytest.raises(raises):
                subject.dispatch("back")
        assert subject.configuration == {"a"} and subject.events_processed == 1


@pytest.mark.parametrize("data", [None, {"amount": 1}])
def test_plan_path_matches_the_full_path(motor: Chart, data: Any) -> None:
    """Same snapshot, counters and notifications with nobody listening as with a listener."""
    runs = []
    for listen in (False, True, False):
        subject, recorder, _ = started(motor, listen=listen)
        for e in (
            "Movement",
            "Movement completion",
            "Initialization",
            "Bogus",
            "Initialization completion",
            "Movement",
            "Error",
            "Error completion",
        ) * 2:
            subject.dispatch(e, data)
        runs.append(outcome(subject, recorder))
    assert runs[0] == runs[1] == runs[2]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(EVENTS), st.sampled_from([None, 1])), max_size=30))
def test_dispatch_and_post_agree_whatever_the_events(events: list[tuple[str, Any]]) -> None:
    """dispatch() without listeners folds to what post()+run_until_idle() with one gives."""
    chart = load_chart(MOTOR)
    fast, fast_rec, _ = started(chart, listen=False)
    slow, slow_rec, _ = started(chart, listen=True)
    for e, data in events:
        fast.dispatch(e, data)
        slow.post(e, data)
        slow.run_until_idle()
        assert fast.snapshot == slow.snapshot
    assert outcome(fast, fast_rec) == outcome(slow, slow_rec)


def demo_scenario(chart: Chart, listen: bool) -> tuple[Any, ...]:
    """The demo's story on a simulated motor, its fault posted by hand (no monitor)."""
    subject = Subject(chart, clock=SimClock())
    device = SimMotor()
    device.bind(subject.post, subject.clock)
    subject.attach(device)
    records: list[Record] = []
    if listen:
        subject.listen(records.append)
    subject.start()

    def settle() -> None:
        subject.advance(5.0)

    subject.dispatch("Movement", {"amount": 10})
    settle()
    subject.dispatch("Initialization")
    settle()
    subject.dispatch("Movement", {"amount": 10})
    subject.advance(0.4)
    subject.dispatch("Error")
    settle()
    subject.dispatch("Movement", {"target": 3})
    settle()
    return (
        subject.snapshot,
        subject.events_processed,
        subject.invokes_issued,
        tuple(device.api_log),
        device.position,
    )


def test_demo_scenario_is_the_same_both_ways(motor: Chart) -> None:
    """The device sees the same API calls at the same times with and without listeners."""
    quiet = demo_scenario(motor, listen=False)
    assert quiet == demo_scenario(motor, listen=True)
    assert quiet == demo_scenario(motor, listen=False)  # now on warm plans
    assert quiet[0].active == {"Blocked"} and quiet[3]


def test_data_less_notifications_follow_a_rename(motor: Chart) -> None:
    """A notification carries the Subject's current name even when it was prebuilt."""
    subject, recorder, _ = started(motor, listen=False)
    for e in ("Movement", "Movement completion", "Movement"):
        subject.dispatch(e)
    subject.name = "M2"
    subject.dispatch("Movement completion")
    subject.dispatch("Movement")
    assert [n.device for n in recorder.seen] == ["Motor", "Motor", "M2"]


def test_attach_after_plans_routes_new_notifications(motor: Chart) -> None:
    """Attaching an observer later takes effect on the plan path at once."""
    subject = Subject(motor, clock=SimClock())
    subject.start()
    for e in ("Movement", "Movement completion", "Movement", "Movement completion"):
        subject.dispatch(e)
    recorder = Recorder()
    subject.attach(recorder)
    subject.dispatch("Movement")
    assert [n.event for n in recorder.seen] == ["Movement"]
    assert subject.invokes_issued == 3


def test_instances_of_one_chart_share_its_machine(motor: Chart) -> None:
    """The chart is compiled once per process; an explorer's own Machine stays its own."""
    a = Subject(motor, clock=SimClock())
    b = Subject(motor, clock=SimClock())
    assert a.machine is b.machine is compiled(motor)
    assert Machine(motor) is not a.machine


def test_memoised_steps_become_plans_with_interned_targets(motor: Chart) -> None:
    """A memoised step is found in its snapshot's plan table, its target interned."""
    m = Machine(motor)
    s0 = initial(m).target
    first = step(m, s0, "Movement")
    plan = m.plans(s0)["Movement"]
    equal = Snapshot(frozenset(first.target.active), first.target.history, first.target.previous)
    assert plan.step is first and step(m, s0, "Movement") is first
    assert m.intern(equal) is plan.target is first.target
    assert plan.table is m.plans(equal)
    assert [a.invoke for _, a in plan.notifies] == [0]


def test_snapshot_guarded_steps_get_a_plan(motor: Chart) -> None:
    """A step whose guard reads only ``previous`` depends on (snapshot, event): it has a plan."""
    m = Machine(motor)
    blocked = m.intern(Snapshot(frozenset({"Blocked"}), (), "Moving"))
    taken = step(m, blocked, "Initialization")
    assert (taken.guarded, taken.handled) == (False, True)
    assert m.plans(blocked)["Initialization"].step is taken


def test_a_plan_carries_its_steps_entered_exited_and_reason(motor: Chart) -> None:
    """Hosts read what a planned step entered and exited, and why one was not handled."""
    m = Machine(motor)
    s0 = initial(m).target
    moved = step(m, s0, "Movement")
    ignored = step(m, moved.target, "Movement")
    plan, refused = m.plans(s0)["Movement"], m.plans(moved.target)["Movement"]
    assert (plan.entered, plan.exited, plan.unhandled) == (("Moving",), ("Blocked",), None)
    assert (refused.entered, refused.unhandled) == ((), ignored.unhandled)
    assert ignored.unhandled == "declared ignored"


#: What makes up a device: none of them may be left in a reference cycle.
_DEVICE_PARTS = {"Subject", "Engine", "Inbox", "Hooks", "Builder", "Program", "Bound"}


def _garbage_of(make: Any) -> set[str]:
    """The kinds of objects only the cyclic collector frees once ``make()``'s result is
    dropped (collected with the collector off meanwhile, so nothing is freed early)."""
    gc.collect()
    gc.disable()
    gc.set_debug(gc.DEBUG_SAVEALL)
    try:
        made = make()
        del made
        gc.collect()
        return {type(o).__name__ for o in gc.garbage}
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        gc.enable()


def test_a_dropped_device_is_freed_without_the_cyclic_collector(motor: Chart) -> None:
    """A device hooked to a host (a System's ready list), run through its queue, with
    events that changed nothing and typed records read, forms no reference cycle: the
    1,000-device bench paid for collecting thousands of them (its figure fell by a third
    after the rows before it)."""
    ready: deque[Subject] = deque()

    def make() -> Subject:
        subject = Subject(motor, clock=SimClock())
        subject.on_queued(ready.append)
        subject.attach(Recorder())
        steps: list[StepRecord] = []
        subject.listen_steps(steps.append)
        subject.start()
        for event in ("Movement", "Movement completion", "Bogus", "Movement", "Bogus"):
            subject.post(event)
            subject.run_until_idle()
        assert sum(len(s.records) for s in steps) > 0  # built: the builders compiled
        ready.clear()
        steps.clear()
        return subject

    assert _garbage_of(make) & _DEVICE_PARTS == set()


def test_an_event_bound_unheard_is_heard_by_a_listener_that_comes_later(motor: Chart) -> None:
    """An ignored event a device bound while nobody listened (it returns at once) still
    reaches an on_step listener and a step listener attached afterwards."""
    subject, _, _ = started(motor, listen=False)
    assert subject.dispatch("Movement completion") == 1  # ignored in Blocked, now bound
    outcomes: list[Any] = []
    subject.on_step(lambda _e, _d, outcome: outcomes.append(outcome))
    steps: list[StepRecord] = []
    subject.listen_steps(steps.append)
    subject.dispatch("Movement completion")
    assert outcomes == ["declared ignored"]
    assert [str(s.outcome) for s in steps] == ["declared ignored"]


def test_then_may_be_given_by_name_or_position(motor: Chart) -> None:
    """post() and dispatch() take ``then`` as an ordinary parameter (no keyword-only
    parameter: CPython 3.11 calls such a function on its slow path)."""
    subject, _, _ = started(motor, listen=False)
    heard: list[Any] = []
    subject.dispatch("Movement", None, heard.append)
    subject.post("Movement completion", then=heard.append)
    subject.run_until_idle()
    assert [str(o) for o in heard] == ["handled", "handled"]
