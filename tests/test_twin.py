"""SimTwin: a simulated device derived from any device file's tables, alone and in a cell."""

from __future__ import annotations

import io
import sys
from pathlib import Path
from typing import Any

import pytest

from statectl.channels.cli.demo import run_demo
from statectl.channels.cli.run import run
from statectl.channels.runconfig import load_driver_config
from statectl.front.builder.build import load_chart
from statectl.front.observers import Notification
from statectl.kernel.errors import DiagnosticError, StatectlError
from statectl.kernel.model import Chart
from statectl.run.devices import SimMotor, SimTwin, connect, make_driver
from statectl.run.devices.base import Driver
from statectl.run.runtime import Record, SimClock, Subject
from statectl.run.runtime.records import MicrostepTaken
from support import PARALLEL_PRESS

ROOT = Path(__file__).parent.parent
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"
PICK = ROOT / "examples" / "pick-and-place"
CELL = PICK / "cell.yaml"
LIMIT = 30.0  # simulated seconds a scenario may take at most

#: The paper's cycle as the demo runs it: (event, source, target) of each transition.
PAPER_CYCLE = [
    ("Movement", "Blocked", "Moving"),
    ("Movement completion", "Moving", "Blocked"),
    ("Initialization", "Blocked", "Returning"),
    ("Initialization completion", "Returning", "Blocked"),
    ("Movement", "Blocked", "Moving"),
    ("Error", "Moving", "Returning"),
    ("Error completion", "Returning", "Blocked"),
]


def transitions(records: list[Record]) -> list[tuple[str, str, str]]:
    return [
        (r.event, t.source, ", ".join(t.targets))
        for r in records
        if isinstance(r, MicrostepTaken)
        for t in r.transitions
    ]


def until(subject: Subject, state: str) -> None:
    """Let simulated time pass until the device rests in ``state``."""
    clock = subject.clock
    assert isinstance(clock, SimClock)
    deadline = clock.now() + LIMIT
    subject.run_until_idle()
    while (subject.configuration != {state} or subject.queued) and clock.now() < deadline:
        subject.advance(0.05)


def twin_motor(**options: Any) -> tuple[Subject, SimTwin, list[Record]]:
    chart = load_chart(MOTOR)
    subject = Subject(chart, clock=SimClock())
    records: list[Record] = []
    subject.listen(records.append)
    twin = SimTwin(chart, **options)
    connect(subject, twin)
    subject.start()
    return subject, twin, records


def paper_scenario(subject: Subject, driver: Driver) -> None:
    """The demo's scenario: move, initialize back, move and fault."""
    subject.post("Movement", {"amount": 10})
    until(subject, "Blocked")
    subject.post("Initialization")
    until(subject, "Blocked")
    subject.post("Movement", {"amount": 10})
    driver.inject_fault("motor stalled", after=0.45)
    until(subject, "Blocked")


def test_the_twin_runs_the_papers_cycle_with_the_sim_motor_demos_state_trace() -> None:
    """Movement, Initialization and a fault in Moving take the demo's transitions on a twin."""
    demo: list[Record] = []
    run_demo(io.StringIO(), listeners=[demo.append])
    subject, twin, records = twin_motor()
    paper_scenario(subject, twin)
    assert transitions(records) == transitions(demo) == PAPER_CYCLE


@pytest.mark.parametrize(
    ("posts", "method", "completion", "seconds"),
    [
        ((("Movement", {"amount": 10}),), "Movement", "Movement completion", 1.0),
        ((("Movement", None), ("Movement completion", None), ("Initialization", None)),
         "Initialization", "Initialization completion", 2.5),
    ],
)  # fmt: skip
def test_a_notification_is_completed_after_its_methods_delay(
    posts: tuple[tuple[str, Any], ...], method: str, completion: str, seconds: float
) -> None:
    """The last notification logs M() and reports M's completion exactly delays[M] later."""
    subject, twin, records = twin_motor(delay=1.0, delays={"Initialization": 2.5})
    for event, data in posts:
        subject.post(event, data)
        subject.run_until_idle()
    assert [c.function for c in twin.api_log][-1] == method
    assert twin.pending == (completion,)
    subject.advance(seconds - 0.01)
    assert twin.pending == (completion,)
    subject.advance(0.01)
    assert (twin.pending, transitions(records)[-1][0]) == ((), completion)


