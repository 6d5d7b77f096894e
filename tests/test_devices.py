"""Drivers: the declared method table, the simulated twins and driver configuration."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, ClassVar

import pytest

from statectl.channels.runconfig import load_driver_config
from statectl.front.builder.build import load_chart
from statectl.front.observers import Notification
from statectl.kernel.errors import DiagnosticError, StatectlError
from statectl.run.devices import (
    DeviceDriver,
    Driver,
    SimMotor,
    SimStepper,
    connect,
    make_driver,
    requested_target,
)
from statectl.run.runtime import ObserverCalled, Record, SimClock, Subject
from statectl.run.runtime.records import EventIgnored, EventReceived, MicrostepTaken

EXAMPLES = Path(__file__).parent.parent / "examples" / "motor"
MOTOR = EXAMPLES / "motor.yaml"


def notify(method: str, data: Any = None) -> Notification:
    invoke = {"Movement": 0, "Initialization": 1, "Error": 2}.get(method, 9)
    return Notification("Motor", invoke, method, method, method, data)


def bound(driver: Driver) -> tuple[Driver, SimClock, list[tuple[str, Any]]]:
    clock = SimClock()
    reports: list[tuple[str, Any]] = []
    driver.bind(lambda e, d: reports.append((e, d)), clock)
    return driver, clock, reports


def calls(driver: Driver) -> list[str]:
    return [str(c) for c in driver.api_log]


@pytest.mark.parametrize(
    ("data", "target", "seconds"),
    [({"amount": 10}, 10.0, 1.0), ({"amount": -5}, -5.0, 0.5), ({"target": 2.5}, 2.5, 0.25)],
)
def test_sim_motor_moves_at_its_speed_and_reports_completion(
    data: dict[str, float], target: float, seconds: float
) -> None:
    """Movement() -> move_to(target); completion is reported when the travel time is over."""
    motor, clock, reports = bound(SimMotor(speed=10))
    motor.update(notify("Movement", data))
    clock.advance(seconds - 0.01)
    assert reports == []
    clock.advance(0.01)
    assert reports == [("Movement completion", {"position": target})]
    assert calls(motor) == [f"SimMotor.move_to({target!r})"]


def test_sim_motor_position_is_interpolated() -> None:
    """Half-way through the travel time the motor is half-way."""
    motor, clock, _ = bound(SimMotor(speed=4))
    motor.update(notify("Movement", {"amount": 8}))
    clock.advance(1.0)
    assert isinstance(motor, SimMotor) and motor.position == pytest.approx(4.0)


@pytest.mark.parametrize("data", [None, {}, {"amount": "far"}])
def test_movement_without_an_amount_is_an_error(data: Any) -> None:
    """A Movement's data must say how far or where to."""
    motor, _, _ = bound(SimMotor())
    with pytest.raises(StatectlError, match="amount"):
        motor.update(notify("Movement", data))


@pytest.mark.parametrize("driver", [SimMotor, SimStepper])
@pytest.mark.parametrize(
    "data",
    [{"amount": float("nan")}, {"amount": float("inf")}, {"target": -float("inf")},
     {"amount": True}],
)  # fmt: skip
def test_a_movement_to_no_finite_number_is_refused_before_any_api_call(
    driver: type[SimMotor] | type[SimStepper], data: dict[str, Any]
) -> None:
    """{amount: .nan}, .inf or true is a StatectlError saying what a movement needs, and no
    API call is made (the stepper ended in ValueError: cannot convert float NaN to integer,
    the motor said 'timer delay must be a number >= 0', true moved one unit)."""
    made, _, reports = bound(driver())
    with pytest.raises(StatectlError, match="a movement needs a finite number"):
        made.update(notify("Movement", data))
    assert (calls(made), reports) == ([], [])


def test_initialization_returns_to_the_previous_position() -> None:
    """Initialization() -> return_to(where the last movement started)."""
    motor, clock, reports = bound(SimMotor(speed=10, position=3))
    motor.update(notify("Movement", {"amount": 10}))
    clock.advance(2.0)
    motor.update(notify("Initialization"))
    clock.advance(2.0)
    assert calls(motor)[-1] == "SimMotor.return_to(3.0)"
    assert reports[-1] == ("Initialization completion", {"position": 3.0})


