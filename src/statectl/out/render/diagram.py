"""A neutral diagram model, built once from a chart and read by every writer.

Rules:
1. Every state becomes a :class:`Node` with a safe id (ASCII letters, digits and ``_``,
   starting with a letter, never a keyword of Mermaid, DOT or PlantUML, unique); writers
   print the id in the syntax and the state's own name only as a quoted label.
2. Every (transition, target) pair becomes an :class:`Edge` labelled ``event [condition]``,
   the paper's label: the prose condition of the table row, or the guard when the row has
   no prose. A targetless transition is a self-loop marked ``(internal)``.
3. The chart's initial states, and each compound state's default children, carry an initial
   marker; a ``monitoring required`` state carries a :class:`Note` naming the fault events
   its monitor raises.
4. A state with a timeout or deferred events carries them as ``details``, lines every
   writer prints under the state's name: ``after 2s / Close timeout``, ``defer: Release``.
5. ``active`` names the states to highlight (a live dashboard); an unknown name is misuse.
"""

from __future__ import annotations

import enum
import re
from collections.abc import Iterable
from dataclasses import dataclass

from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart, ControlKind, EventKind, State, StateKind, Transition

__all__ = [
    "Diagram",
    "Edge",
    "Node",
    "NodeKind",
    "Note",
    "edge_label",
    "from_chart",
    "safe_id",
    "state_details",
]


class NodeKind(enum.Enum):
    STATE = "state"
    COMPOUND = "compound"
    PARALLEL = "parallel"
    FINAL = "final"
    HISTORY_SHALLOW = "history-shallow"
    HISTORY_DEEP = "history-deep"

    @property
    def is_container(self) -> bool:
        return self in (NodeKind.COMPOUND, NodeKind.PARALLEL)

    @property
    def is_history(self) -> bool:
        return self in (NodeKind.HISTORY_SHALLOW, NodeKind.HISTORY_DEEP)


_KINDS = {
    StateKind.ATOMIC: NodeKind.STATE,
    StateKind.COMPOUND: NodeKind.COMPOUND,
    StateKind.PARALLEL: NodeKind.PARALLEL,
    StateKind.FINAL: NodeKind.FINAL,
    StateKind.HISTORY_SHALLOW: NodeKind.HISTORY_SHALLOW,
    StateKind.HISTORY_DEEP: NodeKind.HISTORY_DEEP,
}

#: Words that are keywords in at least one target syntax; ids never equal one (any case).
RESERVED = frozenset(
    {
        "as", "class", "classdef", "digraph", "direction", "edge", "end", "enduml", "graph",
        "hide", "left", "node", "note", "of", "over", "right", "show", "skinparam", "startuml",
        "state", "statediagram", "strict", "style", "subgraph", "top", "bottom", "default",
    }
)  # fmt: skip


@dataclass(frozen=True, slots=True)
class Node:
    id: str
    name: str
    kind: NodeKind
    label: str
    parent: str | None = None  # id of the containing node
    active: bool = False
    initial: tuple[str, ...] = ()  # ids of the default children of a container
    monitored: bool = False
    details: tuple[str, ...] = ()  # timeout and deferred events, one line each (rule 4)


@dataclass(frozen=True, slots=True)
class Edge:
    source: str  # node id
    target: str  # node id
    label: str
    event: str = ""
    condition: str = ""
    internal: bool = False
    color: str = ""  # a writer's stroke colour for it (coverage: taken or never taken)
    dashed: bool = False


@dataclass(frozen=True, slots=True)
class Note:
    node: str  # node id
    text: str


@dataclass(frozen=True, slots=True)
class Diagram:
    name: str
    nodes: tuple[Node, ...]
    edges: tuple[Edge, ...]
    initial: tuple[str, ...]  # ids of the top-level initial states
    notes: tuple[Note, ...] = ()

    def node(self, node_id: str) -> Node:
        for n in self.nodes:
            if n.id == node_id:
                return n
        raise KeyError(node_id)

    def children(self, parent: str | None) -> tuple[Node, ...]:
        return tuple(n for n in self.nodes if n.parent == parent)

    def ancestors(self, node_id: str) -> tuple[str, ...]:
        """Ids of the containers of ``node_id``, innermost first."""
        out: list[str] = []
        parent = self.node(node_id).parent
        while parent is not None:
            out.append(parent)
            parent = self.node(parent).parent
        return tuple(out)

    def home(self, edge: Edge) -> str | None:
        """The innermost compound container holding both ends: where a writer nests the edge.

        Parallel containers are skipped (their blocks hold only regions); ``None`` is top level.
        """
        theirs = set(self.ancestors(edge.target))
        for anc in self.ancestors(edge.source):
            if anc in theirs and self.node(anc).kind is NodeKind.COMPOUND:
                return anc
        return None


