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
5. A command that replaces a movement under way completes only the new one, at
   its own arrival time; the replaced movement never reports.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from statectl.front.observers import Notification
from statectl.kernel.errors import StatectlError
from statectl.run.devices.base import Driver, finite_number, requested_target
from statectl.run.runtime.clock import Clock, Timer

__all__ = ["SimMotor", "motor_option_problems"]

#: The observer methods update() serves itself: Movement -> move_to, the others -> return_to.
_CALLS = frozenset({"Movement", "Initialization", "Error"})
#: An arrival timer this close to the arrival completes it (clock arithmetic is floating point).
_EARLY = 1e-9


def motor_option_problems(options: Mapping[str, Any]) -> tuple[str, ...]:
    """Every problem with SimMotor option values, so a config file shows them at its line."""
    problems: list[str] = []
    speed = options.get("speed", 10.0)
    if not (finite_number(speed) and speed > 0):
        problems.append(f"speed must be a number of units/s > 0 (got {speed!r})")
    position = options.get("position", 0.0)
    if not finite_number(position):
        problems.append(f"position must be a number of units (got {position!r})")
    return tuple(problems)


class SimMotor(Driver):
    """A motor that moves at a constant speed; position is interpolated on the clock.

    The movement under way is a few attributes (where and when it started, where it
    goes, when it arrives) rather than an object per move, and :meth:`update` takes
    the lock once and calls the private bodies of the API functions. One arrival
    timer serves the movements in turn (rule 5): a command that replaces a movement
    under way keeps the armed timer when that fires no later than the new arrival;
    firing early, the timer is armed again for the rest. A stream of commands, each
    replacing the last, so arms no timer per command.
    """

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
        problems = motor_option_problems({"speed": speed, "position": position})
        if problems:
            raise StatectlError(f"SimMotor {'; '.join(problems)}")
        self.speed = float(speed)
        self._position = float(position)  # where the motor is when it is not moving
        self.previous = float(position)  # where the last movement started
        self.target = float(position)
        self._moving = False
        self._since = 0.0  # when the movement under way started
        self._from = 0.0  # where it started
        self._to = 0.0  # where it goes
        self._arrival = 0.0  # when it gets there
        self._arriving = "Movement"  # the method whose completion it reports then
        self._timer: Timer | None = None  # the armed arrival timer, if any
        self._timer_due = 0.0  # when that timer fires
        self._arms = 0  # timers armed: one fired after it was replaced does nothing
        cls = type(self)  # update() below is the base one unless methods and arguments are ours
        self._plain = cls.methods == SimMotor.methods and cls.arguments is SimMotor.arguments

    @property
    def moving(self) -> bool:
        return self._moving

    @property
    def position(self) -> float:
        if not self._moving:
            return self._position
        return self._at(self.clock.now())

    def _at(self, now: float) -> float:
        """Where the movement under way is at ``now``."""
        travelled = (now - self._since) * self.speed
        distance = self._to - self._from
        if travelled >= abs(distance):
            return self._to
        return self._from + (travelled if distance > 0 else -travelled)

    def arguments(self, method: str, data: Any) -> tuple[Any, ...]:
        if method == "Movement":
            where = self._at(self.clock.now()) if self._moving else self._position
            return (requested_target(where, data),)
        return (self.previous,)

    def update(self, notification: Notification) -> None:
        """The base class's update (rule 2 there), the clock read once for the arguments
        and the call; a subclass that changes ``methods`` or ``arguments`` gets the
        base class's."""
        method = notification.method
        if not self._plain or method not in _CALLS:
            super().update(notification)
            return
        with self._lock:
            self.method = method
            clock = self.clock
            now = clock.now()
            if method == "Movement":
                where = self._at(now) if self._moving else self._position
                self._go(clock, now, "move_to", requested_target(where, notification.data))
            else:
                self._go(clock, now, "return_to", self.previous)

    def _locked_form(self, function: str) -> Callable[..., object]:
        bodies: dict[str, Callable[..., object]] = {
            "move_to": self._move_to,
            "return_to": self._return_to,
        }
        return bodies.get(function) or super()._locked_form(function)

    # -- the motor's API ---------------------------------------------------------------------

    def move_to(self, target: float) -> None:
        with self._lock:
            self._move_to(target)

    def return_to(self, position: float) -> None:
        with self._lock:
            self._return_to(position)

    def stop(self) -> None:
        with self._lock:
            self._halt(self.clock.now())
            self._disarm()  # nothing follows: no arrival is due any more

    # -- the bodies, called with the lock held; the clock is read once per call ---------------

    def _move_to(self, target: float) -> None:
        clock = self.clock
        self._go(clock, clock.now(), "move_to", target)

    def _return_to(self, position: float) -> None:
        clock = self.clock
        self._go(clock, clock.now(), "return_to", position)

    def _go(self, clock: Clock, now: float, function: str, target: float) -> None:
        """``move_to`` or ``return_to``: stop a movement under way, then travel."""
        target = float(target)
        if self._moving:
            self._halt(now)
        self._log(now, function, (target,))
        if function == "move_to":
            self.previous = self._position  # not moving now: this is where it is
        self._travel(clock, now, target)

    def _halt(self, now: float) -> None:
        """``stop()``: the motor stays where the movement had got to (the timer stays armed
        for the movement that follows; :meth:`stop` disarms it)."""
        self._log(now, "stop", ())
        if self._moving:
            self._position = self._at(now)
            self._moving = False
        self.target = self._position

    # -- simulation --------------------------------------------------------------------------

    def _travel(self, clock: Clock, now: float, target: float) -> None:
        start = self._position
        self.target = self._to = target
        self._from = start
        self._since = now
        duration = abs(target - start) / self.speed
        self._arrival = arrival = now + duration
        self._arriving = self.method or "Movement"
        self._moving = True
        if self._timer is None or self._timer_due > arrival:  # none armed, or it fires late
            self._disarm()
            self._arm(clock, duration, arrival)

    def _arm(self, clock: Clock, delay: float, due: float) -> None:
        self._arms = arms = self._arms + 1
        self._timer_due = due
        self._timer = clock.call_later(delay, lambda: self._fired(arms))

    def _disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _fired(self, arms: int) -> None:
        with self._lock:
            if arms != self._arms:
                return  # replaced by a timer armed since
            self._timer = None
            if not self._moving:
                return
            clock = self.clock
            now = clock.now()
            if self._arrival - now > _EARLY:  # a later movement took over this timer
                self._arm(clock, self._arrival - now, self._arrival)
                return
            self._position = self._to
            self._moving = False
            method = self._arriving
        self.complete(method, {"position": self._position})