def test_error_stops_and_returns_to_the_start_of_the_failed_movement() -> None:
    """Error() stops the movement in progress and goes back to where it began."""
    motor, clock, reports = bound(SimMotor(speed=10))
    motor.update(notify("Movement", {"amount": 10}))
    clock.advance(0.4)
    motor.update(notify("Error"))
    clock.advance(1.0)
    assert calls(motor) == ["SimMotor.move_to(10.0)", "SimMotor.stop()", "SimMotor.return_to(0.0)"]
    assert reports == [("Error completion", {"position": 0.0})]


@pytest.mark.parametrize(
    ("after", "polls_at", "expected"),
    [
        (None, [0.0, 0.1], ["jam", None]),
        (0.5, [0.2, 0.5, 0.6], [None, "jam", None]),
    ],
)
def test_injected_fault_is_polled_once_after_its_delay(
    after: float | None, polls_at: list[float], expected: list[str | None]
) -> None:
    """poll_fault() returns the injected detail once, not before ``after`` seconds."""
    motor, clock, _ = bound(SimMotor())
    motor.inject_fault("jam", after=after)
    seen = []
    for t in polls_at:
        clock.run_until(t)
        seen.append(motor.poll_fault())
    assert seen == expected


def test_unknown_observer_method_names_the_available_ones() -> None:
    """A method missing from the driver's table is a clear error."""
    motor, _, _ = bound(SimMotor())
    with pytest.raises(StatectlError, match=r"Movement\(\), Initialization\(\), Error\(\)"):
        motor.update(notify("Calibrate"))


def test_a_table_naming_a_missing_function_is_refused() -> None:
    """The method table is checked when the driver is created."""

    class Broken(Driver):
        methods: ClassVar[dict[str, str]] = {"Movement": "fly"}

    with pytest.raises(StatectlError, match="fly"):
        Broken()


@pytest.mark.parametrize(
    ("method", "data", "call"),
    [
        ("Movement", {"amount": 2}, "SimStepper.step(200, 1)"),
        ("Movement", {"target": -1}, "SimStepper.step(100, -1)"),
        ("Initialization", None, "SimStepper.home_to(0)"),
    ],
)
def test_sim_stepper_has_its_own_api(method: str, data: Any, call: str) -> None:
    """The stepper serves the same observer methods through step()/home_to()."""
    stepper, _, _ = bound(SimStepper(steps_per_unit=100, pulse_rate=100))
    stepper.update(notify(method, data))
    assert calls(stepper)[-1] == call


def test_shipped_drivers_satisfy_the_protocol() -> None:
    """SimMotor and SimStepper are DeviceDrivers."""
    assert isinstance(SimMotor(), DeviceDriver) and isinstance(SimStepper(), DeviceDriver)


# -- configuration ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("file", "expected"),
    [
        ("drivers.yaml", ("sim-motor", {"speed": 10, "position": 0})),
        ("stepper.yaml", ("sim-stepper", {"steps_per_unit": 200, "pulse_rate": 2000, "step": 0})),
    ],
)
def test_example_driver_configs_load(file: str, expected: tuple[str, dict[str, Any]]) -> None:
    """The two example configs name a driver for the Motor."""
    assert load_driver_config(EXAMPLES / file) == {"Motor": expected}


@pytest.mark.parametrize(
    ("text", "codes"),
    [
        ("devices: [unclosed", ["D502"]),
        ("- a list", ["D503"]),
        ("other: 1", ["D507", "D503"]),
        ("devices: {Motor: sim-motor}", ["D504"]),
        ("devices: {Motor: {options: {}}}", ["D504"]),
        ("devices: {Motor: {driver: warp-drive}}", ["D505"]),
        ("devices: {Motor: {driver: 'no.such.module:X'}}", ["D505"]),
        ("devices: {Motor: {driver: 'statectl.kernel.errors:Location'}}", ["D505"]),
        ("devices: {Motor: {driver: sim-motor, options: [1]}}", ["D506"]),
        ("devices: {Motor: {driver: sim-motor, colour: red}}", ["D507"]),
        ("devices: {Motor: {driver: sim-motor, options: {sped: 3}}}", ["D508"]),
        (
            "devices:\n  A: {driver: warp}\n  B: {driver: sim-motor, options: {x: 1}}\n",
            ["D505", "D508"],
        ),
    ],
)
def test_bad_driver_configs_give_diagnostics(tmp_path: Path, text: str, codes: list[str]) -> None:
    """Every problem in a driver config is reported, each with its code and line."""
    path = tmp_path / "drivers.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    found = info.value.diagnostics
    assert [d.code for d in found] == codes
    assert all(d.where.file == str(path) and d.where.line for d in found)


