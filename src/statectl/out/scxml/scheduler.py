"""The scheduler under SCXML sessions: one thread, round-robin, delayed sends on a clock.

Apart from :mod:`statectl.out.scxml.session` because it knows nothing of a
document: it runs whatever is ready, fires timers in due order and owns the
wall-clock deadline that bounds a whole run (rule 5 there).

Time is the runtime's :class:`~statectl.run.runtime.clock.Clock` (one protocol for
devices and documents): a delayed send is a ``call_later`` timer whose callback
only hands the delivery back to the scheduler's thread, so sessions never run on
a timer thread. On a :class:`~statectl.run.runtime.clock.SimClock` the scheduler
moves time itself to the next timer (deterministic and instant, and shared with
any device on the same clock); on any other clock (a
:class:`~statectl.run.runtime.clock.WallClock`) it waits for the timer to fire.
``SimulatedClock`` and ``RealClock`` are the old names of those two clocks.
"""

from __future__ import annotations

import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from statectl.kernel.errors import StatectlError
from statectl.out.scxml.datamodel import EvaluationError
from statectl.run.runtime.clock import Clock, SimClock, Timer, WallClock

if TYPE_CHECKING:
    from statectl.out.scxml.session import Session

#: The old name of :class:`~statectl.run.runtime.clock.SimClock` for SCXML runs.
SimulatedClock = SimClock
#: The old name of :class:`~statectl.run.runtime.clock.WallClock` for SCXML runs.
RealClock = WallClock

__all__ = ["RealClock", "Scheduler", "SessionTimeout", "SimulatedClock", "parse_delay"]


class SessionTimeout(StatectlError):
    """The run passed its wall-clock deadline; the session stops where it is."""


_DELAY = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*(ms|s|min|h)?\s*$")


#: Longest ``<send>`` delay, in seconds: the longest timeout a device table takes
#: (2**31 - 1 ms, about 24.8 days). A wall clock cannot wait for ``1e23s``.
MAX_DELAY = (2**31 - 1) / 1000


def parse_delay(text: str) -> float:
    """A CSS2 time (``'2s'``, ``'500ms'``) in seconds, at most :data:`MAX_DELAY`."""
    match = _DELAY.match(text)
    if match is None:
        raise EvaluationError(f"delay {text!r} is not a time such as '1s' or '500ms'")
    unit = match.group(2) or "s"
    seconds = float(match.group(1)) * {"ms": 0.001, "s": 1.0, "min": 60.0, "h": 3600.0}[unit]
    if not seconds <= MAX_DELAY:
        raise EvaluationError(
            f"delay {text.strip()[:40]!r} is longer than {MAX_DELAY:,.3f} s (about 24.8 days)"
        )
    return seconds


@dataclass(eq=False, slots=True)
class _Send:
    """A delayed send: the clock's timer and what to deliver when it fires."""

    session: Session
    sendid: str
    deliver: Callable[[], None]
    timer: Timer | None = field(default=None)
    cancelled: bool = False  # by <cancel>, also after the timer fired but before delivery


class Scheduler:
    """Runs sessions round-robin in one thread and fires delayed sends from a clock."""

    def __init__(
        self,
        clock: Clock | None = None,
        log: Callable[[str], None] | None = None,
        trace: Callable[[str], None] | None = None,
    ) -> None:
        self.clock: Clock = clock or SimClock()
        self.log = log or (lambda text: None)  # what <log> writes
        self.trace = trace or (lambda text: None)  # why an error event was raised
        self.sessions: dict[str, Session] = {}
        #: Delayed sends not yet delivered nor cancelled, in the order they were sent.
        self.pending: list[_Send] = []
        self._fired: deque[_Send] = deque()  # timers that fired, waiting for this thread
        self._cond = threading.Condition()
        #: ``time.monotonic()`` after which every session stops with :class:`SessionTimeout`.
        self.wall_deadline: float | None = None

    def check_deadline(self) -> None:
        """Raise :class:`SessionTimeout` once the wall-clock deadline has passed."""
        if self.wall_deadline is not None and time.monotonic() > self.wall_deadline:
            raise SessionTimeout("the run passed its wall-clock deadline")

    def add_timer(
        self, session: Session, delay: float, sendid: str, deliver: Callable[[], None]
    ) -> None:
        send = _Send(session, sendid, deliver)
        send.timer = self.clock.call_later(delay, lambda: self._fire(send))
        self.pending.append(send)

    def _fire(self, send: _Send) -> None:
        """The clock's callback (maybe on its thread): queue the send for the scheduler."""
        with self._cond:
            self._fired.append(send)
            self._cond.notify()

    def cancel_timers(self, session: Session, sendid: str) -> None:
        for send in self.pending:
            if send.session is session and send.sendid == sendid:
                send.cancelled = True
                if send.timer is not None:
                    send.timer.cancel()
        self.pending = [s for s in self.pending if not s.cancelled]

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
            if not self.pending:
                return None
            if not self._wait(deadline):
                return None
            self._deliver_fired()

    def _wait(self, deadline: float | None) -> bool:
        """Let time pass until a delayed send fires; ``False`` if ``deadline`` comes first."""
        clock = self.clock
        if isinstance(clock, SimClock):
            due = min(s.timer.when for s in self.pending if s.timer is not None)
            if deadline is not None and due > deadline:
                clock.run_until(max(deadline, clock.now()))
                return bool(self._fired)
            clock.run_until(max(due, clock.now()))
            return True
        with self._cond:
            while not self._fired:
                waits = []
                if deadline is not None:
                    waits.append(deadline - clock.now())
                if self.wall_deadline is not None:
                    waits.append(self.wall_deadline - time.monotonic())
                wait = min(waits) if waits else None
                if wait is not None and wait <= 0:
                    return False
                self._cond.wait(wait)
            return True

    def _deliver_fired(self) -> None:
        """Deliver every send whose timer fired, in firing order (due time, then send order)."""
        with self._cond:
            fired = list(self._fired)
            self._fired.clear()
        done = {id(s) for s in fired}
        self.pending = [s for s in self.pending if id(s) not in done]
        for send in fired:
            if not send.cancelled and send.session.running:
                send.deliver()
