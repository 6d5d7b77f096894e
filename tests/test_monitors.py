"""Monitors: the paper's error thread, alive only while its state is."""

from __future__ import annotations

from pathlib import Path

import pytest

from statectl.front.observers import MonitorSpec
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart, ControlKind, EventDef, EventKind, State, Transition
from statectl.run.runtime import (
    EventReceived,
    FaultDetected,
    MonitorStarted,
    MonitorStopped,
    Record,
    SimClock,
    Subject,
    attach_monitors,
)
from statectl.run.runtime.monitors import Monitor

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"


class Device:
    """A fault source that counts its polls and faults on the poll numbers it is given."""

    def __init__(self, fault_at: frozenset[int] = frozenset()) -> None:
        self.polls = 0
        self.fault_at = fault_at

    def poll_fault(self) -> str | None:
        self.polls += 1
        return "overcurrent" if self.polls in self.fault_at else None


def setup(chart: Chart, device: Device, period: float = 0.1) -> tuple[Subject, list[Record]]:
    subject = Subject(chart, clock=SimClock())
    records: list[Record] = []
    subject.listen(records.append)
    attach_monitors(subject, device, period=period)
    subject.start()
    return subject, records


def test_the_motor_gets_one_monitor_for_moving(motor: Chart) -> None:
    """Moving is the one monitored state; its monitor raises Error."""
    subject = Subject(motor, clock=SimClock())
    monitors = attach_monitors(subject, Device())
    assert [(m.spec.state, m.spec.raises) for m in monitors] == [("Moving", ("Error",))]


@pytest.mark.parametrize(
    ("events", "started", "stopped"),
    [
        ([], 0, 0),
        (["Movement"], 1, 0),
        (["Movement", "Movement completion"], 1, 1),
        (["Movement", "Movement completion", "Movement"], 2, 1),
        (["Movement", "Error"], 1, 1),
    ],
)
def test_monitor_runs_while_its_state_is_active(
    motor: Chart, events: list[str], started: int, stopped: int
) -> None:
    """MonitorStarted on entering Moving, MonitorStopped on leaving it."""
    subject, records = setup(motor, Device())
    for e in events:
        subject.post(e)
    subject.run_until_idle()
    assert sum(isinstance(r, MonitorStarted) for r in records) == started
    assert sum(isinstance(r, MonitorStopped) for r in records) == stopped


@pytest.mark.parametrize(
    ("events", "seconds", "polls"),
    [([], 1.0, 0), (["Movement"], 1.0, 10), (["Movement", "Movement completion"], 1.0, 0)],
)
def test_device_is_polled_only_while_monitored(
    motor: Chart, events: list[str], seconds: float, polls: int
) -> None:
    """Every period while the state is active, never otherwise."""
    device = Device()
    subject, _ = setup(motor, device)
    for e in events:
        subject.post(e)
    subject.advance(seconds + 1e-9)
    assert device.polls == polls


def test_fault_is_recorded_and_raises_the_fault_event(motor: Chart) -> None:
    """A fault detail records FaultDetected and posts Error with the detail; Moving is left."""
    subject, records = setup(motor, Device(fault_at=frozenset({3})))
    subject.post("Movement")
    subject.advance(0.5)
    fault = next(r for r in records if isinstance(r, FaultDetected))
    assert (fault.state, fault.event, fault.detail) == ("Moving", "Error", "overcurrent")
    assert fault.time == pytest.approx(0.3)
    received = [r for r in records if isinstance(r, EventReceived)]
    assert received[-1].event == "Error" and received[-1].data == {"detail": "overcurrent"}
    assert subject.configuration == {"Returning"}


def test_a_stopped_monitor_ignores_a_poll_already_queued(motor: Chart) -> None:
    """A poll queued before the state was left does not poll after it."""
    device = Device()
    subject, _ = setup(motor, device, period=1.0)
    subject.post("Movement")
    subject.run_until_idle()
    subject.post("Movement completion")
    clock = subject.clock
    assert isinstance(clock, SimClock)
    clock.advance(1.0)  # the poll is queued behind the completion, not run
    subject.run_until_idle()
    assert device.polls == 0


def test_monitored_initial_state_is_watched_from_the_start() -> None:
    """Monitors attached before start() see the initial entry and can raise at once."""
    chart = Chart(
        "Guard",
        (State("Idle", controls=frozenset({ControlKind.MONITORING})), State("Tripped")),
        (Transition("Idle", ("Trip",), ("Tripped",)),),
        ("Idle",),
        events=(EventDef("Trip", EventKind.FAULT),),
    )
    subject, records = setup(chart, Device(fault_at=frozenset({1})))
    subject.advance(0.1)
    assert isinstance(records[2], MonitorStarted)
    assert subject.configuration == {"Tripped"}


@pytest.mark.parametrize(
    ("spec", "period", "message"),
    [
        (MonitorSpec("Moving", ("Error",), ""), 0.0, "period"),
        (MonitorSpec("Moving", (), ""), 0.1, "no fault event"),
    ],
)
def test_bad_monitor_is_refused(
    motor: Chart, spec: MonitorSpec, period: float, message: str
) -> None:
    """A monitor needs a positive period and a fault event to raise."""
    with pytest.raises(StatectlError, match=message):
        Monitor(Subject(motor, clock=SimClock()), spec, Device(), period)


def test_close_stops_monitor_timers(motor: Chart) -> None:
    """Closing the run cancels the monitor's pending poll."""
    subject, _ = setup(motor, Device())
    subject.post("Movement")
    subject.run_until_idle()
    subject.close()
    clock = subject.clock
    assert isinstance(clock, SimClock)
    assert clock.pending == 0