def test_missing_config_file_is_a_diagnostic(tmp_path: Path) -> None:
    """An unreadable file is D501, not a traceback."""
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(tmp_path / "nope.yaml")
    assert [d.code for d in info.value.diagnostics] == ["D501"]


@pytest.mark.parametrize(
    ("name", "options", "kind"),
    [
        ("sim-motor", {"speed": 2}, SimMotor),
        ("statectl.run.devices.stepper:SimStepper", {}, SimStepper),
    ],
)
def test_make_driver_by_name_or_entry(name: str, options: dict[str, Any], kind: type) -> None:
    """Registry names and 'package.module:Class' entries both make drivers."""
    assert isinstance(make_driver(name, options), kind)


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [("warp", {}, "sim-motor, sim-stepper"), ("sim-motor", {"sped": 1}, "unknown option")],
)
def test_make_driver_errors_say_what_is_available(
    name: str, options: dict[str, Any], message: str
) -> None:
    """An unknown driver or option names what would have worked."""
    with pytest.raises(StatectlError, match=message):
        make_driver(name, options)


# -- the maintainability claim ---------------------------------------------------------------


def run_scenario(config: str) -> tuple[list[tuple[Any, ...]], list[str]]:
    """The Motor scenario on the driver a config names: (state trace, API calls)."""
    name, options = load_driver_config(EXAMPLES / config)["Motor"]
    driver = make_driver(name, options)
    assert isinstance(driver, Driver)
    subject = Subject(load_chart(MOTOR), clock=SimClock())
    records: list[Record] = []
    subject.listen(records.append)
    connect(subject, driver)
    subject.start()
    subject.post("Movement", {"amount": 10})
    subject.advance(2.0)
    subject.post("Initialization")
    subject.advance(2.0)
    subject.post("Movement", {"amount": 4})
    driver.inject_fault("stall", after=0.2)
    subject.advance(2.0)
    subject.post("Error")
    subject.run_until_idle()
    state_kinds = (EventReceived, MicrostepTaken, EventIgnored)
    trace = [
        (type(r).__name__, getattr(r, "event", None), getattr(r, "entered", None))
        for r in records
        if isinstance(r, state_kinds)
    ]
    api = [r.api for r in records if isinstance(r, ObserverCalled)]
    return trace, api


def test_swapping_the_driver_config_changes_api_calls_not_states() -> None:
    """sim-motor and sim-stepper give the same state trace with different API calls,
    and the model file is not touched."""
    before = hashlib.sha256(MOTOR.read_bytes()).hexdigest()
    motor_trace, motor_api = run_scenario("drivers.yaml")
    stepper_trace, stepper_api = run_scenario("stepper.yaml")
    assert motor_trace == stepper_trace
    assert ("MicrostepTaken", "Error", ("Returning",)) in motor_trace
    assert motor_api != stepper_api
    assert all(a.startswith("SimMotor.") for a in motor_api)
    assert all(a.startswith("SimStepper.") for a in stepper_api)
    assert hashlib.sha256(MOTOR.read_bytes()).hexdigest() == before


@pytest.mark.parametrize(
    ("second_at", "second", "silent_until", "report"),
    [
        # the new arrival (1.5 s) is later than the armed timer (1.0 s): it is armed again
        (0.5, ("Movement", {"amount": 10}), 1.49, ("Movement completion", {"position": 15.0})),
        # the new arrival (0.8 s) is earlier: a timer for it replaces the armed one
        (0.4, ("Error", None), 0.79, ("Error completion", {"position": 0.0})),
        # the same arrival time as the armed timer: that timer completes the new movement
        (0.0, ("Movement", {"target": 10.0}), 0.99, ("Movement completion", {"position": 10.0})),
    ],
    ids=["later-arrival", "earlier-arrival", "same-arrival"],
)
def test_a_replaced_movement_never_reports_and_the_new_one_reports_on_arrival(
    second_at: float, second: tuple[str, Any], silent_until: float, report: tuple[str, Any]
) -> None:
    """A command that replaces a movement under way completes once, at its own arrival."""
    motor, clock, reports = bound(SimMotor(speed=10))
    motor.update(notify("Movement", {"amount": 10}))
    clock.run_until(second_at)
    motor.update(notify(*second))
    clock.run_until(silent_until)
    assert reports == []
    clock.advance(0.02)
    assert reports == [report]
    clock.advance(5.0)
    assert reports == [report] and clock.pending == 0


