"""SimStepper: a stepper motor with a different API behind the same observer methods.

Rules:
1. Its API counts steps: ``step(n, direction)`` pulses ``n`` steps at
   ``pulse_rate`` steps per second, ``home_to(step)`` drives to an absolute step
   count, ``halt()`` stops; ``steps_per_unit`` converts the chart's units.
2. ``Movement()`` -> ``step(n, direction)`` for the requested amount or target;
   ``Initialization()`` and ``Error()`` -> ``home_to(step before the last
   movement)``, halting first if a movement is under way.
3. It reports the same completion events as :class:`~statectl.run.devices.motor.SimMotor`,
   so the chart (and the state trace) cannot tell the two apart.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from statectl.kernel.errors import StatectlError
from statectl.run.devices.base import Driver, finite_number, requested_target
from statectl.run.runtime.clock import Timer

__all__ = ["SimStepper", "stepper_option_problems"]


def _integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def stepper_option_problems(options: Mapping[str, Any]) -> tuple[str, ...]:
    """Every problem with SimStepper option values, so a config file shows them at its line."""
    problems: list[str] = []
    per_unit = options.get("steps_per_unit", 100)
    if not (_integer(per_unit) and per_unit > 0):
        problems.append(f"steps_per_unit must be an int > 0 (got {per_unit!r})")
    rate = options.get("pulse_rate", 1000.0)
    if not (finite_number(rate) and rate > 0):
        problems.append(f"pulse_rate must be a number of steps/s > 0 (got {rate!r})")
    step = options.get("step", 0)
    if not _integer(step):
        problems.append(f"step must be an int, a step count (got {step!r})")
    return tuple(problems)


@dataclass(frozen=True, slots=True)
class _Run:
    start_time: float
    start: int
    goal: int
    timer: Timer


class SimStepper(Driver):
    """A stepper driven by pulses; the step count is interpolated on the clock."""

    methods: ClassVar[dict[str, str]] = {
        "Movement": "step",
        "Initialization": "home_to",
        "Error": "home_to",
    }
    completions: ClassVar[dict[str, str]] = {
        "Movement": "Movement completion",
        "Initialization": "Initialization completion",
        "Error": "Error completion",
    }

    def __init__(
        self, *, steps_per_unit: int = 100, pulse_rate: float = 1000.0, step: int = 0
    ) -> None:
        super().__init__()
        given = {"steps_per_unit": steps_per_unit, "pulse_rate": pulse_rate, "step": step}
        problems = stepper_option_problems(given)
        if problems:
            raise StatectlError(f"SimStepper {'; '.join(problems)}")
        self.steps_per_unit = steps_per_unit
        self.pulse_rate = float(pulse_rate)
        self._count = int(step)
        self.home = int(step)  # the step count before the last movement
        self._run: _Run | None = None

    @property
    def moving(self) -> bool:
        return self._run is not None

    @property
    def count(self) -> int:
        """The step counter now."""
        r = self._run
        if r is None:
            return self._count
        done = int((self.clock.now() - r.start_time) * self.pulse_rate)
        total = abs(r.goal - r.start)
        done = min(done, total)
        return r.start + (done if r.goal >= r.start else -done)

    @property
    def position(self) -> float:
        return self.count / self.steps_per_unit

    def arguments(self, method: str, data: Any) -> tuple[Any, ...]:
        if method == "Movement":
            goal = round(requested_target(self.position, data) * self.steps_per_unit)
            delta = goal - self.count
            return (abs(delta), 1 if delta >= 0 else -1)
        return (self.home,)

    # -- the stepper's API -------------------------------------------------------------------

    def step(self, n: int, direction: int) -> None:
        with self._lock:
            if direction not in (1, -1):
                raise StatectlError(f"direction must be 1 or -1 (got {direction!r})")
            if self.moving:
                self.halt()
            self.log_call("step", n, direction)
            self.home = self.count
            self._pulse(self._count + n * direction)

    def home_to(self, step: int) -> None:
        with self._lock:
            if self.moving:
                self.halt()
            self.log_call("home_to", step)
            self._pulse(step)

    def halt(self) -> None:
        with self._lock:
            self.log_call("halt")
            r = self._run
            if r is not None:
                self._count = self.count
                r.timer.cancel()
                self._run = None

    # -- simulation --------------------------------------------------------------------------

    def _pulse(self, goal: int) -> None:
        method = self.method or "Movement"
        duration = abs(goal - self._count) / self.pulse_rate
        timer = self.clock.call_later(duration, lambda: self._arrive(method))
        self._run = _Run(self.clock.now(), self._count, goal, timer)

    def _arrive(self, method: str) -> None:
        with self._lock:
            r = self._run
            if r is None:
                return
            self._count = r.goal
            self._run = None
        self.complete(method, {"position": self.position})