def safe_id(name: str, taken: Iterable[str] = ()) -> str:
    """An identifier every writer can print bare, derived from ``name`` and not in ``taken``."""
    base = re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_") or "state"
    if not base[0].isalpha() or base.lower() in RESERVED:
        base = "s_" + base
    used = set(taken)
    candidate, n = base, 2
    while candidate in used:
        candidate, n = f"{base}_{n}", n + 1
    return candidate


def edge_label(t: Transition) -> str:
    """The paper's ``event [condition]``: prose condition first, else the guard."""
    text = " ".join(t.events)
    condition = (t.condition or t.guard or "").strip()
    if condition:
        text = f"{text} [{condition}]" if text else f"[{condition}]"
    if not t.targets:
        text += " (internal)"
    return " ".join(text.split())


def state_details(state: State) -> tuple[str, ...]:
    """The lines shown under a state's name: its timeout, then the events it defers."""
    out: list[str] = []
    if state.timeout is not None:
        out.append(f"after {state.timeout.duration} / {state.timeout.event}")
    if state.defer:
        out.append("defer: " + ", ".join(state.defer))
    return tuple(out)


def from_chart(chart: Chart, active: frozenset[str] = frozenset()) -> Diagram:
    """Build the diagram of ``chart`` with the ``active`` states highlighted."""
    unknown = sorted(active - {s.name for s in chart.states})
    if unknown:
        raise StatectlError(
            f"active states {', '.join(map(repr, unknown))} are not states of {chart.name!r}; "
            f"states: {', '.join(s.name for s in chart.states)}"
        )
    ids: dict[str, str] = {}
    for s in chart.states:
        ids[s.name] = safe_id(s.name, ids.values())
    monitored_raises: dict[str, list[str]] = {}
    for s in chart.states:
        if ControlKind.MONITORING in s.controls:
            raises = monitored_raises.setdefault(s.name, [])
            for t in chart.transitions_from(s.name):
                for e in t.events:
                    edef = chart.event(e)
                    if edef is not None and edef.kind is EventKind.FAULT and e not in raises:
                        raises.append(e)
    nodes: list[Node] = []
    for s in chart.states:
        kind = _KINDS[s.kind]
        initial: tuple[str, ...] = ()
        if kind is NodeKind.COMPOUND:
            kids = [c for c in chart.children(s.name) if not c.kind.is_history]
            defaults = s.initial or tuple(k.name for k in kids[:1])
            initial = tuple(ids[x] for x in defaults if x in ids)
        label = {NodeKind.HISTORY_SHALLOW: "H", NodeKind.HISTORY_DEEP: "H*"}.get(kind, s.name)
        nodes.append(
            Node(
                id=ids[s.name],
                name=s.name,
                kind=kind,
                label=label,
                parent=ids.get(s.parent) if s.parent is not None else None,
                active=s.name in active,
                initial=initial,
                monitored=s.name in monitored_raises,
                details=state_details(s),
            )
        )
    edges: list[Edge] = []
    for t in chart.transitions:
        if t.source not in ids:
            continue
        label = edge_label(t)
        condition = (t.condition or t.guard or "").strip()
        for target in t.targets or (t.source,):
            if target in ids:
                edges.append(
                    Edge(
                        ids[t.source],
                        ids[target],
                        label,
                        " ".join(t.events),
                        condition,
                        internal=not t.targets,
                    )
                )
    top = chart.initial or tuple(s.name for s in chart.states if s.parent is None)[:1]
    notes = tuple(
        Note(
            ids[name],
            "monitor raises " + ", ".join(raises) if raises else "monitor raises nothing",
        )
        for name, raises in monitored_raises.items()
    )
    return Diagram(
        name=chart.name,
        nodes=tuple(nodes),
        edges=tuple(edges),
        initial=tuple(ids[x] for x in top if x in ids),
        notes=notes,
    )
