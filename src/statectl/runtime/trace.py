"""One readable line per trace record.

Rules:
1. A line is ``t=<time>  <device>  <kind>  <text>``; time, device and kind are
   padded so the text column lines up down a trace.
2. Event data reads like YAML flow style (``{amount: 10}``); API calls read like
   the call (``SimMotor.move_to(10.0)``).
3. No colour codes unless asked for (``colour=True``), so a trace can be
   diffed, logged and pasted.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TextIO

from statectl.runtime.records import (
    EventIgnored,
    EventReceived,
    EventRejected,
    FaultDetected,
    Finished,
    InvokeIssued,
    MonitorStarted,
    MonitorStopped,
    ObserverCalled,
    Record,
    Started,
    StateEntered,
    StateExited,
    TransitionTaken,
)

__all__ = ["TraceWriter", "format_data", "format_record", "kind_of"]

KIND_WIDTH = 8
_COLOURS: Mapping[str, str] = {
    "event": "\x1b[1m",
    "state": "\x1b[36m",
    "invoke": "\x1b[35m",
    "api": "\x1b[35m",
    "ignored": "\x1b[33m",
    "rejected": "\x1b[31m",
    "fault": "\x1b[31m",
    "monitor": "\x1b[34m",
}
_RESET = "\x1b[0m"


def format_data(value: Any) -> str:
    """Event data in YAML flow style: ``{amount: 10, target: 2.5}``."""
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k}: {format_data(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(format_data(v) for v in value) + "]"
    if isinstance(value, str):
        plain = value and value.strip() == value and not any(c in value for c in ",:{}[]'\"#")
        return value if plain else repr(value)
    if isinstance(value, float):
        return f"{value:g}"
    return repr(value)


def _states(names: tuple[str, ...]) -> str:
    return ", ".join(names) if names else "(targetless)"


def kind_of(record: Record) -> str:
    """The short kind column of a record."""
    match record:
        case Started() | Finished():
            return "run"
        case EventReceived():
            return "event"
        case TransitionTaken():
            return "state"
        case StateExited():
            return "exit"
        case StateEntered():
            return "enter"
        case InvokeIssued():
            return "invoke"
        case ObserverCalled():
            return "api"
        case EventIgnored():
            return "ignored"
        case EventRejected():
            return "rejected"
        case MonitorStarted() | MonitorStopped():
            return "monitor"
        case FaultDetected():
            return "fault"


def _text(record: Record) -> str:
    match record:
        case Started():
            return "started"
        case Finished():
            return "finished"
        case EventReceived(event=event, data=data):
            return event if data is None else f"{event} {format_data(data)}"
        case TransitionTaken(source=source, targets=targets, label=label):
            return f"{_states(source)} -> {_states(targets)}  on {label or '(eventless)'}"
        case StateExited(state=state) | StateEntered(state=state):
            return state
        case InvokeIssued(invoke=invoke, name=name, method=method):
            return f"#{invoke} {name} -> observer {method}()"
        case ObserverCalled(method=method, api=api):
            return f"{method}() -> {api}"
        case EventIgnored(event=event, reason=reason):
            return f"{event} ({reason})"
        case EventRejected(event=event, reason=reason):
            if reason == "guard error":  # refused whatever the policy (runtime/eventdata.py)
                return f"{event} ({reason})"
            return f"{event} ({reason}; policy error)"
        case MonitorStarted(state=state):
            return f"{state} started"
        case MonitorStopped(state=state):
            return f"{state} stopped"
        case FaultDetected(state=state, event=event, detail=detail):
            return f"{detail!r} while {state} -> raises {event}"


def format_record(record: Record, *, device_width: int = 0, colour: bool = False) -> str:
    """One aligned line: ``t=   0.00  Motor  event    Movement {amount: 10}``."""
    kind = kind_of(record)
    padded = f"{kind:<{KIND_WIDTH}}"
    if colour:
        padded = f"{_COLOURS.get(kind, '')}{padded}{_RESET}"
    return f"t={record.time:7.2f}  {record.device:<{device_width}}  {padded} {_text(record)}"


class TraceWriter:
    """A listener that writes each record as a line to ``out``."""

    def __init__(self, out: TextIO, *, device_width: int = 0, colour: bool = False) -> None:
        self.out = out
        self.device_width = device_width
        self.colour = colour
        self.lines = 0

    def __call__(self, record: Record) -> None:
        self.out.write(
            format_record(record, device_width=self.device_width, colour=self.colour) + "\n"
        )
        self.lines += 1
