"""SimMotor: a simulated twin of the paper's Motor, with the same observer methods.

Rules:
1. ``Movement()`` calls ``move_to(target)``: the target comes from the event
   data (``{amount: dx}`` relative, ``{target: x}`` absolute); the motor travels
   at ``speed`` units per second on the clock and reports ``Movement completion``
   when it arrives.
2. ``Initialization()`` calls ``return_to(previous)``: back to where the last
   movement started; it reports ``Initialization completion`` on arrival.
3. ``Error()`` also calls ``return_to(previous)``, which first ``stop()``s the
   movement in progress: the motor goes back to the position before the failed
   movement and reports ``Error completion``.
4. ``inject_fault(detail, after)`` makes the Moving monitor see a motor error.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

from statectl.devices.base import Driver, requested_target
from statectl.errors import StatectlError
from statectl.runtime.clock import Timer

__all__ = ["SimMotor"]


class _Motion(NamedTuple):
    """A movement under way (a named tuple: one is made per API call)."""

    start_time: float
    start: float
    target: float
    timer: Timer


class SimMotor(Driver):
    """A motor that moves at a constant speed; position is interpolated on the clock."""

    methods: ClassVar[dict[str, str]] = {
        "Movement": "move_to",
        "Initialization": "return_to",
        "Error": "return_to",
    }
    completions: ClassVar[dict[str, str]] = {
        "Movement": "Movement completion",
        "Initialization": "Initialization completion",
        "Error": "Error completion",
    }

    def __init__(self, *, speed: float = 10.0, position: float = 0.0) -> None:
        super().__init__()
        if not speed > 0:
            raise StatectlError(f"SimMotor speed must be > 0 units/s (got {speed!r})")
        self.speed = float(speed)
        self._position = float(position)
        self.previous = float(position)  # where the last movement started
        self.target = float(position)
        self._motion: _Motion | None = None

    @property
    def moving(self) -> bool:
        return self._motion is not None

    @property
    def position(self) -> float:
        m = self._motion
        if m is None:
            return self._position
        travelled = (self.clock.now() - m.start_time) * self.speed
        distance = m.target - m.start
        if travelled >= abs(distance):
            return m.target
        return m.start + (travelled if distance > 0 else -travelled)

    def arguments(self, method: str, data: Any) -> tuple[Any, ...]:
        if method == "Movement":
            return (requested_target(self.position, data),)
        return (self.previous,)

    # -- the motor's API ---------------------------------------------------------------------

    def move_to(self, target: float) -> None:
        with self._lock:
            if self.moving:
                self.stop()
            self.log_call("move_to", float(target))
            self.previous = self.position
            self._travel(float(target))

    def return_to(self, position: float) -> None:
        with self._lock:
            if self.moving:
                self.stop()
            self.log_call("return_to", float(position))
            self._travel(float(position))

    def stop(self) -> None:
        with self._lock:
            self.log_call("stop")
            m = self._motion
            if m is not None:
                self._position = self.position
                m.timer.cancel()
                self._motion = None
            self.target = self._position

    # -- simulation --------------------------------------------------------------------------

    def _travel(self, target: float) -> None:
        method = self.method or "Movement"
        self.target = target
        start = self._position
        duration = abs(target - start) / self.speed
        timer = self.clock.call_later(duration, lambda: self._arrive(method))
        self._motion = _Motion(self.clock.now(), start, target, timer)

    def _arrive(self, method: str) -> None:
        with self._lock:
            m = self._motion
            if m is None:
                return
            self._position = m.target
            self._motion = None
        self.complete(method, {"position": self._position})
