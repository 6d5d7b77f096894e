"""SimTwin: a simulated twin of any device, derived from its tables, with no code per device.

Rules:
1. The twin serves every observer method of the chart. A notification for
   method ``M`` (a command or fault event drove the device) logs the API call
   ``M()`` and, ``delays[M]`` (else ``delay``) seconds later on the clock,
   reports the completion event of ``M`` that the device's state handles.
2. Which completion: the ``completion``-kind events of ``M``'s observer (the
   Event Definition rows with API ``M``) whose transition leaves a state the
   notification entered or one of its superstates (what the event's transitions
   enter is the kernel's entry set: targets, their ancestors, default children,
   every parallel region; a targetless transition stays in its source). None:
   nothing is reported and a note says why. Several: the first in table order, or a choice of the
   ``seed``'s random stream when a seed is given.
3. Work the device has not finished is superseded when a later notification
   leaves the state it entered (an Error in Moving), or comes from a state the
   device cannot be in beside it (that state was left by an event the twin did
   not see): its completion is cancelled, as a real device stops what it was
   doing.
4. Faults: ``inject_fault(detail, after)`` as every driver; and ``faults``
   (state -> seconds) arms a fault that ``poll_fault()`` reports that long
   after the twin saw the state entered (by a notification or by its own
   completion), unless the state was left first. Only a monitored state polls.
5. Notes (why nothing was reported, what was superseded) are kept in
   :attr:`SimTwin.notes`, go to the ``statectl.run.devices.twin`` logger and to
   :attr:`SimTwin.on_note` when a host sets it.
6. Rules 2 and 3 are not decided here: :mod:`statectl.kernel.semantics.calls`
   decides them, the one model ``statectl verify`` assumes too
   (:attr:`SimTwin.calls`); :attr:`SimTwin.pending_calls` are the calls as the
   explorer keeps them, and :meth:`SimTwin.complete_now` reports one at once
   (``run --replay`` plays a trace's completion steps with it).
"""

from __future__ import annotations

import logging
import random
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from statectl.front.observers import Notification
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart, ControlKind
from statectl.kernel.semantics.calls import Call, CallKey, DeviceCalls
from statectl.run.devices.base import Driver, finite_number
from statectl.run.runtime.clock import Timer

__all__ = ["DEFAULT_DELAY", "SimTwin", "TwinNote", "twin_option_problems"]

#: Seconds a twin takes for any method unless told otherwise.
DEFAULT_DELAY = 1.0

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class TwinNote:
    """Something the twin did not do, and why."""

    time: float
    method: str
    message: str

    def __str__(self) -> str:
        return f"{self.method}(): {self.message}"


@dataclass(frozen=True, slots=True)
class _Work:
    method: str
    event: str  # the event whose step called ``method``: with it, the call's key
    entered: frozenset[str]
    completion: str
    timer: Timer


def _seconds(value: Any) -> bool:
    return finite_number(value) and value >= 0


def _table_problems(name: str, value: Any) -> list[str]:
    if value is None:
        return []
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        return [f"{name} must map names to seconds (got {value!r})"]
    return [
        f"{name}[{k!r}] must be a number of seconds >= 0 (got {v!r})"
        for k, v in value.items()
        if not _seconds(v)
    ]


def twin_option_problems(options: Mapping[str, Any]) -> tuple[str, ...]:
    """Every problem with the values of SimTwin options that needs no chart to see."""
    problems: list[str] = []
    if "delay" in options and not _seconds(options["delay"]):
        problems.append(f"delay must be a number of seconds >= 0 (got {options['delay']!r})")
    problems += _table_problems("delays", options.get("delays"))
    problems += _table_problems("faults", options.get("faults"))
    seed = options.get("seed")
    if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool)):
        problems.append(f"seed must be an integer (got {seed!r})")
    return tuple(problems)


