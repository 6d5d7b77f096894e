"""The scheduler under SCXML sessions: one thread, round-robin, delayed sends on a clock.

Apart from :mod:`statectl.scxml.session` because it knows nothing of a
document: it runs whatever is ready, fires timers in due order and owns the
wall-clock deadline that bounds a whole run (rule 5 there)."""

from __future__ import annotations

import heapq
import itertools
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from statectl.errors import StatectlError
from statectl.scxml.datamodel import EvaluationError

if TYPE_CHECKING:
    from statectl.scxml.session import Session


class SessionTimeout(StatectlError):
    """The run passed its wall-clock deadline; the session stops where it is."""


class Clock(Protocol):
    def now(self) -> float: ...
    def sleep_until(self, when: float) -> None: ...


class RealClock:
    """Wall-clock time; ``sleep_until`` really sleeps."""

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, when: float) -> None:
        delay = when - time.monotonic()
        if delay > 0:
            time.sleep(delay)


class SimulatedClock:
    """Time that moves only when the scheduler waits: timed runs are deterministic."""

    def __init__(self, start: float = 0.0) -> None:
        self.time = start

    def now(self) -> float:
        return self.time

    def sleep_until(self, when: float) -> None:
        self.time = max(self.time, when)


_DELAY = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*(ms|s|min|h)?\s*$")


def parse_delay(text: str) -> float:
    """A CSS2 time (``'2s'``, ``'500ms'``) in seconds."""
    match = _DELAY.match(text)
    if match is None:
        raise EvaluationError(f"delay {text!r} is not a time such as '1s' or '500ms'")
    unit = match.group(2) or "s"
    return float(match.group(1)) * {"ms": 0.001, "s": 1.0, "min": 60.0, "h": 3600.0}[unit]


@dataclass(order=True, slots=True)
class _Timer:
    due: float
    seq: int
    session: Session = field(compare=False)
    sendid: str = field(compare=False)
    deliver: Callable[[], None] = field(compare=False)
    cancelled: bool = field(default=False, compare=False)


class Scheduler:
    """Runs sessions round-robin in one thread and fires delayed sends from a clock."""

    def __init__(
        self,
        clock: Clock | None = None,
        log: Callable[[str], None] | None = None,
        trace: Callable[[str], None] | None = None,
    ) -> None:
        self.clock: Clock = clock or SimulatedClock()
        self.log = log or (lambda text: None)  # what <log> writes
        self.trace = trace or (lambda text: None)  # why an error event was raised
        self.sessions: dict[str, Session] = {}
        self.timers: list[_Timer] = []
        self._seq = itertools.count()
        #: ``time.monotonic()`` after which every session stops with :class:`SessionTimeout`.
        self.wall_deadline: float | None = None

    def check_deadline(self) -> None:
        """Raise :class:`SessionTimeout` once the wall-clock deadline has passed."""
        if self.wall_deadline is not None and time.monotonic() > self.wall_deadline:
            raise SessionTimeout("the run passed its wall-clock deadline")

    def add_timer(
        self, session: Session, delay: float, sendid: str, deliver: Callable[[], None]
    ) -> None:
        heapq.heappush(
            self.timers, _Timer(self.clock.now() + delay, next(self._seq), session, sendid, deliver)
        )

    def cancel_timers(self, session: Session, sendid: str) -> None:
        for t in self.timers:
            if t.session is session and t.sendid == sendid:
                t.cancelled = True

    def run_ready(self) -> bool:
        """Let every session with work do it; return whether any did."""
        progressed = False
        busy = True
        while busy:
            busy = False
            for s in list(self.sessions.values()):
                if s.ready:
                    s.run_available()
                    busy = progressed = True
        return progressed

    def run(self, root: Session, deadline: float | None = None) -> str | None:
        """Run until ``root`` stops or nothing can happen before ``deadline`` (clock time)."""
        while True:
            self.check_deadline()
            self.run_ready()
            if not root.running:
                return root.final_state
            while self.timers and self.timers[0].cancelled:
                heapq.heappop(self.timers)
            if not self.timers:
                return None
            due = self.timers[0].due
            if deadline is not None and due > deadline:
                self.clock.sleep_until(deadline)
                return None
            self.clock.sleep_until(due)
            while self.timers and self.timers[0].due <= self.clock.now():
                timer = heapq.heappop(self.timers)
                if not timer.cancelled and timer.session.running:
                    timer.deliver()
