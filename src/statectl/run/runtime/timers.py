"""Per-state timeouts: a state row's ``timeout: 5s -> Event`` armed on entry, cancelled on exit.

Rules:
1. One :class:`StateTimer` per state with a :class:`~statectl.kernel.model.Timeout`, hooked on
   the step as a :class:`~statectl.run.runtime.hooks.StateWatcher` of that state (as a
   monitor is): the step that enters the state arms a timer on the Subject's clock
   (``SimClock`` or ``WallClock``), the step that exits it cancels the timer, and the
   end of the run cancels every timer. A restored device re-arms the timers of its
   active states, counting from the restore.
2. When the timer fires, the timeout event is delivered on the owner (queued with
   ``call_soon``, so it never races the events the owner processes) only if the state
   has stayed active since the entry that armed it: a generation number, bumped by
   every entry and exit, drops a timer that fired while its cancel was on the way.
   It is then processed at once, at that point of the queue (:meth:`Subject.deliver`),
   so an event queued before the deadline cannot leave the state first and turn the
   timeout into an unhandled event.
3. The timeout event carries no data; records show it as any other event
   (``EventReceived`` and the transition it takes). A timeout is work in flight,
   not a background poll: :meth:`System.settle` waits for it as it waits for a
   device's completion.
4. :func:`attach_timers` is called by the Subject itself for a chart with timeouts,
   so every host (``statectl run``, a System, a bare Subject) gets them.
5. A timer hands its event to :attr:`StateTimer.report`: a bare Subject's own
   :meth:`~statectl.run.runtime.Subject.deliver`; in a System the door's reporter
   (run/door.py), which checks the ``timer`` origin against the commands policy and
   then delivers, still at once and at that point of the queue (rule 2), or drops a
   refused timeout.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from statectl.kernel.model import Timeout
from statectl.run.runtime.clock import Timer

if TYPE_CHECKING:
    from statectl.run.runtime.subject import Subject

__all__ = ["StateTimer", "attach_timers"]


class StateTimer:
    """Arms ``timeout`` while ``state`` is active and delivers its event when it runs out."""

    __slots__ = (
        "_generation",
        "_timer",
        "armed",
        "fired",
        "report",
        "state",
        "subject",
        "timeout",
    )

    def __init__(self, subject: Subject, state: str, timeout: Timeout) -> None:
        self.subject = subject
        self.state = state
        self.timeout = timeout
        self.armed = False
        self.fired = 0  # timeouts run out and handed to report
        #: who processes the timeout event at once (rule 5): the Subject, or a System's door
        self.report: Callable[[str, Any], None] = subject.deliver
        self._generation = 0
        self._timer: Timer | None = None

    # -- StateWatcher: called by the subject's step, on the owner

    def entered(self, state: str) -> None:
        self._cancel()
        self.armed = True
        generation = self._generation
        subject = self.subject
        self._timer = subject.clock.call_later(
            self.timeout.seconds, lambda: subject.call_soon(lambda: self._fire(generation))
        )

    def exited(self, state: str) -> None:
        self._cancel()

    def finished(self) -> None:
        self._cancel()

    def _cancel(self) -> None:
        self._generation += 1
        self.armed = False
        timer = self._timer
        if timer is not None:
            timer.cancel()
            self._timer = None

    def _fire(self, generation: int) -> None:
        if not self.armed or generation != self._generation:
            return  # left (or re-entered) since this timer was armed
        self.armed = False
        self._timer = None
        self.fired += 1
        self.report(self.timeout.event, None)


def attach_timers(subject: Subject) -> tuple[StateTimer, ...]:
    """A :class:`StateTimer` for every state of the subject's chart that has a timeout."""
    timers = tuple(
        StateTimer(subject, s.name, s.timeout) for s in subject.chart.states if s.timeout
    )
    for t in timers:
        subject.watch((t.state,), t)
    return timers
