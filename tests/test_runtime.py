"""The Subject: one owner, a queue, run-to-completion, specific notifications, records."""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from statectl.front.builder.build import load_chart
from statectl.kernel.errors import StatectlError, UnhandledEventError
from statectl.kernel.model import Chart, State, StateKind, Transition
from statectl.kernel.semantics import Machine, initial, step
from statectl.run.runtime import (
    EventIgnored,
    EventReceived,
    EventRejected,
    Finished,
    InvokeIssued,
    MicrostepTaken,
    ObserverCalled,
    Record,
    SimClock,
    Subject,
    Taken,
    WallClock,
)
from support import Recorder, record_keys

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
EVENTS = (
    "Movement",
    "Movement completion",
    "Initialization",
    "Initialization completion",
    "Error",
    "Error completion",
)


def running(chart: Chart, **kw: Any) -> tuple[Subject, list[Record]]:
    subject = Subject(chart, clock=SimClock(), **kw)
    records: list[Record] = []
    subject.listen(records.append)
    subject.start()
    return subject, records


keys = record_keys


def test_start_enters_the_initial_configuration(motor: Chart) -> None:
    """start() records Started and enters the default state."""
    subject, records = running(motor)
    assert subject.configuration == {"Blocked"}
    assert keys(records) == [("Started",), ("MicrostepTaken", None, (), (), ("Blocked",))]


def test_one_event_records_in_order(motor: Chart) -> None:
    """Received, the microstep (exited, transition, entered), then the invoke and the
    observer call."""
    subject, records = running(motor)
    subject.attach(Recorder())
    del records[:]
    subject.post("Movement", {"amount": 10})
    assert subject.run_until_idle() == 1
    assert keys(records) == [
        ("EventReceived", "Movement", {"amount": 10}),
        (
            "MicrostepTaken",
            "Movement",
            ("Blocked",),
            (Taken("Blocked", ("Moving",), "Movement"),),
            ("Moving",),
        ),
        ("InvokeIssued", 0, "Moving", "Movement", "Movement"),
        ("ObserverCalled", "Movement", "Recorder.update(#0)"),
    ]


def test_notification_goes_only_to_the_observer_of_its_invoke(motor: Chart) -> None:
    """The paper's specific notification: invoke #0 reaches the #0 observer and no other."""
    subject, _ = running(motor)
    mover, recoverer = Recorder(), Recorder()
    subject.attach(mover, invokes=[0])
    subject.attach(recoverer, invokes=[1, 2])
    for event in ("Movement", "Error"):
        subject.post(event, {"n": 1})
    subject.run_until_idle()
    assert [(n.invoke, n.method, n.event, n.data) for n in mover.seen] == [
        (0, "Movement", "Movement", {"n": 1})
    ]
    assert [(n.invoke, n.name, n.method) for n in recoverer.seen] == [(2, "Error", "Error")]


@pytest.mark.parametrize(
    ("invokes", "message"),
    [([0], "already claimed"), ([7], "no invoke number")],
)
def test_attach_refuses_bad_claims(motor: Chart, invokes: list[int], message: str) -> None:
    """An invoke number has one observer, and must exist in the chart."""
    subject = Subject(motor, clock=SimClock())
    subject.attach(Recorder(), invokes=[0])
    with pytest.raises(StatectlError, match=message):
        subject.attach(Recorder(), invokes=invokes)


def _without_ignores(chart: Chart) -> Chart:
    return dataclasses.replace(chart, ignored=frozenset())


@pytest.mark.parametrize(
    ("strip", "event", "reason"),
    [
        (False, "Error", "declared ignored"),
        (False, "Initialization", "declared ignored"),  # its guard is false: ignored as listed
        (True, "Initialization", "guard false"),  # not listed: the guard is the reason
        (True, "Error", "no transition"),
        (False, "Jump", "unknown event"),
    ],
)
def test_unhandled_events_are_recorded_with_their_reason(
    motor: Chart, strip: bool, event: str, reason: str
) -> None:
    """Under policy ignore, an event that changes nothing says why."""
    subject, records = running(_without_ignores(motor) if strip else motor)
    del records[:]
    subject.post(event)
    subject.run_until_idle()
    assert keys(records) == [("EventReceived", event, None), ("EventIgnored", event, reason)]
    assert subject.configuration == {"Blocked"}


@pytest.mark.parametrize(
    ("strip", "event", "reason"),
    [
        (True, "Initialization", "guard false"),
        (True, "Error", "no transition"),
        (False, "Jump", "unknown event"),
    ],
)
def test_policy_error_rejects_and_raises(
    motor: Chart, strip: bool, event: str, reason: str
) -> None:
    """Under policy error an unhandled event is recorded as rejected and raised."""
    subject, records = running(_without_ignores(motor) if strip else motor, policy="error")
    subject.post(event)
    with pytest.raises(UnhandledEventError, match=reason):
        subject.run_until_idle()
    assert isinstance(records[-1], EventRejected) and records[-1].reason == reason


def test_policy_error_still_lets_declared_ignores_pass(motor: Chart) -> None:
    """An event the state table declares ignored is not an error under policy error."""
    subject, records = running(motor, policy="error")
    subject.post("Error")
    subject.run_until_idle()
    assert isinstance(records[-1], EventIgnored)


def test_events_after_a_rejected_one_stay_queued(motor: Chart) -> None:
    """A raise stops the drain at the bad event; the next call processes the rest."""
    subject, _ = running(motor, policy="error")
    subject.post("Jump")
    subject.post("Movement", {"amount": 1})
    with pytest.raises(UnhandledEventError):
        subject.run_until_idle()
    assert subject.queued == 1
    subject.run_until_idle()
    assert subject.configuration == {"Moving"}


