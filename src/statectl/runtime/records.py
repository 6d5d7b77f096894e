"""The typed trace records a running device emits, and the API call value they describe.

Rules:
1. The set of records is closed (:data:`Record`); every record is an immutable
   value carrying the ``device`` it is about and the clock ``time``. Records are
   named tuples whose equality also compares their kind (a ``StateEntered`` never
   equals a ``StateExited`` with the same fields): a listener gets several per
   event, and a frozen dataclass costs three times as much to build.
2. Listeners receive records in the order things happened, never strings;
   formatting is :mod:`statectl.runtime.trace`'s job.
3. For one event the order is: ``EventReceived``, then per microstep
   ``StateExited``..., ``TransitionTaken``..., ``StateEntered``..., then that
   microstep's ``InvokeIssued`` + ``ObserverCalled``...; or, when no transition
   was taken, ``EventReceived`` then one ``EventIgnored`` / ``EventRejected``.
"""

from __future__ import annotations

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


def _same_kind_eq(self: tuple[Any, ...], other: object) -> bool:
    return type(self) is type(other) and tuple.__eq__(self, other)


def _same_kind_ne(self: tuple[Any, ...], other: object) -> bool:
    return not _same_kind_eq(self, other)


def _same_kind_hash(self: tuple[Any, ...]) -> int:
    return hash((type(self).__name__, *self))


class Started(NamedTuple):
    device: str
    time: float


class EventReceived(NamedTuple):
    device: str
    time: float
    event: str
    data: Any = None


class TransitionTaken(NamedTuple):
    """One transition of a microstep; ``event`` is ``None`` for an eventless one."""

    device: str
    time: float
    event: str | None
    source: tuple[str, ...]
    targets: tuple[str, ...]
    label: str


class StateExited(NamedTuple):
    device: str
    time: float
    state: str


class StateEntered(NamedTuple):
    device: str
    time: float
    state: str


class InvokeIssued(NamedTuple):
    device: str
    time: float
    invoke: int
    name: str
    method: str
    event: str


class ObserverCalled(NamedTuple):
    """The observer method ran and called ``api`` (e.g. ``SimMotor.move_to(10.0)``)."""

    device: str
    time: float
    method: str
    api: str


class EventIgnored(NamedTuple):
    device: str
    time: float
    event: str
    reason: IgnoreReason


class EventRejected(NamedTuple):
    """An unhandled event under the ``error`` policy."""

    device: str
    time: float
    event: str
    reason: IgnoreReason


class MonitorStarted(NamedTuple):
    device: str
    time: float
    state: str


class MonitorStopped(NamedTuple):
    device: str
    time: float
    state: str


class FaultDetected(NamedTuple):
    """A monitor found a fault while ``state`` was active and raises ``event``."""

    device: str
    time: float
    state: str
    event: str
    detail: str


class Finished(NamedTuple):
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


for _kind in (
    Started,
    EventReceived,
    TransitionTaken,
    StateExited,
    StateEntered,
    InvokeIssued,
    ObserverCalled,
    EventIgnored,
    EventRejected,
    MonitorStarted,
    MonitorStopped,
    FaultDetected,
    Finished,
):  # rule 1: a record equals only a record of its own kind
    _kind.__eq__ = _same_kind_eq  # type: ignore[method-assign]  # see rule 1
    _kind.__ne__ = _same_kind_ne  # type: ignore[assignment,method-assign]  # see rule 1
    _kind.__hash__ = _same_kind_hash  # type: ignore[method-assign]  # see rule 1


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
