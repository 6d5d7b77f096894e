"""The chart as a value: frozen records that describe a device's statechart.

Rules:
1. A :class:`Chart` is immutable and says nothing about a run; the runtime holds
   the configuration (which states are active), never the chart.
2. States are listed in document order, every parent before its children; that
   order is the W3C SCXML document order the semantics relies on.
3. Every element keeps the :class:`~statectl.kernel.errors.Location` it came from, so a
   message about it can point at the table row or the SCXML line.
4. Actions are a closed set of frozen records; the semantics returns them and
   the runtime performs them.
"""

from __future__ import annotations

import enum
from collections.abc import Collection, Iterable, Iterator, Mapping, MutableSequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from statectl.kernel.errors import Location

__all__ = [
    "FIELD_TYPES",
    "MAX_DEFERRED",
    "Action",
    "Api",
    "Assign",
    "Block",
    "Cancel",
    "Chart",
    "ChildInvoke",
    "Content",
    "ControlKind",
    "DataItem",
    "DoneData",
    "EventDef",
    "EventKind",
    "Foreach",
    "If",
    "InvokeNumber",
    "Kept",
    "Log",
    "Notify",
    "Param",
    "Raise",
    "Script",
    "Send",
    "State",
    "StateKind",
    "Timeout",
    "Transition",
    "field_accepts",
    "keep_deferred",
    "take_released",
]

NOWHERE = Location()


class ControlKind(enum.Enum):
    """The paper's "required state control" column."""

    DEFAULT = "default"
    MONITORING = "monitoring required"
    TRIGGER = "event trigger required"


class EventKind(enum.Enum):
    """Who produces an event, which decides whether taking it calls the device."""

    COMMAND = "command"  # from outside or a sensor: drives the device API
    COMPLETION = "completion"  # reported back by the device through its API
    FAULT = "fault"  # raised by a monitor: drives the API's fault handling
    INTERNAL = "internal"  # raised by the chart itself


class StateKind(enum.Enum):
    ATOMIC = "atomic"
    COMPOUND = "compound"
    PARALLEL = "parallel"
    FINAL = "final"
    HISTORY_SHALLOW = "history-shallow"
    HISTORY_DEEP = "history-deep"

    @property
    def is_history(self) -> bool:
        # identity, not ``in (...)``: a tuple test hashes the member, and every step,
        # build and check asks this of each state it touches
        return self is StateKind.HISTORY_SHALLOW or self is StateKind.HISTORY_DEEP


class Action:
    """Base of the closed set of actions a step can ask the runtime to perform."""

    __slots__ = ()


@dataclass(frozen=True, slots=True)
class Notify(Action):
    """Notify the specific observer registered for ``invoke`` (the paper's step 3)."""

    invoke: int
    name: str  # the invoke enumeration member, e.g. "Moving"
    method: str  # the observer method it maps to, e.g. "Movement"
    event: str  # the event whose transition issued it


@dataclass(frozen=True, slots=True)
class Raise(Action):
    """Put an event on the internal queue (processed before the next external one)."""

    event: str


@dataclass(frozen=True, slots=True)
class Log(Action):
    label: str
    message: str = ""
    expr: str | None = None  # SCXML ``<log expr>``: evaluated by the host's datamodel
    origin: Location = NOWHERE


# -- SCXML executable content: performed by a host-supplied executor, never by the kernel --


@dataclass(frozen=True, slots=True)
class Param:
    """``<param name expr|location>``: one name/value pair of event or done data."""

    name: str
    expr: str | None = None
    location: str | None = None
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class Content:
    """``<content expr>`` or inline content; ``body`` is text or serialised XML."""

    expr: str | None = None
    body: str | None = None
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class DoneData:
    """``<donedata>`` of a final state: the data of its ``done.state`` event."""

    params: tuple[Param, ...] = ()
    content: Content | None = None


