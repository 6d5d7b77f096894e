"""Time for the runtime: an injected clock, simulated or real.

Rules:
1. Everything that runs reads time from a :class:`Clock`; nothing calls
   ``time.time()`` or sleeps, so a :class:`SimClock` makes a timed scenario
   deterministic and instant.
2. ``call_later`` never blocks the caller and never runs ``fn`` on the
   caller's stack; it returns a :class:`Timer` whose ``cancel()`` is safe to
   call at any time, also after the timer fired.
3. :class:`SimClock` fires due timers in ``(time, sequence)`` order when it is
   advanced; a timer scheduled by a callback during an advance fires in that same
   advance if it is due by its end.
4. :class:`WallClock` runs one daemon timer thread over a heap; a callback that
   raises is reported to ``on_error`` and never stops the thread.
"""

from __future__ import annotations

import heapq
import itertools
import sys
import threading
import time
import traceback
from collections.abc import Callable
from typing import Protocol

import msgspec

from statectl.kernel.errors import StatectlError

__all__ = ["Clock", "SimClock", "Timer", "WallClock"]


class Timer(msgspec.Struct, eq=False):
    """A scheduled callback; ``cancel()`` stops it if it has not fired yet.

    A ``background`` timer (a monitor's poll) repeats for as long as its state is
    active; it is no work in flight, so "wait until the work is done" skips it.
    A mutable struct, compared by identity: a monitor makes one per poll and a driver
    one per move, and a struct is built in C (half a slotted dataclass's time).
    """

    when: float
    fn: Callable[[], object]
    cancelled: bool = False
    background: bool = False

    def cancel(self) -> None:
        self.cancelled = True


class Clock(Protocol):
    """What the runtime, monitors and drivers need of time."""

    def now(self) -> float: ...

    def call_later(
        self, delay: float, fn: Callable[[], object], *, background: bool = False
    ) -> Timer: ...


#: Heap size below which a SimClock never compacts.
_COMPACT_MIN = 64


def _check_delay(delay: float) -> float:
    if not delay >= 0:  # also refuses NaN
        raise StatectlError(f"timer delay must be a number >= 0 (got {delay!r})")
    return float(delay)


class SimClock:
    """A deterministic clock: time moves only when :meth:`advance` or :meth:`run_until` says."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = float(start)
        self._heap: list[tuple[float, int, Timer]] = []
        self._seq = itertools.count()
        self._compact_at = _COMPACT_MIN

    def now(self) -> float:
        return self._now

    def call_later(
        self, delay: float, fn: Callable[[], object], *, background: bool = False
    ) -> Timer:
        if type(delay) is not float or not delay >= 0:  # NaN too
            delay = _check_delay(delay)
        when = self._now + delay
        timer = Timer(when, fn, False, background)  # positional: a driver makes one per move
        heap = self._heap
        if len(heap) >= self._compact_at:
            self._compact()
        heapq.heappush(heap, (when, next(self._seq), timer))
        return timer

    def _compact(self) -> None:
        """Drop cancelled timers, which otherwise wait in the heap until time passes them.

        A monitor's poll is cancelled each time its state is left; while time stands
        still (events only) they would pile up. Compacting when the heap has doubled
        keeps it within twice the live timers, at amortised constant cost.
        """
        live = [entry for entry in self._heap if not entry[2].cancelled]
        heapq.heapify(live)
        self._heap[:] = live
        self._compact_at = max(_COMPACT_MIN, 2 * len(live))

    def next_deadline(self, *, work_only: bool = False) -> float | None:
        """When the earliest live timer is due, or ``None`` when none is pending.

        With ``work_only``, background timers (monitor polls) do not count.
        """
        while self._heap and self._heap[0][2].cancelled:
            heapq.heappop(self._heap)
        if not work_only:
            return self._heap[0][0] if self._heap else None
        due = [t.when for _, _, t in self._heap if not (t.cancelled or t.background)]
        return min(due) if due else None

    @property
    def pending(self) -> int:
        """Live (not cancelled, not fired) timers."""
        return sum(1 for _, _, t in self._heap if not t.cancelled)

    def run_until(self, t: float, settle: Callable[[], object] | None = None) -> int:
        """Fire every timer due by ``t`` in order, then set the time to ``t``.

        ``settle`` runs after each fired timer, so an owner can drain the events a
        timer posted before the next timer looks at the device. Returns how many fired.
        """
        if t < self._now:
            raise StatectlError(f"a SimClock cannot go back in time (now {self._now}, asked {t})")
        fired = 0
        while self._heap and self._heap[0][0] <= t:
            when, _, timer = heapq.heappop(self._heap)
            if timer.cancelled:
                continue
            self._now = when
            timer.cancelled = True  # fired: a late cancel() is a no-op
            timer.fn()
            fired += 1
            if settle is not None:
                settle()
        self._now = t
        return fired

    def advance(self, dt: float, settle: Callable[[], object] | None = None) -> int:
        """Move time forward by ``dt`` seconds, firing due timers (see :meth:`run_until`)."""
        return self.run_until(self._now + _check_delay(dt), settle)


def _print_error(exc: BaseException) -> None:
    traceback.print_exception(exc, file=sys.stderr)


class WallClock:
    """Real time (monotonic seconds since creation); timers run on one daemon thread."""

    def __init__(self, on_error: Callable[[BaseException], None] = _print_error) -> None:
        self._origin = time.monotonic()
        self._heap: list[tuple[float, int, Timer]] = []
        self._seq = itertools.count()
        self._cond = threading.Condition()
        self._thread: threading.Thread | None = None
        self._stopped = False
        self.on_error = on_error

    def now(self) -> float:
        return time.monotonic() - self._origin

    def call_later(
        self, delay: float, fn: Callable[[], object], *, background: bool = False
    ) -> Timer:
        timer = Timer(self.now() + _check_delay(delay), fn, background=background)
        with self._cond:
            if self._stopped:
                raise StatectlError("this WallClock was stopped; create a new one")
            heapq.heappush(self._heap, (timer.when, next(self._seq), timer))
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._run, name="statectl-timers", daemon=True
                )
                self._thread.start()
            self._cond.notify()
        return timer

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._stopped:
                    if self._heap:
                        wait = self._heap[0][0] - self.now()
                        if wait <= 0:
                            break
                        self._cond.wait(min(wait, threading.TIMEOUT_MAX))  # larger: OverflowError
                    else:
                        self._cond.wait()
                if self._stopped:
                    return
                _, _, timer = heapq.heappop(self._heap)
            if timer.cancelled:
                continue
            timer.cancelled = True
            try:
                timer.fn()
            except Exception as exc:  # a failing callback must not stop the other timers
                self.on_error(exc)

    def stop(self, timeout: float | None = 1.0) -> None:
        """Stop the timer thread; pending timers never fire."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
