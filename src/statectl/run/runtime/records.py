"""The typed trace records a running device emits, and the API call value they describe.

Rules:
1. The set of records is closed (:data:`Record`); every record is an immutable
   value carrying the ``device`` it is about and the clock ``time``. Records are
   frozen ``msgspec`` structs, not named tuples: a listener that reads records gets
   about five per event, and a struct is built in a third of a named tuple's time
   (and kept out of the cyclic collector). A record equals only a record of its own
   kind with the same fields; :func:`fields_of` gives the fields after device and time.
2. Listeners receive records in the order things happened, never strings;
   formatting is :mod:`statectl.run.runtime.trace`'s job.
3. For one event the order is: ``EventReceived``, then per microstep one
   ``MicrostepTaken`` (the states it exited, the transitions it took, the states it
   entered: what the kernel's microstep says, once), then that microstep's
   ``InvokeIssued`` + ``ObserverCalled``...; or, when no transition was taken,
   ``EventReceived`` then one ``EventIgnored`` / ``EventRejected``. A monitor
   starting or stopping for the microstep's states comes right after its
   ``MicrostepTaken``. One record per microstep rather than one per state and
   transition: a listener that reads every record gets three or four per event
   of the paper's Motor, not six, and a transition across levels of a nested
   chart is still one record.
4. A :class:`StepRecord` is what one event did, as one object: the kernel's step
   (or why nothing happened), the API calls its notifications made and anything
   recorded meanwhile (a monitor starting). Its typed records are those of rule 3,
   built the first time they are asked for, so a listener that reads only the
   outcome, or the states entered, never pays for them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import msgspec

from statectl.kernel.model import Notify
from statectl.kernel.semantics import Outcome, Step, Unhandled  # at run time: fields resolve

if TYPE_CHECKING:
    from collections.abc import Iterator

    from statectl.kernel.semantics import Microstep

__all__ = [
    "ApiCall",
    "Builder",
    "EventIgnored",
    "EventReceived",
    "EventRejected",
    "FaultDetected",
    "Finished",
    "IgnoreReason",
    "InvokeIssued",
    "MicrostepTaken",
    "MonitorStarted",
    "MonitorStopped",
    "ObserverCalled",
    "Record",
    "Started",
    "StepRecord",
    "Taken",
    "fields_of",
    "format_args",
    "records_plan",
]

#: Why an event changed nothing: the kernel's :class:`~statectl.kernel.semantics.Unhandled`
#: (a ``str`` enum, so it compares, prints and serialises as ``"guard false"`` etc.).
IgnoreReason = Unhandled


class _Record(msgspec.Struct, frozen=True, gc=False):
    """What every record has: the device it is about and the clock time (rule 1)."""

    device: str
    time: float


class Started(_Record, frozen=True, gc=False):
    pass


class EventReceived(_Record, frozen=True, gc=False):
    event: str
    data: Any = None


class Taken(msgspec.Struct, frozen=True, gc=False):
    """One transition a microstep took: from ``source`` to ``targets``, on ``label``."""

    source: str
    targets: tuple[str, ...]
    label: str  # the event, or "" for an eventless transition


class MicrostepTaken(_Record, frozen=True, gc=False):
    """One microstep: what it ``exited``, the ``transitions`` it took, what it ``entered``.

    ``event`` is ``None`` for an eventless microstep and for the configuration a
    device starts in or is restored to (no transition then). States are in the
    kernel's order: exits innermost first, entries outermost first.
    """

    event: str | None
    exited: tuple[str, ...]
    transitions: tuple[Taken, ...]
    entered: tuple[str, ...]


class InvokeIssued(_Record, frozen=True, gc=False):
    invoke: int
    name: str
    method: str
    event: str


class ObserverCalled(_Record, frozen=True, gc=False):
    """The observer method ran and called ``api`` (e.g. ``SimMotor.move_to(10.0)``)."""

    method: str
    api: str


class EventIgnored(_Record, frozen=True, gc=False):
    event: str
    reason: IgnoreReason


class EventRejected(_Record, frozen=True, gc=False):
    """An unhandled event under the ``error`` policy."""

    event: str
    reason: IgnoreReason


class MonitorStarted(_Record, frozen=True, gc=False):
    state: str


class MonitorStopped(_Record, frozen=True, gc=False):
    state: str


class FaultDetected(_Record, frozen=True, gc=False):
    """A monitor found a fault while ``state`` was active and raises ``event``."""

    state: str
    event: str
    detail: str


class Finished(_Record, frozen=True, gc=False):
    pass


Record = (
    Started
    | EventReceived
    | MicrostepTaken
    | InvokeIssued
    | ObserverCalled
    | EventIgnored
    | EventRejected
    | MonitorStarted
    | MonitorStopped
    | FaultDetected
    | Finished
)


def fields_of(record: Record) -> tuple[Any, ...]:
    """A record's fields after ``device`` and ``time``, in order (what makes it this record)."""
    return msgspec.structs.astuple(record)[2:]


def format_args(args: tuple[Any, ...]) -> str:
    return ", ".join(map(repr, args))


