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
4. A :class:`StepRecord` is what one event did, as one object: the kernel's step
   (or why nothing happened), the API calls its notifications made and anything
   recorded meanwhile (a monitor starting). Its typed records are those of rule 3,
   built the first time they are asked for, so a listener that reads only the
   outcome, or the states entered, never pays for them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

from statectl.model import Notify
from statectl.semantics import Unhandled

if TYPE_CHECKING:
    from collections.abc import Iterator

    from statectl.semantics import Step

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
    "StepRecord",
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


#: What one notification's observer did, as a step record keeps it: ``None`` (no observer),
#: the API calls it made (a driver that logs them), or the observer itself (one call).
_Made = tuple[ApiCall, ...] | object


class _Tail(NamedTuple):
    """What most step records do not have, kept apart so the common one is built quickly."""

    reason: Unhandled | None = None  # why the event changed nothing
    rejected: bool = False  # ... under policy ``error``
    final: bool = False  # the event finished the run
    upto: int | None = None  # the step failed after this many typed records
    extras: tuple[tuple[int, Record], ...] | list[tuple[int, Record]] = ()  # made meanwhile


class StepRecord:
    """What one event did, as one object; its typed :attr:`records` are built on demand.

    A :meth:`~statectl.runtime.subject.Subject.listen_steps` listener gets one per
    event (rule 4): ``event``, ``data``, the kernel's ``step`` (``None`` when the
    event changed nothing, then ``reason`` says why), ``entered`` and ``exited``.
    Records made outside any event (``Started``, a monitor's ``FaultDetected``,
    ``Finished``) come as a step record of their own, ``event`` ``None``. The
    typed records are exactly those a :meth:`~statectl.runtime.subject.Subject.listen`
    listener gets one by one, in the same order.
    """

    __slots__ = ("_made", "_records", "_tail", "data", "device", "event", "step", "time")

    def __init__(
        self,
        device: str,
        time: float,
        event: str | None,
        data: Any,
        step: Step | None,
        made: tuple[_Made, ...] | list[_Made] = (),
        tail: _Tail | None = None,
        records: tuple[Record, ...] | None = None,
    ) -> None:
        self.device = device
        self.time = time
        self.event = event
        self.data = data
        self.step = step
        self._made = made  # per notification performed, in order
        self._tail = tail  # what most steps do not have (_Tail), or None
        if records is not None:  # else made when first read (``records``)
            self._records = records

    @property
    def reason(self) -> Unhandled | None:
        """Why the event changed nothing (``None`` when it was handled)."""
        return self._tail.reason if self._tail is not None else None

    @property
    def rejected(self) -> bool:
        """Unhandled under policy ``error`` (``EventRejected``, not ``EventIgnored``)."""
        return self._tail is not None and self._tail.rejected

    @property
    def final(self) -> bool:
        """This event finished the run (``Finished`` closes its records)."""
        return self._tail is not None and self._tail.final

    @classmethod
    def of(cls, record: Record) -> StepRecord:
        """A record made outside any event, as a step record of its own."""
        return cls(record.device, record.time, None, None, None, (), None, (record,))

    @property
    def outcome(self) -> str:
        """``handled``, why the event changed nothing, or ``""`` outside an event."""
        if self.step is not None:
            return "handled"
        return self.reason.value if self.reason is not None else ""

    @property
    def entered(self) -> tuple[str, ...]:
        return self.step.entered if self.step is not None else ()

    @property
    def exited(self) -> tuple[str, ...]:
        return self.step.exited if self.step is not None else ()

    @property
    def failed(self) -> bool:
        """An observer or watcher raised during the step: its records end there."""
        return self._tail is not None and self._tail.upto is not None

    @property
    def meanwhile(self) -> tuple[Record, ...]:
        """The records others made during the step (a monitor starting), in order;
        read without building the step's own records."""
        tail = self._tail
        if tail is None or not tail.extras or self.event is None:
            return ()
        return tuple(record for _, record in tail.extras)

    @property
    def api_calls(self) -> int:
        """How many ``ObserverCalled`` records the step has, without building them."""
        tail = self._tail
        if self.event is None or (tail is not None and tail.upto is not None):
            return sum(type(r) is ObserverCalled for r in self.records)
        n = 0
        for made in self._made:  # per notification: its API calls, its observer, or None
            if made is not None:
                n += len(made) if isinstance(made, tuple) else 1
        return n

    @property
    def records(self) -> tuple[Record, ...]:
        """The typed records of rule 3 (and those made meanwhile), built once."""
        try:
            return self._records
        except AttributeError:  # not read yet
            records = self._records = _typed(self)
            return records

    def __iter__(self) -> Iterator[Record]:
        return iter(self.records)

    def __repr__(self) -> str:
        return f"StepRecord({self.device!r}, {self.time!r}, {self.event!r}, {self.outcome!r})"