@dataclass(frozen=True, slots=True)
class Block(Action):
    """One handler (``<onentry>``/``<onexit>``) of several: an error skips only its rest."""

    actions: tuple[Action, ...]


@dataclass(frozen=True, slots=True)
class Assign(Action):
    location: str
    expr: str | None = None
    body: str | None = None  # inline content instead of ``expr``
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class Script(Action):
    source: str
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class If(Action):
    """``<if>/<elseif>/<else>``: the first branch whose condition holds (``None``: else)."""

    branches: tuple[tuple[str | None, tuple[Action, ...]], ...]
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class Foreach(Action):
    array: str
    item: str
    index: str | None = None
    actions: tuple[Action, ...] = ()
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class Send(Action):
    """``<send>``: every ``*expr`` twin is evaluated when the send is performed."""

    event: str | None = None
    eventexpr: str | None = None
    target: str | None = None
    targetexpr: str | None = None
    type: str | None = None
    typeexpr: str | None = None
    id: str | None = None
    idlocation: str | None = None
    delay: str | None = None
    delayexpr: str | None = None
    namelist: tuple[str, ...] = ()
    params: tuple[Param, ...] = ()
    content: Content | None = None
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class Cancel(Action):
    sendid: str | None = None
    sendidexpr: str | None = None
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class ChildInvoke:
    """``<invoke>`` of a state: a child session started when the state settles active."""

    type: str | None = None
    typeexpr: str | None = None
    src: str | None = None
    srcexpr: str | None = None
    id: str | None = None
    idlocation: str | None = None
    namelist: tuple[str, ...] = ()
    autoforward: bool = False
    params: tuple[Param, ...] = ()
    content: Content | None = None
    finalize: tuple[Action, ...] = ()
    origin: Location = NOWHERE


#: How many deferred events a running device keeps at most, in Python and in generated C++.
MAX_DEFERRED = 16
#: A deferred event kept with its data, in arrival order.
Kept = tuple[str, Any]


def keep_deferred(kept: MutableSequence[Kept], event: str, data: Any) -> bool:
    """Keep a deferred arrival after those kept before it, while fewer than
    :data:`MAX_DEFERRED` are kept; False: dropped. The one rule the runtime
    (statectl.run.runtime.defer) and testgen's oracle keep by."""
    if len(kept) >= MAX_DEFERRED:
        return False
    kept.append((event, data))
    return True


def take_released(kept: MutableSequence[Kept], deferring: Collection[str]) -> Kept | None:
    """Remove and return the first kept event, in arrival order, that no active state
    defers (``deferring``, :meth:`Chart.deferring`); None when every one is still deferred."""
    for i, (event, data) in enumerate(kept):
        if event not in deferring:
            del kept[i]
            return event, data
    return None


@dataclass(frozen=True, slots=True)
class Timeout:
    """A state's timeout: ``event`` is raised ``seconds`` after the state is entered,
    unless it was left first (statectl.run.runtime.timers arms and cancels it)."""

    seconds: float
    event: str
    origin: Location = NOWHERE

    @property
    def duration(self) -> str:
        """``250ms``, ``2s``, ``2min``: the largest whole unit, as the tables write it (the
        tables' timeout cell and every diagram show this text)."""
        ms = round(self.seconds * 1000)
        if ms % 60000 == 0:
            return f"{ms // 60000}min"
        if ms % 1000 == 0:
            return f"{ms // 1000}s"
        return f"{ms}ms"


