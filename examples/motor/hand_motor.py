"""The Motor written by hand, as a vendor's driver with its own state logic would be.

Nothing of statectl runs here: the class keeps its own state, calls its API and
reports its own completions. The suite statectl testgen writes for motor.yaml checks
it (docs/testing.md, "Other implementations"):

    pytest tests/generated --statectl-impl python:hand_motor:HandMotor

The contract (statectl.out.testgen.adapters.python): ``HandMotor(api)``, ``send(event,
data)`` returning ``None`` (handled) or why not, ``states``; and, for the tests of
faults, monitors, completions and recovery, ``advance``, ``inject_fault``,
``monitoring`` and ``restart``.
"""

from __future__ import annotations

from typing import Any

#: What each state declares ignored (the tables' ignore cells).
IGNORED = {
    "Blocked": {"Movement completion", "Initialization", "Initialization completion", "Error",
                "Error completion"},
    "Moving": {"Movement", "Initialization", "Initialization completion", "Error completion"},
    "Returning": {"Movement", "Movement completion", "Initialization", "Error"},
}  # fmt: skip
#: (state, event) -> (next state, the API method it calls, or None)
MOVES = {
    ("Blocked", "Movement"): ("Moving", "Movement"),
    ("Moving", "Movement completion"): ("Blocked", None),
    ("Blocked", "Initialization"): ("Returning", "Initialization"),
    ("Returning", "Initialization completion"): ("Blocked", None),
    ("Moving", "Error"): ("Returning", "Error"),
    ("Returning", "Error completion"): ("Blocked", None),
}
WORK = 1.0  # seconds the motor takes for any call
POLL = 0.1  # seconds between two fault checks while Moving


class HandMotor:
    """A Motor: Blocked, Moving (monitored), Returning."""

    def __init__(self, api: Any) -> None:
        self.api = api
        self.state = "Blocked"
        self.previous = ""
        self.now = 0.0
        self.work: tuple[float, str] | None = None  # (due, the completion it reports)
        self.entered_by = ""  # the call that entered the state (what a restart redoes)
        self.fault: str | None = None
        self.polls = 0
        self.next_poll = 0.0

    @property
    def states(self) -> tuple[str, ...]:
        return (self.state,)

    def send(self, event: str, data: Any = None) -> str | None:
        move = MOVES.get((self.state, event))
        if move is None:
            return "declared ignored" if event in IGNORED[self.state] else "no transition"
        if event == "Initialization" and self.previous != "Moving":
            return "declared ignored"  # the row's guard is false; the state ignores it
        target, method = move
        self.previous, self.state = self.state, target
        self.work = None
        if method is not None:
            self.entered_by = method
            self._call(method, data)
        if target == "Moving":
            self.next_poll = self.now + POLL
        return None

    def _call(self, method: str, data: Any) -> None:
        getattr(self.api, method)(data)
        self.work = (self.now + WORK, f"{method} completion")

    def advance(self, seconds: float) -> list[str]:
        """Let time run: the motor reports its completion, the monitor checks for faults."""
        end, taken = self.now + seconds, []
        while True:
            poll = self.next_poll if self.state == "Moving" else None
            due = self.work[0] if self.work is not None else None
            first = min((t for t in (poll, due) if t is not None and t <= end), default=None)
            if first is None:
                break
            self.now = first
            if first == due and self.work is not None:
                completion = self.work[1]
                if self.send(completion) is None:
                    taken.append(completion)
            else:
                self.polls += 1
                self.next_poll = first + POLL
                if self.fault is not None:
                    detail, self.fault = self.fault, None
                    self.send("Error", {"detail": detail})
                    taken.append("Error")
        self.now = end
        return taken

    def inject_fault(self, detail: str) -> None:
        self.fault = detail

    def monitoring(self) -> dict[str, int]:
        return {"Moving": self.polls} if self.state == "Moving" else {}

    def restart(self) -> list[str]:
        """Power lost and back: the state is kept (it was persisted), the work is not."""
        self.work = None
        if self.state == "Moving":  # recovery: a motor that was moving takes Error
            self.send("Error", {"detail": "resumed after a restart"})
            return ["Error"]
        if self.state == "Returning":  # recovery: redo the call that entered Returning
            self._call(self.entered_by, None)
        return []