class ApiCall(msgspec.Struct, frozen=True, gc=False):
    """One call a driver made to its device's API; ``str()`` reads ``SimMotor.move_to(10.0)``.

    A frozen struct (immutable, built in a fraction of a frozen dataclass's time): a
    driver logs one for every call it makes.
    """

    time: float
    device: str  # the driver class, as the API's owner
    function: str
    args: tuple[Any, ...] = ()

    def __str__(self) -> str:
        return f"{self.device}.{self.function}({format_args(self.args)})"


#: What one notification's observer did, as a step record keeps it: ``None`` (no observer),
#: the API calls it made (a driver that logs them), or, for an observer that logs none,
#: the ``ObserverCalled.api`` of its one call (:func:`update_api`).
_Made = tuple[ApiCall, ...] | str | None


class _Tail(msgspec.Struct, frozen=True):
    """What most step records do not have, kept apart so the common one is built quickly
    (a struct: a named tuple's constructor took four times as long, 208 against 49 ns)."""

    reason: Unhandled | None = None  # why the event changed nothing
    rejected: bool = False  # ... under policy ``error``
    final: bool = False  # the event finished the run
    upto: int | None = None  # the step failed after this many typed records
    extras: tuple[tuple[int, Record], ...] | list[tuple[int, Record]] = ()  # made meanwhile


class StepRecord(msgspec.Struct, eq=False):
    """What one event did, as one object; its typed :attr:`records` are built on demand.

    A :meth:`~statectl.run.runtime.subject.Subject.listen_steps` listener gets one per
    event (rule 4): ``event``, ``data``, the kernel's ``step`` (``None`` when the
    event changed nothing, then ``reason`` says why), ``entered`` and ``exited``.
    Records made outside any event (``Started``, a monitor's ``FaultDetected``,
    ``Finished``) come as a step record of their own, ``event`` ``None``. The
    typed records are exactly those a :meth:`~statectl.run.runtime.subject.Subject.listen`
    listener gets one by one, in the same order. A struct (compared by identity):
    one is built per event for every step listener, in half a plain class's time.
    """

    device: str
    time: float
    event: str | None
    data: Any
    step: Step | None
    _made: tuple[_Made, ...] | list[_Made] = ()  # per notification performed, in order
    _tail: _Tail | None = None  # what most steps do not have, or None
    _records: tuple[Record, ...] | None = None  # made when first read (``records``)
    _builder: Builder | None = None  # its program's, which makes its typed records

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
    def outcome(self) -> Outcome | str:
        """What the event did (an :class:`~statectl.kernel.semantics.Outcome`, a ``str``
        enum: ``"handled"`` or why it changed nothing), or ``""`` outside an event."""
        if self.step is not None:
            return Outcome.HANDLED
        return self.reason if self.reason is not None else ""

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
                n += 1 if type(made) is str else len(made)
        return n

    @property
    def records(self) -> tuple[Record, ...]:
        """The typed records of rule 3 (and those made meanwhile), built once."""
        records = self._records
        if records is None:  # not read yet
            builder = self._builder
            if builder is not None and self._tail is None:  # a program's usual step
                compiled = builder.compiled
                built = compiled(self) if compiled is not None else builder.build(self)
                records = self._records = built
            else:
                records = self._records = _typed(self)
        return records

    def __iter__(self) -> Iterator[Record]:
        return iter(self.records)

    def __repr__(self) -> str:
        return f"StepRecord({self.device!r}, {self.time!r}, {self.event!r}, {str(self.outcome)!r})"


#: Builds rule 3's records of one step record whose step is known (rule 3).
_Build = Callable[["StepRecord"], "tuple[Record, ...]"]
#: ``ObserverCalled.api`` of an observer that logs no API calls, per (its type, invoke).
_UPDATES: dict[tuple[type, int], str] = {}
_UPDATES_MAX = 4096


def update_api(observer: object, invoke: int) -> str:
    """``ObserverCalled.api`` of an observer that logs no API calls: ``Counter.update(#0)``."""
    api = _UPDATES.get((type(observer), invoke))
    if api is None:
        if len(_UPDATES) >= _UPDATES_MAX:
            _UPDATES.clear()
        api = _UPDATES[type(observer), invoke] = f"{type(observer).__name__}.update(#{invoke})"
    return api


def _called(out: list[Record], d: str, t: float, did: _Made, method: str) -> None:
    """The ``ObserverCalled`` records of one notification, from what its observer did."""
    if type(did) is str:
        out.append(ObserverCalled(d, t, method, did))
    elif did is not None:
        out.extend([ObserverCalled(d, t, method, str(c)) for c in did])


#: Per kernel microstep (by identity): its transitions as ``Taken`` values. A memoised
#: step's microsteps recur, so a record listener's ``MicrostepTaken`` reuses them.
_TAKEN: dict[int, tuple[Microstep, tuple[Taken, ...]]] = {}


def taken(micro: Microstep) -> tuple[Taken, ...]:
    """The transitions of a kernel microstep as a ``MicrostepTaken`` record gives them."""
    hit = _TAKEN.get(id(micro))
    if hit is not None and hit[0] is micro:
        return hit[1]
    made = tuple(Taken(x.source, x.targets, x.label) for x in micro.transitions)
    if len(_TAKEN) >= _UPDATES_MAX:
        _TAKEN.clear()
    _TAKEN[id(micro)] = (micro, made)
    return made