def test_a_scheduled_fault_raises_error_and_supersedes_the_movement() -> None:
    """faults={Moving: 0.3}: the monitor raises Error; Movement completion is never reported."""
    subject, twin, records = twin_motor(faults={"Moving": 0.3})
    subject.post("Movement", {"amount": 10})
    until(subject, "Blocked")
    assert transitions(records) == [
        ("Movement", "Blocked", "Moving"),
        ("Error", "Moving", "Returning"),
        ("Error completion", "Returning", "Blocked"),
    ]
    assert [n.method for n in twin.notes] == ["Movement"]
    assert "superseded by Error" in str(twin.notes[0])


@pytest.mark.parametrize(
    ("device", "events", "method", "why"),
    [
        ("sensor.yaml", ("Part in",), "Read", "has no completion event"),
        ("conveyor.yaml", ("Start",), "Drive", "has no completion event"),
        ("gripper.yaml", ("Grip", "Grip completion", "Slip"), "Release",
         "Slip entered Open, and no completion of Release() (Release completion) leaves it"),
    ],
)  # fmt: skip
def test_a_method_with_no_completion_for_the_state_reports_nothing_and_says_why(
    device: str, events: tuple[str, ...], method: str, why: str
) -> None:
    """The twin logs M(), reports nothing and leaves a note with the reason."""
    chart = load_chart(PICK / device)
    twin = SimTwin(chart)
    subject = Subject(chart, clock=SimClock())
    connect(subject, twin)
    subject.start()
    for event in events:
        subject.post(event)
        subject.run_until_idle()
    before = subject.configuration
    subject.advance(10.0)
    assert subject.configuration == before
    assert twin.pending == ()
    assert [c.function for c in twin.api_log][-1] == method
    assert why in str(twin.notes[-1]) and twin.notes[-1].method == method


LINES = "conveyor: Start\n+2\nsensor: Part in\n+5\n"
FINAL = {"conveyor": "Running", "arm": "Blocked", "gripper": "Open", "sensor": "Clear"}


def finals(text: str) -> dict[str, str]:
    rows = (line.removeprefix("final ").split(": ") for line in text.splitlines()
            if line.startswith("final "))  # fmt: skip
    return dict(rows)


@pytest.mark.parametrize(
    ("driver", "journal", "banner"),
    [(None, False, True), (None, True, True), ("sim-twin", False, False)],
)
def test_the_cell_runs_a_whole_pick_on_twins_in_batch_mode(
    tmp_path: Path, driver: str | None, journal: bool, banner: bool
) -> None:
    """Start and a part: links and twin completions carry the cell round and the belt resumes."""
    out, err = io.StringIO(), io.StringIO()
    db = str(tmp_path / "cell.db") if journal else None
    code = run(str(CELL), driver=driver, journal=db, events=io.StringIO(LINES), out=out, err=err)
    text = out.getvalue()
    assert code == 0, err.getvalue()
    assert finals(text) == FINAL
    assert ("no driver configured: simulated twins" in text) is banner
    picked = [
        "Movement completion", "Grip completion", "Initialization completion",
        "Release completion", "Resume",
    ]  # fmt: skip
    seen = [w for line in text.splitlines() if " event " in line for w in picked
            if line.endswith(f"event    {w}")]  # fmt: skip
    assert seen == picked


def test_a_device_file_runs_on_a_twin_when_no_driver_is_given() -> None:
    """statectl run motor.yaml with no driver: the Movement completes on the twin."""
    out, err = io.StringIO(), io.StringIO()
    code = run(str(MOTOR), events=io.StringIO("Movement {amount: 10}\n"), out=out, err=err)
    assert code == 0, err.getvalue()
    assert "SimTwin.Movement()" in out.getvalue()
    assert out.getvalue().splitlines()[0] == "no driver configured: simulated twins for Motor"
    assert "final state Blocked" in out.getvalue().splitlines()