@dataclass(frozen=True, slots=True)
class State:
    """A chart state; ``parent`` is ``None`` for a top-level state."""

    name: str
    kind: StateKind = StateKind.ATOMIC
    parent: str | None = None
    initial: tuple[str, ...] = ()  # default entry targets of a compound state
    controls: frozenset[ControlKind] = frozenset()
    description: str = ""
    component: str = ""  # the paper's "component name/API" column
    on_entry: tuple[Action, ...] = ()
    on_exit: tuple[Action, ...] = ()
    history_default: tuple[str, ...] = ()  # targets of a history state with no value yet
    origin: Location = NOWHERE
    initial_actions: tuple[Action, ...] = ()  # content of an ``<initial>`` transition
    history_actions: tuple[Action, ...] = ()  # content of a history state's default transition
    data: tuple[DataItem, ...] = ()  # ``<datamodel>`` declared in this state
    invokes: tuple[ChildInvoke, ...] = ()
    donedata: DoneData | None = None  # of a final state
    number: int | None = None  # the standard's state number (tables' ``number`` column)
    timeout: Timeout | None = None  # the state table's ``timeout`` cell
    defer: tuple[str, ...] = ()  # events kept while this state is active (``defer`` cell)


@dataclass(frozen=True, slots=True)
class Transition:
    """``source + event [guard] / actions = targets``; no targets means targetless."""

    source: str
    events: tuple[str, ...]  # empty: eventless
    targets: tuple[str, ...]
    guard: str | None = None
    condition: str = ""  # the paper's prose "condition for the trigger"
    internal: bool = False
    actions: tuple[Action, ...] = ()
    origin: Location = NOWHERE

    @property
    def label(self) -> str:
        """The paper's transition label, ``event [condition]``."""
        text = " ".join(self.events)
        if self.guard:
            text += f" [{self.guard}]"
        return text


#: The types an event's declared data fields may have, and the Python values each
#: accepts (an int is a float; a bool is only a bool): the one table the tables, the
#: build, the runtime and the tools share (docs/tables.md, "Event data").
FIELD_TYPES: Mapping[str, tuple[type, ...]] = MappingProxyType(
    {
        "int": (int,),
        "float": (int, float),
        "str": (str,),
        "bool": (bool,),
        "list": (list, tuple),
        "dict": (Mapping,),
        "any": (object,),
    }
)


def field_accepts(kind: str, value: Any) -> bool:
    """Whether ``value`` fits a data field declared ``kind``."""
    if isinstance(value, bool) and kind not in ("bool", "any"):
        return False
    return isinstance(value, FIELD_TYPES.get(kind, (object,)))


@dataclass(frozen=True, slots=True)
class EventDef:
    name: str
    kind: EventKind = EventKind.COMMAND
    api: str | None = None  # the observer method (device API) this event drives or reports on
    description: str = ""
    origin: Location = NOWHERE
    #: declared data fields ``((name, type), ...)``; empty: the event declares none
    fields: tuple[tuple[str, str], ...] = ()
    #: a completion the device may report with no call of its API pending (the
    #: table's ``unasked`` column; statectl.kernel.semantics.calls rule 4)
    unasked: bool = False
    #: the severity (1-1000) of the OPC UA alarm a fault raises (the table's ``severity``
    #: column); None: the server's default
    severity: int | None = None


@dataclass(frozen=True, slots=True)
class Api:
    """An observer method: one device API shared by every event that names it."""

    method: str
    events: tuple[str, ...]
    origin: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class InvokeNumber:
    """An invoke number: the enumerated value a notification carries."""

    number: int
    name: str
    method: str


@dataclass(frozen=True, slots=True)
class DataItem:
    """A datamodel variable; ``expr`` is evaluated in the chart's expression language."""

    name: str
    expr: str | None = None
    origin: Location = NOWHERE
    src: str | None = None  # SCXML ``<data src>``
    body: str | None = None  # SCXML inline ``<data>`` content


