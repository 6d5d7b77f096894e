"""Monitors: the paper's error thread, one per state that needs monitoring.

Rules:
1. Each ``MonitorSpec`` of :func:`statectl.front.observers.extract` becomes a
   :class:`Monitor` that runs only while its state is active: a
   :class:`~statectl.run.runtime.subject.StateWatcher` of that state, it starts when
   the step enters it and stops when a step exits it (or the run finishes). It
   hooks the step, not the record stream, so a monitored device keeps the plan
   path; ``MonitorStarted`` / ``MonitorStopped`` are recorded for listeners.
2. While running it polls the device every ``period`` seconds on the Subject's
   clock, the first poll one period after the state was entered. The poll itself
   runs on the Subject's owner (queued with ``call_soon``), so it never races the
   events the owner processes. Leaving the state leaves the poll timer armed: a
   state left and entered again within a period (a command cycle) reuses it, and
   a timer due before the next poll only arms itself again; :meth:`Monitor.finished`
   (the end of the run) cancels it.
3. When ``poll_fault()`` returns a detail string the monitor records
   ``FaultDetected`` and posts the state's first fault event with
   ``{"detail": detail}`` as its data to :attr:`Monitor.report` (the Subject's own
   ``post``; in a System the door's reporter, which checks the ``monitor`` origin,
   run/door.py); the transition it drives stops the monitor.
4. A monitored state with no fault event leaving it gets no monitor: there is
   nothing it could raise (``statectl check`` reports such a state).
"""

from __future__ import annotations

from functools import partial
from typing import Protocol

from statectl.front.observers import MonitorSpec, extract
from statectl.kernel.errors import StatectlError
from statectl.run.runtime.clock import Timer
from statectl.run.runtime.records import FaultDetected, MonitorStarted, MonitorStopped
from statectl.run.runtime.subject import Subject

__all__ = ["DEFAULT_PERIOD", "FaultSource", "Monitor", "attach_monitors"]

#: Seconds between two polls of a device, unless told otherwise.
DEFAULT_PERIOD = 0.1
#: A timer this close to the due time polls (clock arithmetic is floating point).
_EARLY = 1e-9


class FaultSource(Protocol):
    """What a monitor needs of a device: a fault detail, reported once, or ``None``."""

    def poll_fault(self) -> str | None: ...


class Monitor:
    """Watches ``device`` while ``spec.state`` is active and raises ``spec.raises[0]``."""

    def __init__(
        self, subject: Subject, spec: MonitorSpec, device: FaultSource, period: float
    ) -> None:
        if not period > 0:
            raise StatectlError(f"a monitor period must be > 0 seconds (got {period!r})")
        if not spec.raises:
            raise StatectlError(f"state {spec.state!r} has no fault event for a monitor to raise")
        self.subject = subject
        self.spec = spec
        self.device = device
        self.period = period
        self.active = False
        self.polls = 0
        #: where a fault's event goes (rule 3): the Subject's queue, or a System's door
        self.report = subject.post
        self._timer: Timer | None = None  # armed (or fired, its poll not yet run), or None
        self._due = 0.0  # when the next poll is due while active
        # what the timer calls: the poll queued for the owner (rule 2), made once here,
        # not a bound method and a closure per poll
        self._fired = partial(subject.call_soon, self._poll)

    # -- StateWatcher: called by the subject's step, on the owner

    def entered(self, state: str) -> None:
        if self.active:
            return
        self.active = True
        s = self.subject
        now = s.clock.now()
        self._due = now + self.period
        if s.listening:
            s.emit(MonitorStarted(s.name, now, self.spec.state))
        if self._timer is None:  # else the armed timer comes first and waits the rest
            self._arm(self.period)

    def exited(self, state: str) -> None:
        self._stop(record=True)

    def finished(self) -> None:
        self._stop(record=False)
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _stop(self, *, record: bool) -> None:
        """Stop polling. The timer stays armed: a state left and entered again within a
        period (a command cycle) reuses it instead of cancelling one and making another;
        when it comes due for a stopped monitor it does nothing."""
        if not self.active:
            return
        self.active = False
        s = self.subject
        if record and s.listening:
            s.emit(MonitorStopped(s.name, s.clock.now(), self.spec.state))

    def _arm(self, delay: float) -> None:
        self._timer = self.subject.clock.call_later(delay, self._fired, background=True)

    def _poll(self) -> None:
        self._timer = None
        if not self.active:  # left since (also: a poll queued before the state was left)
            return
        now = self.subject.clock.now()
        if self._due - now > _EARLY:  # entered again after the timer was armed
            self._arm(self._due - now)
            return
        self.polls += 1
        detail = self.device.poll_fault()
        if detail is not None:
            s = self.subject
            event = self.spec.raises[0]
            if s.listening:
                s.emit(FaultDetected(s.name, now, self.spec.state, event, detail))
            self.report(event, {"detail": detail})
        self._due = now + self.period
        self._arm(self.period)


def attach_monitors(
    subject: Subject, device: FaultSource, *, period: float = DEFAULT_PERIOD
) -> tuple[Monitor, ...]:
    """Create and register a monitor for every monitored state of the subject's chart.

    Call before :meth:`Subject.start` so a monitored initial state is watched too.
    """
    monitors = tuple(
        Monitor(subject, spec, device, period)
        for spec in extract(subject.chart).monitors
        if spec.raises
    )
    for m in monitors:
        subject.watch((m.spec.state,), m)
    return monitors