def test_stop_disarms_the_arrival() -> None:
    """stop() ends the movement: nothing is reported and no timer is left armed."""
    motor, clock, reports = bound(SimMotor(speed=10))
    motor.update(notify("Movement", {"amount": 10}))
    clock.advance(0.3)
    assert isinstance(motor, SimMotor)
    motor.stop()
    clock.advance(5.0)
    assert (reports, clock.pending, motor.position) == ([], 0, pytest.approx(3.0))


@pytest.mark.parametrize("made", [1, 999, 1000, 2001, 5000])
def test_the_api_log_keeps_the_recent_calls_and_counts_them_all(made: int) -> None:
    """api_log holds the last 1,000 calls (or more), oldest first; api_calls counts all."""
    motor, _, _ = bound(SimMotor(speed=10))
    for i in range(made):
        motor.log_call("probe", i)
    log = motor.api_log
    assert motor.api_calls == made
    assert min(made, 1000) <= len(log) < 2000
    assert [c.args[0] for c in log] == list(range(made - len(log), made))


@pytest.mark.parametrize(
    ("before", "then", "settle"),
    [
        (0, 3, False),
        (5, 2, False),
        (5, 2, True),
        (1990, 30, False),
        (1990, 30, True),
        (7, 0, False),
    ],
)
def test_api_since_gives_the_calls_the_log_would(before: int, then: int, settle: bool) -> None:
    """api_since(n) is the log's calls after the first n, whether or not the log was read
    (settled) in between and however often it was cut."""
    motor, _, _ = bound(SimMotor(speed=10))
    for i in range(before):
        motor.log_call("probe", i)
    mark = motor.api_calls
    if settle:
        assert len(motor.api_log) > 0
    for i in range(then):
        motor.log_call("probe", before + i)
    since = motor.api_since(mark)
    assert since == tuple(motor.api_log[len(motor.api_log) - then :]) if then else since == ()
    assert [c.args[0] for c in since] == list(range(before, before + then))


@pytest.mark.parametrize("heard", ["records", "steps"])
def test_the_trace_names_the_api_calls_after_the_log_was_cut(heard: str) -> None:
    """ObserverCalled records name the calls a notification made, however long the run,
    whether heard one by one or read from a step record."""
    chart = load_chart(MOTOR)
    subject = Subject(chart, clock=SimClock())
    connect(subject, make_driver("sim-motor", {}, chart=chart))
    subject.start()
    cycle = ["Movement", "Movement completion", "Initialization", "Initialization completion"]
    for _ in range(700):  # 2,100 API calls: the log has been cut
        for e in cycle:
            subject.dispatch(e, {"amount": 1} if e == "Movement" else None)
    records: list[Record] = []
    if heard == "records":
        subject.listen(records.append)
    else:
        subject.listen_steps(lambda step: records.extend(step.records))
    subject.dispatch("Movement", {"amount": 1})
    apis = [r.api for r in records if isinstance(r, ObserverCalled)]
    assert apis == ["SimMotor.stop()", "SimMotor.move_to(1.0)"]


@pytest.mark.parametrize(
    ("data", "target"),
    [
        ({"amount": 5}, 7.0),
        ({"target": 1.5}, 1.5),
        ({"target": 1.5, "amount": 5}, 1.5),  # an absolute target wins
        ({"target": "x", "amount": 5}, 7.0),  # ... when it is a number
        ({"amount": float("nan")}, None),
        ({"target": float("inf")}, None),
        ({"amount": 1e308, "x": 0}, 1e308),
        ({"amount": False}, None),
        ({"amount": "5"}, None),
        (None, None),
    ],
)
def test_requested_target_takes_finite_numbers_only(data: Any, target: float | None) -> None:
    """requested_target, which drivers of one's own use too, answers a finite target or
    refuses with what a movement needs (a bool is no number here)."""
    if target is None:
        with pytest.raises(StatectlError, match="a movement needs a finite number"):
            requested_target(2.0, data)
    else:
        assert requested_target(2.0, data) == target