def test_event_posted_by_an_observer_runs_after_the_current_one(motor: Chart) -> None:
    """Run-to-completion: an event posted during a step is processed after it."""
    subject, records = running(motor)
    subject.attach(Recorder(then=lambda n: subject.post("Movement completion")))
    del records[:]
    subject.post("Movement", {"amount": 1})
    assert subject.run_until_idle() == 2
    order = [type(r).__name__ for r in records]
    assert order.index("ObserverCalled") < order.index("EventReceived", 1)
    assert subject.configuration == {"Blocked"}


def test_processing_before_start_is_refused(motor: Chart) -> None:
    """Events wait in the queue until start(); draining before it is a misuse."""
    subject = Subject(motor, clock=SimClock())
    subject.post("Movement")
    with pytest.raises(StatectlError, match="start"):
        subject.run_until_idle()


def test_close_records_finished_and_refuses_posts(motor: Chart) -> None:
    """close() ends the run once; a later post is an error, not a silent drop."""
    subject, records = running(motor)
    subject.close()
    subject.close()
    assert [type(r) for r in records].count(Finished) == 1
    with pytest.raises(StatectlError, match="closed"):
        subject.post("Movement")


def test_reaching_a_top_level_final_state_finishes_the_run() -> None:
    """Entering a top-level final state records Finished."""
    chart = Chart(
        "Once",
        (State("a"), State("done", StateKind.FINAL)),
        (Transition("a", ("go",), ("done",)),),
        ("a",),
    )
    subject, records = running(chart)
    subject.post("go")
    subject.run_until_idle()
    assert isinstance(records[-1], Finished) and subject.finished


def test_guards_read_the_subjects_data() -> None:
    """Data given to the Subject is the datamodel guards read."""
    chart = Chart(
        "Gate",
        (State("shut"), State("open")),
        (Transition("shut", ("push",), ("open",), guard="force > 5"),),
        ("shut",),
    )
    for force, expected in ((10, {"open"}), (1, {"shut"})):
        subject, _ = running(chart, data={"force": force})
        subject.post("push")
        subject.run_until_idle()
        assert subject.configuration == expected


def test_bad_policy_is_refused(motor: Chart) -> None:
    """The policy is 'ignore' or 'error'."""
    with pytest.raises(StatectlError, match="policy"):
        Subject(motor, clock=SimClock(), policy="strict")  # type: ignore[arg-type]


def test_no_records_are_built_when_nobody_listens(
    motor: Chart, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The hot path builds no record without a listener."""
    import statectl.run.runtime.engine as engine
    import statectl.run.runtime.subject as mod

    def refuse(*args: object) -> None:
        raise AssertionError("record built")

    for module in (mod, engine):  # the Subject owns, its engine performs
        for name in ("EventReceived", "MicrostepTaken", "Taken", "taken"):
            if hasattr(module, name):
                monkeypatch.setattr(module, name, refuse)
    subject = Subject(motor, clock=SimClock())
    subject.start()
    for event in ("Movement", "Movement completion", "Jump"):
        subject.post(event, {"amount": 1})
    assert subject.run_until_idle() == 3
    assert subject.configuration == {"Blocked"}


def test_posts_from_many_threads_are_all_processed(motor: Chart) -> None:
    """post() is safe from any thread and loses nothing."""
    subject, records = running(motor)
    threads = [
        threading.Thread(target=lambda: [subject.post("Jump") for _ in range(200)])
        for _ in range(8)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert subject.run_until_idle() == 1600
    assert sum(isinstance(r, EventIgnored) for r in records) == 1600


def test_worker_owns_the_subject_and_survives_errors(motor: Chart) -> None:
    """In worker mode a rejected event goes to the error callback; the worker goes on."""
    clock = WallClock()
    subject = Subject(motor, clock=clock, policy="error")
    errors: list[BaseException] = []
    moved = threading.Event()
    subject.listen(
        lambda r: (
            moved.set() if isinstance(r, MicrostepTaken) and r.entered == ("Moving",) else None
        )
    )
    subject.start_worker(on_error=errors.append)
    subject.post("Jump")
    subject.post("Movement", {"amount": 1})
    assert moved.wait(5.0)
    with pytest.raises(StatectlError, match="worker"):
        subject.run_until_idle()
    subject.close()
    clock.stop()
    assert [type(e) for e in errors] == [UnhandledEventError]
    assert subject.configuration == {"Moving"}


@settings(max_examples=60, deadline=None)
@given(st.lists(st.sampled_from(EVENTS), max_size=25))
def test_subject_follows_the_pure_semantics(events: list[str]) -> None:
    """Whatever the events, the Subject's configuration is the fold of semantics.step,
    and each received event is followed by exactly one transition or ignore record."""
    chart = load_chart(MOTOR)
    machine = Machine(chart)
    snapshot = initial(machine).target
    subject, records = running(chart)
    for e in events:
        subject.post(e)
        subject.run_until_idle()
        snapshot = step(machine, snapshot, e).target
        assert subject.configuration == snapshot.active
    received = [i for i, r in enumerate(records) if isinstance(r, EventReceived)]
    assert len(received) == len(events)
    for i in received:
        follow = records[i + 1]
        assert isinstance(follow, MicrostepTaken | EventIgnored)
    assert sum(isinstance(r, InvokeIssued) for r in records) == subject.invokes_issued
    assert not [r for r in records if isinstance(r, ObserverCalled)]  # nobody attached