CHOICE = """\
device: Worker
states:
  - {component: Worker, api: Work(), state: Idle, control: default, description: idle}
  - {component: Worker, api: Work(), state: Busy, control: event trigger required,
     description: working}
events:
  - {event: Work, condition: asked, old: Idle, new: Busy, kind: command, api: Work}
  - {event: Done, condition: it worked, old: Busy, new: Idle, kind: completion, api: Work}
  - {event: Failed, condition: it did not, old: Busy, new: Idle, kind: completion, api: Work}
"""


def worker(tmp_path: Path) -> Chart:
    path = tmp_path / "worker.yaml"
    path.write_text(CHOICE, encoding="utf-8")
    return load_chart(path)


def reported(chart: Chart, seed: int | None, runs: int) -> list[str]:
    twin = SimTwin(chart, seed=seed)
    subject = Subject(chart, clock=SimClock())
    records: list[Record] = []
    subject.listen(records.append)
    connect(subject, twin)
    subject.start()
    for _ in range(runs):
        subject.post("Work")
        subject.advance(1.0)
    return [e for e, _, _ in transitions(records) if e != "Work"]


def test_several_completions_take_the_first_unless_seeded(tmp_path: Path) -> None:
    """No seed: the first completion in table order; a seed: a repeatable choice of both."""
    chart = worker(tmp_path)
    assert reported(chart, None, 8) == ["Done"] * 8
    seeded = reported(chart, 7, 20)
    assert seeded == reported(chart, 7, 20)
    assert set(seeded) == {"Done", "Failed"}


@pytest.mark.parametrize(
    ("options", "codes"),
    [
        ("{delay: -1}", ["D509"]),
        ("{delay: soon, seed: x}", ["D509", "D509"]),
        ("{delays: {Movement: -2}, faults: [Moving]}", ["D509", "D509"]),
        ("{speed: 10}", ["D508"]),
        ("{chart: motor.yaml}", ["D508"]),
    ],
)
def test_bad_twin_options_are_d5xx_diagnostics(
    tmp_path: Path, options: str, codes: list[str]
) -> None:
    """A config file's bad sim-twin options are reported with their codes, all at once."""
    path = tmp_path / "drivers.yaml"
    path.write_text(f"devices:\n  Motor:\n    driver: sim-twin\n    options: {options}\n")
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    assert [d.code for d in info.value.diagnostics] == codes
    assert all(d.where.line == 4 for d in info.value.diagnostics)


def test_a_good_twin_config_loads_and_makes_a_twin(tmp_path: Path) -> None:
    """delay, delays, faults and seed pass the checks; make_driver gives the twin its chart."""
    path = tmp_path / "drivers.yaml"
    path.write_text(
        "devices:\n  Motor: {driver: sim-twin, options: "
        "{delay: 0.5, delays: {Error: 2}, faults: {Moving: 0.3}, seed: 1}}\n"
    )
    name, options = load_driver_config(path)["Motor"]
    twin = make_driver(name, options, chart=load_chart(MOTOR))
    assert isinstance(twin, SimTwin)
    assert (twin.delay, twin.delays, twin.faults, twin.seed) == (0.5, {"Error": 2.0},
                                                                 {"Moving": 0.3}, 1)  # fmt: skip


@pytest.mark.parametrize(
    ("options", "chart", "message"),
    [
        ({}, False, "derived from the device's chart"),
        ({"delay": -1}, True, "delay must be a number of seconds >= 0"),
        ({"delays": {"Jump": 1}}, True, "delays names method(s) ['Jump']"),
        ({"faults": {"Blocked": 1}}, True, "monitored states: Moving"),
    ],
)
def test_make_driver_refuses_a_twin_it_cannot_build(
    options: dict[str, Any], chart: bool, message: str
) -> None:
    """No chart, a bad value, or a method or state the chart lacks: an error saying which."""
    with pytest.raises(StatectlError, match=None) as info:
        make_driver("sim-twin", options, chart=load_chart(MOTOR) if chart else None)
    assert message in str(info.value)