class SimTwin(Driver):
    """A device simulated from its own tables: every method completes after a delay."""

    def __init__(
        self,
        chart: Chart,
        *,
        delay: float = DEFAULT_DELAY,
        delays: Mapping[str, float] | None = None,
        faults: Mapping[str, float] | None = None,
        seed: int | None = None,
    ) -> None:
        super().__init__()
        problems = list(
            twin_option_problems({"delay": delay, "delays": delays, "faults": faults, "seed": seed})
        )
        methods = tuple(api.method for api in chart.apis)
        unknown = sorted(set(delays or {}) - set(methods))
        if unknown:
            problems.append(
                f"delays names method(s) {unknown} that {chart.name} does not have; "
                f"its observer methods: {', '.join(methods) or 'none'}"
            )
        monitored = tuple(s.name for s in chart.states if ControlKind.MONITORING in s.controls)
        strays = sorted(set(faults or {}) - set(monitored))
        if strays:
            problems.append(
                f"faults names state(s) {strays} that no monitor of {chart.name} watches; "
                f"monitored states: {', '.join(monitored) or 'none'}"
            )
        if problems:
            raise StatectlError(f"SimTwin for {chart.name}: " + "; ".join(problems))
        self.chart = chart
        self.calls = DeviceCalls(chart)  # which completion follows which call (shared)
        self.delay = float(delay)
        self.delays: dict[str, float] = {k: float(v) for k, v in (delays or {}).items()}
        self.faults: dict[str, float] = {k: float(v) for k, v in (faults or {}).items()}
        self.seed = seed
        self._rng = random.Random(seed) if seed is not None else None
        self._work: list[_Work] = []
        self._armed: dict[str, tuple[str, float]] = {}  # state -> (detail, due)
        self._notes: list[TwinNote] = []
        self.on_note: Callable[[TwinNote], None] | None = None

    # -- what the tables say ------------------------------------------------------------------

    @property
    def notes(self) -> Sequence[TwinNote]:
        return tuple(self._notes)

    @property
    def pending(self) -> tuple[str, ...]:
        """The completion events the twin will still report, in the order they were started."""
        with self._lock:
            return tuple(w.completion for w in self._work)

    @property
    def pending_calls(self) -> tuple[CallKey, ...]:
        """The calls the twin has not completed, as the explorer keeps them (sorted)."""
        with self._lock:
            return tuple(sorted({(w.method, w.event) for w in self._work}))

    # -- the driver protocol ------------------------------------------------------------------

    def serves(self) -> frozenset[str]:
        """Every observer method of its own chart (base rule 6)."""
        return frozenset(api.method for api in self.chart.apis)

    def update(self, notification: Notification) -> None:
        method, event = notification.method, notification.event
        with self._lock:
            self.method = method
            plan = self.calls.call(method, event)
            self._leave(plan, f"superseded by {event}")
            self._forget(plan, event)
            self.log_call(method)
            self._enter(plan.entered)
            if not plan.completions:
                self._note(method, f"reports nothing: {plan.reason}")
                return
            completion = self._choose(plan.completions)
            delay = self.delays.get(method, self.delay)
            # a WallClock may fire the timer on its thread before call_later returns: the
            # callback reads its work only under the lock, which is held until it is listed
            work: list[_Work] = []
            timer = self.clock.call_later(delay, lambda: self._finish(work))
            work.append(_Work(method, event, plan.entered, completion, timer))
            self._work.append(work[0])

    def poll_fault(self) -> str | None:
        detail = super().poll_fault()
        if detail is not None:
            return detail
        with self._lock:
            now = self.clock.now()
            for state, (text, due) in list(self._armed.items()):
                if due <= now:
                    del self._armed[state]
                    return text
        return None

    # -- simulation ---------------------------------------------------------------------------

    def _choose(self, completions: tuple[str, ...]) -> str:
        if self._rng is None or len(completions) == 1:
            return completions[0]
        return self._rng.choice(completions)

    def _finish(self, holder: list[_Work], completion: str | None = None) -> None:
        with self._lock:
            if not holder or holder[0] not in self._work:
                return  # never listed (call_later raised) or superseded
            work = holder[0]
            if completion is not None:  # another completion of the same call (a replay)
                work = _Work(work.method, work.event, work.entered, completion, work.timer)
                self._work[self._work.index(holder[0])] = work
            self._work.remove(work)
            self._disarm(work.entered)
            self._enter(self.calls.completion_entered(work.entered, work.completion))
        self.report(work.completion)

    def would_report(self, completion: str) -> bool:
        """Whether a pending call of the twin is completed by ``completion``."""
        with self._lock:
            return any(
                completion in self.calls.call(w.method, w.event).completions for w in self._work
            )

    def complete_now(self, completion: str) -> bool:
        """Report ``completion`` at once if a pending call it completes is listed (the
        oldest such); False when none is: the twin would never report it (a replay)."""
        with self._lock:
            work = next((w for w in self._work if w.completion == completion), None)
            if work is None:
                plans = (self.calls.call(w.method, w.event) for w in self._work)
                if not any(completion in p.completions for p in plans):
                    return False
                work = next(
                    w
                    for w in self._work
                    if completion in self.calls.call(w.method, w.event).completions
                )
            work.timer.cancel()
        self._finish([work], completion)
        return True

    def _leave(self, plan: Call, why: str) -> None:
        """Rule 3: cancel the work whose state ``plan`` leaves; disarm their faults."""
        for w in [w for w in self._work if self.calls.left_by(w.entered, plan)]:
            w.timer.cancel()
            self._work.remove(w)
            self._note(w.method, f"{w.completion} not reported: {why}")
        self._disarm(plan.left)

    def _forget(self, plan: Call, event: str) -> None:
        """Rule 3: work whose state the device cannot be in beside ``plan``'s sources was
        left unseen."""
        sources = plan.sources
        for w in list(self._work):
            if self.calls.unseen(w.entered, plan):
                w.timer.cancel()
                self._work.remove(w)
                self._note(
                    w.method,
                    f"{w.completion} not reported: {event} came from "
                    f"{', '.join(sorted(sources))}, so the device left "
                    f"{', '.join(sorted(w.entered))}",
                )

    def _enter(self, states: Iterable[str]) -> None:
        now = self.clock.now()
        for s in states:
            if s in self.faults:
                self._armed[s] = (f"simulated fault in {s}", now + self.faults[s])

    def _disarm(self, states: Iterable[str]) -> None:
        for s in states:
            self._armed.pop(s, None)

    def _note(self, method: str, message: str) -> None:
        note = TwinNote(self.clock.now(), method, message)
        self._notes.append(note)
        _log.info("%s: %s", self.chart.name, note)
        if self.on_note is not None:
            self.on_note(note)
