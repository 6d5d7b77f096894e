"""Helpers shared by the test modules (imported, not collected)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from statectl.front.observers import Notification
from statectl.run.devices import connect, make_driver
from statectl.run.runtime import Subject, attach_monitors
from statectl.run.runtime.records import fields_of

ROOT = Path(__file__).resolve().parents[1]
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"

#: Where the W3C SCXML conformance pack is read from (in place, never copied): the
#: environment variable, else beside the clone (docs/testing.md, "The W3C pack").
W3C_VARIABLE = "STATECTL_W3C_DIR"
W3C_PACK = Path(
    os.environ.get(W3C_VARIABLE) or ROOT.parent / "shared" / "conformance" / "w3c-scxml"
)
#: How a test that needs the pack says it was skipped; conftest.py's summary looks for it.
W3C_SKIPPED = f"W3C pack not found at {W3C_PACK} (set {W3C_VARIABLE} to its directory)"


#: The paper's whole Motor cycle, guarded event included, with the data Movement carries.
PAPER_CYCLE: tuple[tuple[str, Any], ...] = (
    ("Movement", {"amount": 10}),
    ("Movement completion", None),
    ("Initialization", None),  # guarded: previous == 'Moving'
    ("Initialization completion", None),
    ("Movement", {"amount": 10}),
    ("Error", None),
    ("Error completion", None),
)


class QuietFaults:
    """A fault source that never faults: a monitor polls it and finds nothing."""

    def poll_fault(self) -> str | None:
        return None


def wire_motor(subject: Subject, wiring: str) -> None:
    """Wire a Motor Subject as a test names it: ``bare`` (a Recorder), ``monitor`` (and
    its monitors), ``driver`` (the simulated motor, as the demo connects it), ``nobody``."""
    if wiring in ("bare", "monitor"):
        subject.attach(Recorder())
    if wiring == "monitor":
        attach_monitors(subject, QuietFaults())
    elif wiring == "driver":
        connect(subject, make_driver("sim-motor", {}, chart=subject.chart))


class Recorder:
    """An observer that remembers its notifications and may act on each."""

    def __init__(self, then: Any = None) -> None:
        self.seen: list[Notification] = []
        self.then = then

    def update(self, notification: Notification) -> None:
        self.seen.append(notification)
        if self.then is not None:
            self.then(notification)


def record_keys(records: Any) -> list[tuple[Any, ...]]:
    """Each record as (kind, its fields but device and time): what a trace compares."""
    return [(type(r).__name__, *fields_of(r)) for r in records]


#: A press whose Work is parallel: the ram presses while the clamp holds. Work is
#: entered with a device call (Start -> Go()); only the ram's completion ends it.
PARALLEL_PRESS = """\
device: Press
states:
  - state: Idle
    control: default
  - state: Work
    type: parallel
  - state: Ram
    parent: Work
  - state: Pressing
    parent: Ram
    control: event trigger required
  - state: Clamp
    parent: Work
  - state: Holding
    parent: Clamp
    control: event trigger required
events:
  - {event: Start, old: Idle, new: Work, kind: command, api: Go}
  - {event: Done, old: Pressing, new: Idle, kind: completion, api: Go}
  - {event: Release, old: Holding, new: Idle, kind: command}
"""
