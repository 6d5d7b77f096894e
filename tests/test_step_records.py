"""Step records: one object per event, whose typed records equal those listen() gets.

A listen_steps() listener must see exactly what a listen() listener sees, in the same
order (rule 3 of runtime/records.py), however the device is wired; only the number of
objects and when they are built differ.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from typing import Any

import pytest

from statectl.front.observers import Notification
from statectl.kernel.errors import UnhandledEventError
from statectl.kernel.model import Chart, InvokeNumber, Notify, State, StateKind, Transition
from statectl.kernel.semantics import Unhandled
from statectl.run.runtime import (
    ApiCall,
    EventIgnored,
    MonitorStarted,
    ObserverCalled,
    Record,
    SimClock,
    StepRecord,
    Subject,
)
from support import PAPER_CYCLE, Recorder, wire_motor

STRAYS = (("Movement completion", None), ("No such event", None), ("Movement", {"amount": 1}))


class Failing:
    """An observer whose device call fails."""

    def update(self, notification: Notification) -> None:
        raise RuntimeError("the device is gone")


def _run(
    chart: Chart,
    wiring: str,
    events: tuple[tuple[str, Any], ...],
    hear: Callable[[Subject, list[Record], list[StepRecord]], None],
    policy: str = "ignore",
) -> tuple[list[Record], list[StepRecord], str]:
    subject = Subject(chart, clock=SimClock(), policy=policy)  # type: ignore[arg-type]
    wire_motor(subject, wiring)
    typed: list[Record] = []
    steps: list[StepRecord] = []
    hear(subject, typed, steps)
    subject.start()
    ending = "ok"
    for event, data in events:
        try:
            subject.dispatch(event, data)
        except (UnhandledEventError, RuntimeError) as exc:
            ending = type(exc).__name__
    subject.close()
    return typed, steps, ending


def _typed(subject: Subject, typed: list[Record], steps: list[StepRecord]) -> None:
    subject.listen(typed.append)


def _stepped(subject: Subject, typed: list[Record], steps: list[StepRecord]) -> None:
    subject.listen_steps(steps.append)


@pytest.mark.parametrize("wiring", ["bare", "monitor", "driver", "nobody"])
@pytest.mark.parametrize(
    "events", [PAPER_CYCLE, PAPER_CYCLE + STRAYS], ids=["paper", "with-strays"]
)
@pytest.mark.parametrize("policy", ["ignore", "error"])
def test_step_records_hold_the_records_listen_gets(
    motor: Chart, wiring: str, events: tuple[tuple[str, Any], ...], policy: str
) -> None:
    """The typed records of the step records are listen()'s, in order, one step record
    per event (plus one per record made outside an event: Started, Finished)."""
    want, _, end_typed = _run(motor, wiring, events, _typed, policy)
    _, steps, end_steps = _run(motor, wiring, events, _stepped, policy)
    got = [r for s in steps for r in s.records]
    assert got == want
    assert end_steps == end_typed
    per_event = [s for s in steps if s.event is not None]
    assert [s.event for s in per_event] == [e for e, _ in events]


def test_a_step_record_says_what_happened_without_building_records(motor: Chart) -> None:
    """outcome, entered and exited come from the step; records are built when first read."""
    _, steps, _ = _run(motor, "monitor", PAPER_CYCLE + STRAYS[:1], _stepped)
    moved = next(s for s in steps if s.event == "Movement")
    assert (moved.outcome, moved.entered, moved.exited) == ("handled", ("Moving",), ("Blocked",))
    assert moved._records is None  # nothing read it yet
    assert any(isinstance(r, MonitorStarted) for r in moved)
    stray = steps[-2]  # the last event; close() made the last record
    assert (stray.event, stray.outcome, stray.step) == (
        "Movement completion",
        "declared ignored",
        None,
    )
    assert [type(r) for r in stray.records][-1] is EventIgnored


def test_a_failing_observer_ends_the_step_record_where_listen_ends(motor: Chart) -> None:
    """When the device call raises, the step record holds the records made until then."""

    def failing(subject: Subject) -> None:
        subject.attach(Failing())

    results = []
    for hear in (_typed, _stepped):
        subject = Subject(motor, clock=SimClock())
        failing(subject)
        typed: list[Record] = []
        steps: list[StepRecord] = []
        hear(subject, typed, steps)
        subject.start()
        with pytest.raises(RuntimeError):
            subject.dispatch("Movement", {"amount": 1})
        results.append(typed or [r for s in steps for r in s.records])
    assert results[0] == results[1]
    assert type(results[0][-1]).__name__ == "InvokeIssued"


def test_a_final_state_ends_the_step_record_with_finished() -> None:
    """A step that reaches a final state closes its records with Finished, once."""
    chart = Chart(
        "Once",
        (State("Idle"), State("Done", StateKind.FINAL)),
        (Transition("Idle", ("go",), ("Done",)),),
        ("Idle",),
    )
    want, _, _ = _run(chart, "nobody", (("go", None),), _typed)
    _, steps, _ = _run(chart, "nobody", (("go", None),), _stepped)
    assert [r for s in steps for r in s.records] == want
    assert [s.final for s in steps if s.event == "go"] == [True]


def test_stopping_step_records_stops_them(motor: Chart) -> None:
    """The undo listen_steps() returns stops the records."""
    subject = Subject(motor, clock=SimClock())
    steps: list[StepRecord] = []
    off = subject.listen_steps(steps.append)
    subject.start()
    subject.dispatch("Movement", {"amount": 1})
    off()
    subject.dispatch("Movement completion")
    assert [s.event for s in steps] == [None, None, "Movement"]  # Started, Blocked entered


@pytest.mark.parametrize("wiring", ["bare", "monitor", "driver"])
def test_with_a_listen_listener_too_both_get_the_same_records(motor: Chart, wiring: str) -> None:
    """With listen() attached as well, step listeners still get every record, in order."""

    def both(subject: Subject, typed: list[Record], steps: list[StepRecord]) -> None:
        subject.listen(typed.append)
        subject.listen_steps(steps.append)

    typed, steps, _ = _run(motor, wiring, PAPER_CYCLE + STRAYS, both)
    assert [r for s in steps for r in s.records] == typed


def test_a_record_made_by_a_step_listener_comes_after_the_step(motor: Chart) -> None:
    """A step listener that records something gets it after the step record it is given."""
    subject = Subject(motor, clock=SimClock())
    subject.attach(Recorder())
    heard: list[str | None] = []

    def hear(step: StepRecord) -> None:
        heard.append(step.event)
        if step.event == "Movement":
            subject.emit(EventIgnored(subject.name, 0.0, "note", Unhandled.NO_TRANSITION))

    subject.listen_steps(hear)
    subject.start()
    subject.dispatch("Movement", {"amount": 1})
    subject.dispatch("Movement completion")
    assert heard == [None, None, "Movement", None, "Movement completion"]


class TwoCalls:
    """An observer that logs two API calls per notification (as a driver logs them)."""

    def __init__(self) -> None:
        self.api_log: list[ApiCall] = []

    def update(self, notification: Notification) -> None:
        for n in (1, 2):
            self.api_log.append(ApiCall(0.0, "Rig", notification.method, (n,)))


def _rig() -> Chart:
    """Going On notifies two observers, in order, one of them again on the way back."""
    reach, run = Notify(0, "Reach", "Reach", "go"), Notify(1, "Run", "Run", "go")
    return Chart(
        "Rig",
        (State("Off"), State("On")),
        (
            Transition("Off", ("go",), ("On",), actions=(reach, run)),
            Transition("On", ("stop",), ("Off",), actions=(Notify(1, "Run", "Run", "stop"),)),
        ),
        ("Off",),
        invokes=(InvokeNumber(0, "Reach", "Reach"), InvokeNumber(1, "Run", "Run")),
    )


def test_a_planned_step_unheard_issues_every_notification_in_order() -> None:
    """A plan with two notifications, nobody listening: each observer gets its own, in
    the step's order, with the event's data, every time the plan runs."""
    subject = Subject(_rig(), clock=SimClock())
    heard: list[tuple[int, Any]] = []
    for invoke in (0, 1):
        subject.attach(Recorder(lambda n: heard.append((n.invoke, n.data))), (invoke,))
    subject.start()
    for n in range(3):
        subject.dispatch("go", {"speed": n} if n else None)
        subject.dispatch("stop")
    assert heard == [
        (0, None), (1, None), (1, None),
        (0, {"speed": 1}), (1, {"speed": 1}), (1, None),
        (0, {"speed": 2}), (1, {"speed": 2}), (1, None),
    ]  # fmt: skip


@pytest.mark.parametrize(
    "observers", [("plain", "plain"), ("calls", "plain"), ("calls", "calls"), ("none", "calls")]
)
def test_records_of_repeated_steps_are_listens_however_observers_log(
    observers: tuple[str, str],
) -> None:
    """A step seen again builds its records from compiled code: still listen()'s records,
    with every notification's observer calls in place (none, one, or each logged call)."""
    from statectl.run.runtime import TraceWriter

    chart = _rig()
    events = (("go", None), ("stop", None)) * 4 + (("go", {"speed": 2}),)
    runs: list[list[Record]] = []
    texts: list[str] = []
    for hear in ("typed", "steps"):
        subject = Subject(chart, clock=SimClock())
        for invoke, kind in enumerate(observers):
            if kind != "none":
                subject.attach(Recorder() if kind == "plain" else TwoCalls(), (invoke,))
        out = io.StringIO()
        writer = TraceWriter(out, device_width=3)
        got: list[Record] = []
        if hear == "typed":
            subject.listen(got.append)
            subject.listen(writer)
        else:
            steps: list[StepRecord] = []
            subject.listen_steps(steps.append)
            subject.listen_steps(writer.step)
        subject.start()
        for event, data in events:
            subject.dispatch(event, data)
        if hear == "steps":
            got = [r for s in steps for r in s.records]
        runs.append(got)
        texts.append(out.getvalue())
    assert runs[0] == runs[1]
    assert texts[0] == texts[1]
    calls = sum(isinstance(r, ObserverCalled) for r in runs[0])
    each = [{"plain": 1, "calls": 2, "none": 0}[k] for k in observers]
    assert calls == 5 * sum(each) + 4 * each[1]  # five go, four stop