@dataclass(frozen=True, slots=True)
class Chart:
    """A device's statechart: the value every host (runtime, verifier, codegen) reads."""

    name: str
    states: tuple[State, ...]
    transitions: tuple[Transition, ...]
    initial: tuple[str, ...]
    events: tuple[EventDef, ...] = ()
    apis: tuple[Api, ...] = ()
    invokes: tuple[InvokeNumber, ...] = ()
    ignored: frozenset[tuple[str, str]] = frozenset()  # (state, event) declared ignored
    data: tuple[DataItem, ...] = ()
    datamodel: str = "safe"
    component: str = ""
    origin: Location = field(default=NOWHERE)
    binding: str = "early"  # SCXML data binding: "early" or "late"
    script: tuple[Action, ...] = ()  # SCXML top-level ``<script>``, run once at start
    profile: str = ""  # the standard profile the device file declares (docs/profiles.md)
    #: lookups by name, built on first use: a cache, not part of the value
    _index: dict[str, Any] = field(
        default_factory=dict, init=False, repr=False, compare=False, hash=False
    )

    def _lookup(self) -> dict[str, Any]:
        """State, event, children and transitions by name, built once (linear lookups)."""
        index = self._index
        if not index:
            children: dict[str | None, list[State]] = {}
            by_source: dict[str, list[Transition]] = {}
            for st in self.states:
                children.setdefault(st.parent, []).append(st)
            for t in self.transitions:
                by_source.setdefault(t.source, []).append(t)
            events: dict[str, EventDef] = {}
            for e in self.events:
                events.setdefault(e.name, e)  # the first of a name, as a scan finds it
            states: dict[str, State] = {}
            for st in self.states:
                states.setdefault(st.name, st)
            index.update(
                states=states,
                events=events,
                children={k: tuple(v) for k, v in children.items()},
                by_source={k: tuple(v) for k, v in by_source.items()},
            )
        return index

    def state(self, name: str) -> State:
        return self._lookup()["states"][name]  # type: ignore[no-any-return]  # typed by _lookup

    def has_state(self, name: str) -> bool:
        return name in self._lookup()["states"]

    def event(self, name: str) -> EventDef | None:
        events: dict[str, EventDef] = self._lookup()["events"]
        return events.get(name)

    def children(self, name: str | None) -> Iterator[State]:
        return iter(self._lookup()["children"].get(name, ()))

    def transitions_from(self, name: str) -> Iterator[Transition]:
        return iter(self._lookup()["by_source"].get(name, ()))

    @property
    def default_states(self) -> tuple[str, ...]:
        """States marked ``default`` in the State Definition table."""
        return tuple(s.name for s in self.states if ControlKind.DEFAULT in s.controls)

    @property
    def deferred(self) -> frozenset[tuple[str, str]]:
        """(state, event) pairs of the states' ``defer`` cells: ignored by the kernel, kept
        by the runtime (statectl.run.runtime.defer) until the state is left."""
        return frozenset((s.name, e) for s in self.states for e in s.defer)

    def deferring(self, active: Iterable[str]) -> tuple[str, ...]:
        """The events the states ``active`` defer, each once: by state name, then as each
        ``defer`` cell lists them. The one answer the runtime (which keeps them,
        statectl.run.runtime.defer), the cell explorer and testgen's oracle ask."""
        index = self._lookup()
        defers: dict[str, tuple[str, ...]] | None = index.get("defers")
        if defers is None:
            defers = {}
            for st in self.states:
                if st.defer:
                    defers.setdefault(st.name, st.defer)  # the first of a name, as state()
            index["defers"] = defers
        if not defers:
            return ()
        return tuple(dict.fromkeys(e for s in sorted(active) if s in defers for e in defers[s]))

    @property
    def event_names(self) -> tuple[str, ...]:
        """Every event the chart knows: declared, then used by transitions, in order.

        Worked out once per chart (kept with the lookups): a check asks it in five rules,
        and each answer walked every transition."""
        index = self._lookup()
        names: tuple[str, ...] | None = index.get("event_names")
        if names is None:
            seen: dict[str, None] = {e.name: None for e in self.events}
            for t in self.transitions:
                for e in t.events:
                    seen.setdefault(e, None)
            names = index["event_names"] = tuple(seen)
        return names
