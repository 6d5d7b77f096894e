"""``statectl run --json``: one JSON object per event line, so a script can check a scenario.

Rules:
1. An event line gives ``{"line", "t", "device", "event", "data", "handled",
   "why", "state", "invokes", "steps"}``: ``handled`` is whether the line's own
   event changed anything on its device; ``why`` is the reason it did not
   (``no transition``, ``guard false``, ``declared ignored``, ``unknown event``),
   else null; ``state`` is that device's configuration after the line settled
   (sorted); ``invokes`` the invokes issued meanwhile (by any device), in order;
   ``steps`` every event any device processed meanwhile (a driver's completions,
   a cell's links), each ``{"device", "event", "outcome"}``.
2. A ``+SECONDS`` line gives ``{"line", "t", "advance", "invokes", "steps"}``;
   a bad line ``{"line", "error"}`` (the message also goes to stderr). Blank
   and comment lines give nothing. A cell's objects add ``states``: every
   device's configuration.
4. An event the device's active state defers (its ``defer`` cell) is declared ignored by
   the kernel and kept by the runtime: its object adds ``"kept": true`` while a state
   that defers it is still active after the line, so "ignored" is not read as "lost"
   (not when the device already kept the most it keeps and dropped it).
5. Nothing else is written to standard output, so each output line is one
   JSON object (``jq``, ``json.loads`` per line).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any, TextIO

from statectl.kernel.model import Notify
from statectl.kernel.semantics import Outcome, Unhandled
from statectl.run.runtime.records import EventRejected, InvokeIssued, StepRecord
from statectl.run.system import System

__all__ = ["StepLog"]


class StepLog:
    """Rule 1-3: collects what one line caused, and writes it as one JSON object."""

    def __init__(self, system: System, out: TextIO) -> None:
        self._system = system
        self._out = out
        self._steps: list[dict[str, Any]] = []
        self._invokes: list[dict[str, Any]] = []
        self._dropped: set[tuple[str, str]] = set()
        system.listen_steps(self._record)
        system.listen(self._rejected)  # a deferral's drop is a record outside any step
        for name, subject in system.subjects.items():
            subject.on_step(self._stepper(name))

    def _stepper(self, device: str) -> Callable[[str, Any, str], None]:
        def stepped(event: str, _data: Any, outcome: str) -> None:
            self._steps.append({"device": device, "event": event, "outcome": str(outcome)})

        return stepped

    def _rejected(self, record: object) -> None:
        if isinstance(record, EventRejected) and record.reason is Unhandled.DECLARED_IGNORED:
            self._dropped.add((record.device, record.event))  # rule 4: the kept queue was full

    def _record(self, step: StepRecord) -> None:
        decided = step.step
        if step.event is not None and (
            decided is None or not any(isinstance(a, Notify) for a in decided.actions)
        ):
            return  # an event that issued nothing: its records are not built
        for record in step.records:
            if not isinstance(record, InvokeIssued):
                continue
            self._invokes.append(
                {
                    "device": record.device,
                    "invoke": record.invoke,
                    "name": record.name,
                    "method": record.method,
                    "event": record.event,
                }
            )

    def begin(self) -> None:
        """Forget what happened before this line (the start, a bad line)."""
        self._steps.clear()
        self._invokes.clear()
        self._dropped.clear()

    def event(self, number: int, device: str | None, event: str, data: Any) -> None:
        """Rule 1: the object for an event line, once it settled."""
        name = self._system.device(device)
        own = next(
            (s for s in self._steps if s["device"] == name and s["event"] == event),
            None,
        )
        outcome = "not processed" if own is None else own["outcome"]
        handled = outcome == Outcome.HANDLED
        self._write(
            {
                "line": number,
                "t": round(self._system.clock.now(), 6),
                "device": name,
                "event": event,
                "data": data,
                "handled": handled,
                "why": None if handled else outcome,
                "state": self._configuration(name),
                **({"kept": True} if not handled and self._kept(name, event) else {}),
            }
        )

    def _kept(self, name: str, event: str) -> bool:
        """Rule 4: an active state of ``name`` defers ``event`` now, and it was not dropped."""
        if (name, event) in self._dropped:
            return False
        subject = self._system.subjects[name]
        active = subject.configuration
        return any(event in s.defer for s in subject.chart.states if s.name in active)

    def advance(self, number: int, seconds: float) -> None:
        """Rule 2: the object for a ``+SECONDS`` line."""
        self._write({"line": number, "t": round(self._system.clock.now(), 6), "advance": seconds})

    def error(self, number: int, message: str) -> None:
        """Rule 2: the object for a bad line."""
        self._out.write(json.dumps({"line": number, "error": message}) + "\n")
        self.begin()

    def _configuration(self, name: str) -> list[str]:
        return sorted(self._system.subjects[name].configuration)

    def _write(self, obj: dict[str, Any]) -> None:
        obj["invokes"] = list(self._invokes)
        obj["steps"] = list(self._steps)
        if len(self._system.subjects) > 1:
            obj["states"] = {n: self._configuration(n) for n in self._system.subjects}
        self._out.write(json.dumps(obj, default=repr) + "\n")
        self._out.flush()
        self.begin()
