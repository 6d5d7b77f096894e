"""Helpers shared by the test modules (imported, not collected)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from statectl.observers import Notification
from statectl.runtime.records import fields_of

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
