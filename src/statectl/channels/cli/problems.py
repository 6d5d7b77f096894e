"""What went wrong during a run that went on, and the exit code it makes (run rule 9).

``statectl run`` and ``statectl node`` count bad lines, unknown or rejected events,
refused environment commands, invariant violations and a cut-short settle; at the end
one line says what and the exit code is 1.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TextIO

from statectl.kernel.errors import UnhandledEventError
from statectl.kernel.exits import OK, PROBLEMS
from statectl.kernel.semantics import Unhandled
from statectl.run.runtime.records import EventIgnored, EventRejected, StepRecord

if TYPE_CHECKING:  # the explorer is imported by a cell's run only, not by every command
    from statectl.cell.explore.enforce import Violation

__all__ = ["Problems", "verdict"]


class Problems:
    """What went wrong during a run that went on (bad lines, unknown events)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()  # the feeder thread and the owner both count
        self.lines = 0  # event lines reported and skipped
        self.unknown = 0  # events no chart knows, or rejected under the 'error' policy
        self.unsettled = ""  # a batch settle stopped at --settle-limit: what to say
        self.refused = 0  # environment commands whose 'when' was false (a cell)
        self.violated = 0  # invariant violations seen live (a cell)
        self.failed = 0  # events a driver refused in a live run (system.py rule 7)
        self.partway = 0  # devices a bus outage left part-way (a driver's unfinished())

    def record(self, record: object) -> None:
        """A listener: count the events a device refused or did not know (a guard error is
        counted by :meth:`failure`, which hears it whether records are built or not)."""
        refused = (
            isinstance(record, EventRejected) and record.reason is not Unhandled.GUARD_ERROR
        ) or (isinstance(record, EventIgnored) and record.reason is Unhandled.UNKNOWN_EVENT)
        if refused:
            with self._lock:
                self.unknown += 1

    def step(self, step: StepRecord) -> None:
        """A step listener: :meth:`record` without building the records of a step."""
        if step.event is None:  # a record made outside any event
            for record in step.records:
                self.record(record)
        elif step.step is None and (
            (step.rejected and step.reason is not Unhandled.GUARD_ERROR)
            or step.reason is Unhandled.UNKNOWN_EVENT
        ):
            with self._lock:
                self.unknown += 1

    def failure(self, err: TextIO) -> Callable[[Exception], None]:
        """A System callback: a row that failed while draining (a guard or an assignment
        that raised) is said where and counted as rejected; a driver that refused an
        event's data is counted apart. Counted here, not from records: a run without a
        ``listen()`` listener gets no record of a guard error, and an assignment's none."""

        def say(exc: Exception) -> None:
            err.write(f"{exc}\n")
            with self._lock:
                if isinstance(exc, UnhandledEventError):
                    self.unknown += 1
                else:
                    self.failed += 1

        return say

    def refuse(self) -> None:
        with self._lock:
            self.refused += 1

    def violation(self, out: TextIO, width: int) -> Callable[[Violation], None]:
        """A System callback: each invariant violation goes into the trace and is counted."""

        def seen(v: Violation) -> None:
            with self._lock:
                self.violated += 1
            out.write(f"t={v.time:7.2f}  {'cell':<{width}}  {'VIOLATED':<8} {v}\n")

        return seen

    def counting(self, post: Callable[..., Any], err: TextIO) -> Callable[..., Any]:
        """``post`` for the dashboard: a refused command is reported and counted (rule 10)."""

        from statectl.cell.explore.enforce import Refused  # a cell's run has it loaded already

        def post_counted(device: str | None, event: str, data: Any = None, **how: Any) -> Any:
            try:
                return post(device, event, data, **how)
            except Refused as exc:
                err.write(f"statectl run: {exc}\n")
                self.refuse()
                raise

        return post_counted

    def bad_line(self) -> None:
        with self._lock:
            self.lines += 1

    def summary(self) -> str | None:
        """One line for the end of the run, or None when nothing went wrong."""
        parts = []
        if self.lines:
            parts.append(f"{self.lines} event line(s) reported above and skipped")
        if self.unknown:
            parts.append(f"{self.unknown} event(s) unknown to the device or rejected")
        if self.unsettled:
            parts.append(self.unsettled)
        if self.refused:
            parts.append(f"{self.refused} environment command(s) refused by the cell's 'when'")
        if self.violated:
            parts.append(f"{self.violated} invariant violation(s)")
        if self.failed:
            parts.append(f"{self.failed} event(s) a driver refused, reported above")
        if self.partway:
            parts.append(f"{self.partway} device(s) left part-way by a bus outage, reported above")
        return "; ".join(parts) or None


def verdict(problems: Problems, err: TextIO, command: str = "run") -> int:
    """Exit 1 when anything went wrong on the way, with one line saying what."""
    summary = problems.summary()
    if summary is None:
        return OK
    err.write(f"statectl {command}: {summary}: exit 1\n")
    return PROBLEMS
