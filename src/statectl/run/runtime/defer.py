"""Deferred events: an event in a state's ``defer`` cell is kept while that state is active.

Rules:
1. The kernel treats a deferred event as declared ignored in its state (the chart's
   :attr:`~statectl.kernel.model.Chart.deferred` pairs join its ignored pairs), so it changes
   nothing and is never an error under policy ``error``. A :class:`Deferrer`, a step
   listener of the Subject, then keeps it with its data when an active state defers it.
2. After every step, kept events that no active state defers any more are released,
   in the order they arrived, each processed before anything queued meanwhile
   (:meth:`Subject.call_next`): handled there, or unhandled as any event (a kept event
   that the new configuration defers too stays kept, in its place). So an event is
   never kept longer than the state that defers it is active: a command given during
   a move is not carried into a much later state.
3. At most :data:`MAX_DEFERRED` events are kept; one more is dropped and counted in
   :attr:`Deferrer.dropped`, with an ``EventRejected`` record for listeners, so a
   device flooded with deferred events stays bounded. The generated C++ keeps the same
   number in a fixed array (statectl.out.codegen.cpp_timers) and drops the same way.
4. Kept events live in memory: a restarted (journalled) device resumes with none.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any

from statectl.kernel.model import Kept, keep_deferred, take_released
from statectl.kernel.semantics import Unhandled
from statectl.run.runtime.records import EventRejected

if TYPE_CHECKING:
    from statectl.run.runtime.subject import Subject

__all__ = ["Deferrer", "attach_defer"]


class Deferrer:
    """Keeps the deferred events of one Subject and releases them when their state is left."""

    __slots__ = ("_scheduled", "dropped", "kept", "subject")

    def __init__(self, subject: Subject) -> None:
        self.subject = subject
        self.kept: deque[Kept] = deque()
        self.dropped = 0
        self._scheduled = False

    def deferring(self) -> tuple[str, ...]:
        """The events the active configuration defers now (the chart's answer)."""
        subject = self.subject
        return subject.chart.deferring(subject.configuration)

    def heard(self, event: str, data: Any, outcome: str) -> None:
        """The step listener: keep a deferred arrival, release what is no longer deferred."""
        if outcome == Unhandled.DECLARED_IGNORED and event in self.deferring():
            if not keep_deferred(self.kept, event, data):  # rule 3: no room
                self.dropped += 1
                s = self.subject
                if s.listening:
                    s.emit(EventRejected(s.name, s.clock.now(), event, Unhandled.DECLARED_IGNORED))
            return
        if self.kept and not self._scheduled:
            self._schedule()

    def _schedule(self) -> None:
        deferring = self.deferring()
        if any(event not in deferring for event, _ in self.kept):
            self._scheduled = True
            self.subject.call_next(self._release)

    def _release(self) -> None:
        """On the owner, before anything queued: deliver the first kept event not deferred."""
        self._scheduled = False
        released = take_released(self.kept, self.deferring())
        if released is not None:
            self.subject.deliver(*released)
        if self.kept and not self._scheduled:
            self._schedule()


def attach_defer(subject: Subject) -> Deferrer:
    """A :class:`Deferrer` listening to the subject's steps (the Subject calls it itself)."""
    deferrer = Deferrer(subject)
    subject.on_step(deferrer.heard)
    return deferrer
