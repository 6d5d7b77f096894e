"""The paper's step 3: the Subject, its observers and the invoke numbers.

Rules:
1. An event is data the *Subject* (the running device) watches; a device with
   its API is an *Observer*.
2. Events that name the same API share one observer method (Movement and
   Movement completion become ``Movement()``). Methods are numbered in the order
   their API first appears in the Event Definition table: that number is the
   *invoke number* a notification carries.
3. Unlike the textbook pattern, a notification goes to the one observer
   registered for its invoke number, never to all of them.
4. Taking a transition for a ``command`` or ``fault`` event notifies the
   method (it drives the device); ``completion`` events are reported back by
   the device through that same method, so they notify nothing.
5. An invoke is named after the state its driving event enters (the paper's
   Moving, Returning); where that name is taken already, after its method
   (the paper's Error). An explicit ``invoke`` cell wins over both.
6. A state marked ``monitoring required`` gets a monitor, active only while the
   state is, that raises the ``fault`` events leaving it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

from statectl.kernel.model import Api, Chart, ControlKind, EventKind, InvokeNumber

__all__ = [
    "DRIVING_KINDS",
    "EventSpec",
    "MonitorSpec",
    "Notification",
    "Observer",
    "ObserverModel",
    "derive_invokes",
    "extract",
]

DRIVING_KINDS = frozenset({EventKind.COMMAND, EventKind.FAULT})


@dataclass(frozen=True, slots=True)
class EventSpec:
    """What :func:`derive_invokes` needs of one event row."""

    event: str
    kind: EventKind
    api: str | None
    new: str
    invoke: str | None = None  # explicit invoke name from the table, if any


def derive_invokes(rows: Sequence[EventSpec]) -> tuple[tuple[Api, ...], tuple[InvokeNumber, ...]]:
    """Group events by API into observer methods and number them (rules 2 and 5)."""
    methods: dict[str, dict[str, None]] = {}  # method -> its events, first-seen order
    driving_target: dict[str, str] = {}
    explicit: dict[str, str] = {}
    for r in rows:
        if not r.api:
            continue
        methods.setdefault(r.api, {})[r.event] = None
        if r.kind in DRIVING_KINDS:
            driving_target.setdefault(r.api, r.new)
        if r.invoke:
            explicit.setdefault(r.api, r.invoke)
    apis = tuple(Api(method, tuple(events)) for method, events in methods.items())
    used = set(explicit.values())
    invokes: list[InvokeNumber] = []
    for number, api in enumerate(apis):
        name = explicit.get(api.method)
        if name is None:
            target = driving_target.get(api.method)
            name = target if target is not None and target not in used else api.method
            used.add(name)
        invokes.append(InvokeNumber(number, name, api.method))
    return apis, tuple(invokes)


class Notification(NamedTuple):
    """The typed record an observer receives: which invoke, for which event, with what data.

    Immutable like the other records, but a named tuple rather than a frozen
    dataclass: one is built for every notification that carries event data, and a
    frozen dataclass costs three times as much to build (each field is set through
    ``object.__setattr__``).
    """

    device: str
    invoke: int
    name: str
    method: str
    event: str
    data: Any = None


class Observer(Protocol):
    """A device with its API: maps an invoke number to one device API call."""

    def update(self, notification: Notification) -> None: ...


@dataclass(frozen=True, slots=True)
class MonitorSpec:
    state: str
    raises: tuple[str, ...]
    description: str


@dataclass(frozen=True, slots=True)
class ObserverModel:
    """Everything step 3 derives from a chart; printed by ``statectl observers``."""

    subject: str
    invokes: tuple[InvokeNumber, ...]
    apis: tuple[Api, ...]
    monitors: tuple[MonitorSpec, ...]
    notifying: tuple[tuple[str, int], ...]  # (event, invoke number) for driving events

    def invoke_for_method(self, method: str) -> InvokeNumber:
        for i in self.invokes:
            if i.method == method:
                return i
        raise KeyError(method)

    def to_json(self) -> dict[str, Any]:
        return {
            "subject": self.subject,
            "invokes": [
                {"number": i.number, "name": i.name, "method": i.method} for i in self.invokes
            ],
            "observers": [{"method": a.method, "events": list(a.events)} for a in self.apis],
            "monitors": [
                {"state": m.state, "raises": list(m.raises), "description": m.description}
                for m in self.monitors
            ],
            "notifications": [{"event": e, "invoke": n} for e, n in self.notifying],
        }


def extract(chart: Chart) -> ObserverModel:
    """Derive the Subject/Observer structure of a built chart."""
    by_method = {i.method: i for i in chart.invokes}
    notifying: list[tuple[str, int]] = []
    for e in chart.events:
        if e.kind in DRIVING_KINDS and e.api in by_method:
            notifying.append((e.name, by_method[e.api].number))
    monitors = []
    for s in chart.states:
        if ControlKind.MONITORING in s.controls:
            raises = []
            for t in chart.transitions_from(s.name):
                for ev in t.events:
                    edef = chart.event(ev)
                    if edef is not None and edef.kind is EventKind.FAULT and ev not in raises:
                        raises.append(ev)
            monitors.append(MonitorSpec(s.name, tuple(raises), s.description))
    return ObserverModel(chart.name, chart.invokes, chart.apis, tuple(monitors), tuple(notifying))
