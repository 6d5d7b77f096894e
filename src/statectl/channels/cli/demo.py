"""The paper's step 3 made to run: the Motor on a simulated clock, traced record by record.

Rules:
1. The model is the packaged copy of ``examples/motor/motor.yaml``
   (``statectl/data/motor.yaml``), so the demo runs from a wheel too.
2. The driver comes from a driver name or a driver config file; the model is
   the same whichever runs it.
3. A driver on a real bus (``cia402-sim``: a simulated CiA 402 drive speaking
   CANopen on python-can's virtual bus) runs on a WallClock, since the bus runs
   in real time; the demo closes its bus at the end.
4. The scenario: a Movement of 10 until its completion; an Initialization back
   (its guard ``previous == 'Moving'`` holds); a second Movement during which the
   motor faults, the Moving monitor raises Error, the motor returns to where the
   movement began, and the run ends Blocked.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from importlib.resources import as_file, files
from typing import TextIO

from statectl.channels.runconfig import load_driver_config
from statectl.front.builder.build import load_chart
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart
from statectl.run.devices import Driver, connect, make_driver
from statectl.run.runtime import Clock, Listener, SimClock, Subject, TraceWriter, WallClock

__all__ = ["FAULT", "motor_chart", "run_demo"]

#: The motor error the demo injects during the second movement.
FAULT = "motor stalled"
_TICK = 0.05
_LIMIT = 30.0


def motor_chart() -> Chart:
    """The packaged Motor model, built from its tables."""
    with as_file(files("statectl") / "data" / "motor.yaml") as path:
        return load_chart(path)


def _until(subject: Subject, state: str) -> None:
    """Advance simulated time until the device rests in ``state`` with nothing queued."""
    clock = subject.clock
    deadline = clock.now() + _LIMIT
    subject.run_until_idle()
    while subject.configuration != {state} or subject.queued:
        if clock.now() >= deadline:
            active = ", ".join(sorted(subject.configuration))
            raise StatectlError(f"demo: not back in {state} after {_LIMIT} s (in {active})")
        if isinstance(clock, SimClock):
            due = clock.next_deadline()
            subject.advance(_TICK if due is None else max(0.0, min(_TICK, due - clock.now())))
        else:  # a bus in real time: let its frames arrive
            time.sleep(0.002)
            subject.run_until_idle()


def run_demo(
    out: TextIO,
    *,
    driver: str = "sim-motor",
    config: str | None = None,
    listeners: Iterable[Listener] = (),
) -> Subject:
    """Run the Motor scenario, print its trace to ``out`` and return the finished Subject.

    ``listeners`` receive every record too (tests, a journal, a dashboard).
    """
    chart = motor_chart()
    options: dict[str, object] = {}
    if config is not None:
        devices = load_driver_config(config)
        if chart.name not in devices:
            raise StatectlError(f"{config}: no driver for device {chart.name!r}")
        driver, options = devices[chart.name]
    device = make_driver(driver, options, chart=chart)
    if not isinstance(device, Driver):
        raise StatectlError(f"driver {driver!r} cannot inject faults; the demo needs a twin")
    realtime = bool(getattr(device, "realtime", False))
    clock: Clock = WallClock() if realtime else SimClock()
    subject = Subject(chart, clock=clock)
    invokes = ", ".join(f"#{i.number} {i.name} -> {i.method}()" for i in chart.invokes)
    out.write(f"statectl demo: {chart.name} on {type(device).__name__} (driver {driver})\n")
    out.write(f"invokes: {invokes}\n\n")
    subject.listen_steps(TraceWriter(out, device_width=len(subject.name)).step)
    for listener in listeners:
        subject.listen(listener)
    try:
        connect(subject, device)
        subject.start()
        subject.post("Movement", {"amount": 10})
        _until(subject, "Blocked")
        subject.post("Initialization")
        _until(subject, "Blocked")
        subject.post("Movement", {"amount": 10})
        device.inject_fault(FAULT, after=0.45)
        _until(subject, "Blocked")
    finally:
        subject.close()
        close = getattr(device, "close", None)
        if callable(close):
            close()
        if isinstance(clock, WallClock):
            clock.stop()

    final = ", ".join(sorted(subject.configuration))
    calls = getattr(device, "api_calls", None)
    made = calls if isinstance(calls, int) else len(device.api_log)
    out.write(
        f"\nfinal state {final}; {subject.events_processed} events processed; "
        f"{subject.invokes_issued} invokes issued; {made} API calls\n"
    )
    return subject