def records_plan(step: Step) -> list[tuple[Any, tuple[Any, ...]] | Notify]:
    """Rule 3's records of ``step`` after ``EventReceived``: (kind, fields) or a notification."""
    plan: list[tuple[Any, tuple[Any, ...]] | Notify] = []
    for micro in step.microsteps:
        plan.append((MicrostepTaken, (micro.event, micro.exited, taken(micro), micro.entered)))
        for a in micro.actions:
            if isinstance(a, Notify):
                plan.append((InvokeIssued, (a.invoke, a.name, a.method, a.event)))
                plan.append(a)
    return plan


def _interpret(plan: list[tuple[Any, tuple[Any, ...]] | Notify]) -> _Build:
    """A builder that reads the plan at every call: for a step seen once."""

    def build(r: StepRecord) -> tuple[Record, ...]:
        d, t, made = r.device, r.time, r._made
        out: list[Record] = [EventReceived(d, t, r.event, r.data)]  # type: ignore[arg-type]
        k = 0
        for item in plan:
            if isinstance(item, Notify):
                if k < len(made):
                    _called(out, d, t, made[k], item.method)
                k += 1
            else:
                out.append(item[0](d, t, *item[1]))
        return tuple(out)

    return build


def _compile(plan: list[tuple[Any, tuple[Any, ...]] | Notify]) -> _Build:
    """A builder with the plan written out as code: for a step seen again.

    The code is one tuple display of struct calls (about 40 ns a record) for the usual
    case, where each notification's observer made one call (``made`` holds its ``api``
    text); any other case goes to the plan's reader. Every value reaches the code as a
    name bound to it (``c0``, ``c1``...), never as text, so nothing from a chart is ever
    part of the source.
    """
    slow = _interpret(plan)
    names: dict[str, Any] = {"ER": EventReceived, "OC": ObserverCalled, "slow": slow}

    def const(value: Any) -> str:
        name = f"c{len(names)}"
        names[name] = value
        return name

    items = ["ER(d, t, r.event, r.data)"]
    usual: list[str] = []
    for item in plan:
        if isinstance(item, Notify):
            k = len(usual)
            usual.append(f"type(made[{k}]) is str")
            items.append(f"OC(d, t, {const(item.method)}, made[{k}])")
        else:
            kind, fields = item
            items.append(f"{const(kind)}(d, t, {', '.join(const(f) for f in fields)})")
    lines = ["def build(r):", "    d = r.device", "    t = r.time"]
    if usual:
        lines += [
            "    made = r._made",
            f"    if len(made) != {len(usual)} or not ({' and '.join(usual)}):",
            "        return slow(r)",
        ]
    lines.append(f"    return ({', '.join(items)},)")
    exec("\n".join(lines), names)  # generated from names only (see above)
    build: _Build = names["build"]
    return build


class Builder:
    """The builder of one step's typed records: its program keeps it, its step records
    carry it, so reading them costs no lookup.

    :meth:`build` reads the step's records plan the first time; the second time it
    compiles the plan (:func:`_compile`) into :attr:`compiled`, which a step record
    calls directly from then on, so a step that is not memoised (seen once) never pays
    for compiling. (A plain function in a slot, not a bound method of the builder: a
    builder refers to nothing that refers back to it, so no program is ever left for
    the cyclic collector.)
    """

    __slots__ = ("_plan", "compiled")

    def __init__(self) -> None:
        self._plan: list[tuple[Any, tuple[Any, ...]] | Notify] | None = None
        self.compiled: _Build | None = None

    def build(self, r: StepRecord) -> tuple[Record, ...]:
        """The typed records of ``r`` (a step record of this builder's step)."""
        compiled = self.compiled
        if compiled is not None:
            return compiled(r)
        plan = self._plan
        if plan is None:  # the first time: read the plan
            plan = self._plan = records_plan(r.step)  # type: ignore[arg-type]
            return _interpret(plan)(r)
        compiled = self.compiled = _compile(plan)  # the second: compile it
        return compiled(r)


def _typed(r: StepRecord) -> tuple[Record, ...]:
    """Rule 3's records of a step record, with those made meanwhile put back in place."""
    step, tail = r.step, r._tail
    out: list[Record]
    if step is not None:
        builder = r._builder
        built = builder.build(r) if builder is not None else _interpret(records_plan(step))(r)
        if tail is None:
            return tuple(built)
        d, t = r.device, r.time
        out = list(built)
        if tail.final:
            out.append(Finished(d, t))
        if tail.upto is not None:
            del out[tail.upto :]
    elif r.event is None:
        out = []
    else:
        d, t = r.device, r.time
        out = [EventReceived(d, t, r.event, r.data)]
        if tail is not None and tail.reason is not None:
            kind = EventRejected if tail.rejected else EventIgnored
            out.append(kind(d, t, r.event, tail.reason))
    extras = tail.extras if tail is not None else ()
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
