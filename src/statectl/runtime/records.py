"""The typed trace records a running device emits, and the API call value they describe.

Rules:
1. The set of records is closed (:data:`Record`); every record is a frozen,
   slotted value carrying the ``device`` it is about and the clock ``time``.
2. Listeners receive records in the order things happened, never strings;
   formatting is :mod:`statectl.runtime.trace`'s job.
3. For one event the order is: ``EventReceived``, then per microstep
   ``StateExited``..., ``TransitionTaken``..., ``StateEntered``..., then that
   microstep's ``InvokeIssued`` + ``ObserverCalled``...; or, when no transition
   was taken, ``EventReceived`` then one ``EventIgnored`` / ``EventRejected``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

from statectl.semantics import Unhandled

__all__ = [
    "ApiCall",
    "EventIgnored",
    "EventReceived",
    "EventRejected",
    "FaultDetected",
    "Finished",
    "IgnoreReason",
    "InvokeIssued",
    "MonitorStarted",
    "MonitorStopped",
    "ObserverCalled",
    "Record",
    "Started",
    "StateEntered",
    "StateExited",
    "TransitionTaken",
    "format_args",
]

#: Why an event changed nothing: the kernel's :class:`~statectl.semantics.Unhandled`
#: (a ``str`` enum, so it compares, prints and serialises as ``"guard false"`` etc.).
IgnoreReason = Unhandled


@dataclass(frozen=True, slots=True)
class Started:
    device: str
    time: float


@dataclass(frozen=True, slots=True)
class EventReceived:
    device: str
    time: float
    event: str
    data: Any = None


@dataclass(frozen=True, slots=True)
class TransitionTaken:
    """One transition of a microstep; ``event`` is ``None`` for an eventless one."""

    device: str
    time: float
    event: str | None
    source: tuple[str, ...]
    targets: tuple[str, ...]
    label: str


@dataclass(frozen=True, slots=True)
class StateExited:
    device: str
    time: float
    state: str


@dataclass(frozen=True, slots=True)
class StateEntered:
    device: str
    time: float
    state: str


@dataclass(frozen=True, slots=True)
class InvokeIssued:
    device: str
    time: float
    invoke: int
    name: str
    method: str
    event: str


@dataclass(frozen=True, slots=True)
class ObserverCalled:
    """The observer method ran and called ``api`` (e.g. ``SimMotor.move_to(10.0)``)."""

    device: str
    time: float
    method: str
    api: str


@dataclass(frozen=True, slots=True)
class EventIgnored:
    device: str
    time: float
    event: str
    reason: IgnoreReason


@dataclass(frozen=True, slots=True)
class EventRejected:
    """An unhandled event under the ``error`` policy."""

    device: str
    time: float
    event: str
    reason: IgnoreReason


@dataclass(frozen=True, slots=True)
class MonitorStarted:
    device: str
    time: float
    state: str


@dataclass(frozen=True, slots=True)
class MonitorStopped:
    device: str
    time: float
    state: str


@dataclass(frozen=True, slots=True)
class FaultDetected:
    """A monitor found a fault while ``state`` was active and raises ``event``."""

    device: str
    time: float
    state: str
    event: str
    detail: str


@dataclass(frozen=True, slots=True)
class Finished:
    device: str
    time: float


Record = (
    Started
    | EventReceived
    | TransitionTaken
    | StateExited
    | StateEntered
    | InvokeIssued
    | ObserverCalled
    | EventIgnored
    | EventRejected
    | MonitorStarted
    | MonitorStopped
    | FaultDetected
    | Finished
)


def format_args(args: tuple[Any, ...]) -> str:
    return ", ".join(repr(a) for a in args)


class ApiCall(NamedTuple):
    """One call a driver made to its device's API; ``str()`` reads ``SimMotor.move_to(10.0)``.

    A named tuple (immutable, built in a third of a frozen dataclass's time): a
    driver logs one for every call it makes.
    """

    time: float
    device: str  # the driver class, as the API's owner
    function: str
    args: tuple[Any, ...] = ()

    def __str__(self) -> str:
        return f"{self.device}.{self.function}({format_args(self.args)})"
