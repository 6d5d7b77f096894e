"""Helpers shared by the test modules (imported, not collected)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from statectl.observers import Notification

ROOT = Path(__file__).resolve().parents[1]
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"


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
    return [
        (type(r).__name__, *(getattr(r, f) for f in r._fields if f not in ("device", "time")))
        for r in records
    ]