#: A run of a step's typed records: their kinds, their fields after device and time,
#: and the notification whose ``InvokeIssued`` ends the run (its observer's calls follow).
_Run = tuple[tuple[Any, ...], tuple[tuple[Any, ...], ...], Notify | None]
#: Per step (by identity): its runs. Plans keep their steps, so a memoised step is
#: worked out once; bounded for the steps that are not memoised.
_TEMPLATES: dict[int, tuple[Step, tuple[_Run, ...]]] = {}
_TEMPLATES_MAX = 4096
_new = tuple.__new__


def _template(step: Step) -> tuple[_Run, ...]:
    """Rule 3's records of ``step`` without the observers' calls, as runs built in one go."""
    hit = _TEMPLATES.get(id(step))
    if hit is not None and hit[0] is step:
        return hit[1]
    runs: list[_Run] = []
    kinds: list[Any] = []
    fields: list[tuple[Any, ...]] = []
    for micro in step.microsteps:
        for s in micro.exited:
            kinds.append(StateExited)
            fields.append((s,))
        for x in micro.transitions:
            kinds.append(TransitionTaken)
            fields.append((micro.event, (x.source,), x.targets, x.label))
        for s in micro.entered:
            kinds.append(StateEntered)
            fields.append((s,))
        for a in micro.actions:
            if isinstance(a, Notify):
                kinds.append(InvokeIssued)
                fields.append((a.invoke, a.name, a.method, a.event))
                runs.append((tuple(kinds), tuple(fields), a))
                kinds, fields = [], []
    if kinds:
        runs.append((tuple(kinds), tuple(fields), None))
    if len(_TEMPLATES) >= _TEMPLATES_MAX:
        _TEMPLATES.clear()
    made = tuple(runs)
    _TEMPLATES[id(step)] = (step, made)
    return made


def _typed(r: StepRecord) -> tuple[Record, ...]:
    """Rule 3's records of a step record, with those made meanwhile put back in place."""
    d, t, step = r.device, r.time, r.step
    out: list[Record] = [EventReceived(d, t, r.event, r.data)] if r.event is not None else []
    if step is None:
        reason = r.reason
        if reason is not None and r.event is not None:
            kind = EventRejected if r.rejected else EventIgnored
            out.append(kind(d, t, r.event, reason))
    else:
        made = iter(r._made)
        dt = (d, t)
        for kinds, fields, a in _template(step):  # each run built by map(), no loop here
            out.extend(map(_new, kinds, map(dt.__add__, fields)))
            if a is None:
                continue
            did = next(made, None)
            if isinstance(did, tuple):
                out.extend(_new(ObserverCalled, (d, t, a.method, str(c))) for c in did)
            elif did is not None:
                api = f"{type(did).__name__}.update(#{a.invoke})"
                out.append(ObserverCalled(d, t, a.method, api))
        if r.final:
            out.append(Finished(d, t))
        upto = r._tail.upto if r._tail is not None else None
        if upto is not None:
            del out[upto:]
    extras = r._tail.extras if r._tail is not None else ()
    if not extras:
        return tuple(out)
    merged: list[Record] = []
    at = 0
    for before, record in extras:
        if before > at:
            merged.extend(out[at:before])
            at = before
        merged.append(record)
    merged.extend(out[at:])
    return tuple(merged)