def test_drivers_that_take_no_chart_ignore_it() -> None:
    """make_driver(..., chart=) still builds a SimMotor, which has no use for the chart."""
    assert isinstance(make_driver("sim-motor", {"speed": 5}, chart=load_chart(MOTOR)), SimMotor)


class _FiresAtOnce:
    """A clock whose timer fires on its own thread before ``call_later`` returns.

    A WallClock's timer thread may run a zero-delay callback before the caller of
    ``call_later`` takes its next step; this clock makes that interleaving certain
    (it waits up to 0.2 s for the callback, which the twin's lock may hold back).
    """

    def __init__(self) -> None:
        self.errors: list[BaseException] = []

    def now(self) -> float:
        return 0.0

    def call_later(self, delay: float, fn: Any, *, background: bool = False) -> Any:
        import threading

        from statectl.run.runtime.clock import Timer

        def run() -> None:
            try:
                fn()
            except BaseException as exc:  # what a WallClock hands to on_error
                self.errors.append(exc)

        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        thread.join(0.2)
        return Timer(delay, fn, background=background)


def test_a_twin_timer_that_fires_before_call_later_returns_still_reports_its_completion() -> None:
    """A completion whose timer fires at once (another thread) is reported, never lost."""
    import time

    chart = load_chart(MOTOR)
    clock = _FiresAtOnce()
    reported: list[str] = []
    twin = SimTwin(chart, delay=0.0)
    twin.bind(lambda event, data: reported.append(event), clock)  # type: ignore[arg-type]
    move = next(i for i in chart.invokes if i.method == "Movement")
    twin.update(Notification(chart.name, move.number, move.name, move.method, "Movement", None))
    deadline = time.monotonic() + 2.0
    while not reported and time.monotonic() < deadline:
        time.sleep(0.01)
    assert clock.errors == []
    assert reported == ["Movement completion"]


def test_eight_threads_notifying_a_twin_on_a_wall_clock_lose_no_completion() -> None:
    """Under 8 notifying threads on a WallClock every started completion is reported."""
    import threading
    import time

    from statectl.run.runtime import WallClock

    chart = load_chart(MOTOR)
    errors: list[BaseException] = []
    clock = WallClock(on_error=errors.append)
    reported: list[str] = []
    twins = [SimTwin(chart, delay=0.0) for _ in range(8)]
    for twin in twins:
        twin.bind(lambda event, data: reported.append(event), clock)
    move = next(i for i in chart.invokes if i.method == "Movement")
    note = Notification(chart.name, move.number, move.name, move.method, "Movement", None)
    rounds = 200

    def notify(twin: SimTwin) -> None:
        deadline = time.monotonic() + 10.0
        for _ in range(rounds):
            twin.update(note)
            # one piece of work at a time, so none is superseded; a lost one stays pending
            while twin.pending and time.monotonic() < deadline:
                time.sleep(0)

    threads = [threading.Thread(target=notify, args=(t,)) for t in twins]
    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads often, as a loaded machine does
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
    finally:
        sys.setswitchinterval(switch)
        clock.stop()
    assert errors == []
    assert len(reported) == rounds * len(twins)


def test_a_twin_completes_work_entered_in_a_region_of_a_parallel_state(tmp_path: Path) -> None:
    """Start enters Work, so each region's default (Pressing): Go() completes with Done."""
    path = tmp_path / "press.yaml"
    path.write_text(PARALLEL_PRESS, encoding="utf-8")
    chart = load_chart(path)
    subject = Subject(chart, clock=SimClock())
    twin = SimTwin(chart, delay=1.0)
    connect(subject, twin)
    subject.start()
    subject.post("Start")
    until(subject, "Idle")
    assert ([c.function for c in twin.api_log], twin.notes) == (["Go"], ())
    assert subject.configuration == {"Idle"} and subject.events_processed == 2
