"""The chart's reachable graph, explored by the kernel: shortest paths to rows, states, pairs.

Rules:
1. Every decision is the kernel's: :func:`~statectl.kernel.semantics.initial` and
   :func:`~statectl.kernel.semantics.step` from the default state, breadth-first over the
   events a test can send (commands, completions and faults; not the chart's own
   internal or ``done.*``/``error.*`` events, which only the chart raises).
2. A guard that reads the snapshot (``previous``, ``In()``) is made true or false
   by the path that leads to its row. A guard over the datamodel is made true and
   false by the data the test starts with: candidate values come from the chart's
   defaults and the literals the guards compare against (each, one below, one
   above, a different text, both booleans); the kernel's own guard evaluation
   (:func:`~statectl.kernel.semantics.condition_match`) says which outcome a node gives.
3. A node is ``(data, snapshot)``; the search visits at most ``max_nodes`` of them
   and the first edge found that takes a row is its shortest path (ties: the
   chart's default data first, then events in table order).
4. The kernel is asked only about events an active state has a transition for or
   declares ignored (:class:`~statectl.kernel.semantics.offers.Offers`); every other event
   is ``no transition`` in that node without a step, and gets no edge
   (``Graph.stepped`` says which were asked), so exploring a big sparse chart stays linear.
"""

from __future__ import annotations

import ast
import itertools
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from statectl.kernel.model import Chart, EventKind, Notify, StateKind, Transition, field_accepts
from statectl.kernel.semantics import (
    Machine,
    Run,
    Snapshot,
    Step,
    Unhandled,
    compiled,
    condition_match,
    initial,
    initial_data,
    step,
)
from statectl.kernel.semantics.offers import Offers
from statectl.out.testgen.conditions import input_values

__all__ = ["MAX_DATA", "MAX_NODES", "Edge", "Graph", "Node", "explore"]

#: Bound on the nodes (data x snapshot) one exploration visits.
MAX_NODES = 20_000
#: Bound on the candidate datamodel assignments tried for guards over data.
MAX_DATA = 64

Data = tuple[tuple[str, Any], ...]


@dataclass(frozen=True, slots=True)
class Node:
    """A place a test can bring the device to: the data it started with and a snapshot."""

    data: int  # index into Graph.datas
    snapshot: Snapshot


@dataclass(frozen=True, slots=True)
class Edge:
    """One event sent in ``source`` and the kernel's decision for it."""

    source: Node
    event: str
    step: Step
    target: Node
    data: Any = None  # the event's own data (``_event['data']``), when a guard reads it


@dataclass(frozen=True, slots=True)
class Graph:
    """The explored graph: nodes in breadth-first order, with how each was first reached."""

    chart: Chart
    datas: tuple[Data, ...]  # datas[0] is the chart's default datamodel (overrides: none)
    defaults: Data
    sendable: tuple[str, ...]
    start: tuple[Node, ...]  # per data, the node the device starts in
    initial_steps: tuple[Step, ...]
    parent: Mapping[Node, Edge | None]  # the edge that first reached a node
    edges: tuple[Edge, ...]  # every edge, in breadth-first order
    complete: bool  # False when max_nodes stopped the search
    #: per event whose guards read its data, the data tried (``None``: none sent)
    event_datas: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    #: per expanded node, the sendable events the kernel was asked about (rule 4); each
    #: other one has no edge: no transition, nothing taken, the node unchanged
    stepped: Mapping[Node, frozenset[str]] = field(default_factory=dict)

    def path(self, node: Node) -> tuple[Edge, ...]:
        """The shortest sequence of edges from the start to ``node``."""
        out: list[Edge] = []
        edge = self.parent[node]
        while edge is not None:
            out.append(edge)
            edge = self.parent[edge.source]
        return tuple(reversed(out))

    def overrides(self, node: Node) -> dict[str, Any]:
        """The datamodel values a test must set to start as ``node`` did (none: defaults)."""
        defaults = dict(self.defaults)
        return {k: v for k, v in self.datas[node.data] if defaults.get(k, _UNSET) != v}

    def guard_holds(self, node: Node, t: Transition, event_data: Any = None) -> bool:
        """The kernel's answer: does ``t``'s guard hold in ``node`` for an external event?"""
        run = Run(
            set(node.snapshot.active),
            dict(node.snapshot.history),
            node.snapshot.previous,
            dict(self.datas[node.data]),
        )
        run.event = t.events[0] if t.events else None
        return condition_match(compiled(self.chart), run, t, event_data)


_UNSET = object()


def sendable_events(chart: Chart) -> tuple[str, ...]:
    """The events a test may send: every chart event but internal and platform ones."""
    out = []
    for name in chart.event_names:
        d = chart.event(name)
        if d is not None and d.kind is EventKind.INTERNAL:
            continue
        if name.startswith(("done.", "error.")) or name == "*":
            continue
        out.append(name)
    return tuple(out)


def default_data(chart: Chart) -> Data:
    """The chart's data at start, as a device starts with it (the kernel's answer)."""
    return tuple(initial_data(chart).items())


def _literals(source: str) -> list[Any]:
    """The constants a guard compares against, with their neighbours (rule 2)."""
    found: list[Any] = []
    for node in ast.walk(ast.parse(source, mode="eval")):
        if not isinstance(node, ast.Constant):
            continue
        v = node.value
        if isinstance(v, bool) or v is None:
            found += [True, False, None]
        elif isinstance(v, int | float):
            found += [v, v - 1, v + 1]
        elif isinstance(v, str):
            found += [v, v + "_other" if v else "x"]
    return found


def candidate_data(chart: Chart, m: Machine) -> tuple[Data, ...]:
    """The default datamodel first, then assignments that may flip the guards over data.

    Each name a guard reads takes its default and the values the guard's conditions
    compare it with (:func:`~statectl.out.testgen.conditions.input_values`): literals
    and their neighbours, both booleans for a bare read, another name's default and
    its neighbours; a name compared otherwise takes every literal of the guard."""
    defaults = default_data(chart)
    names = [k for k, _ in defaults]
    read = {n for g in m.guards.values() for n in g.names} & set(names)
    if not read:
        return (defaults,)
    values: dict[str, list[Any]] = {n: [v] for n, v in defaults if n in read}
    known = frozenset(names)
    for guard in m.guards:
        found = input_values(guard, known, dict(defaults))
        for n in m.guards[guard].names & read:
            lits = found.get(("data", n)) or _literals(guard)
            for v in lits:
                if not any(type(v) is type(w) and v == w for w in values[n]):
                    values[n].append(v)
    keys = sorted(read, key=names.index)
    out = [defaults]
    for combo in itertools.product(*(values[k] for k in keys)):
        d = dict(defaults)
        d.update(zip(keys, combo, strict=True))
        data = tuple(d.items())
        if data not in out:
            out.append(data)
        if len(out) >= MAX_DATA:
            break
    return tuple(out)


def _event_data_reads(source: str) -> tuple[set[str], bool]:
    """The keys a guard reads of ``_event.data`` (or ``_event['data']``), and whether it
    reads it whole."""
    keys: set[str] = set()
    whole = False
    parents: dict[int, ast.AST] = {}
    tree = ast.parse(source, mode="eval")
    for node in ast.walk(tree):
        for child in ast.iter_child_nodes(node):
            parents[id(child)] = node
    for node in ast.walk(tree):
        subscript = (
            isinstance(node, ast.Subscript)
            and isinstance(node.slice, ast.Constant)
            and node.slice.value == "data"
        )
        attribute = isinstance(node, ast.Attribute) and node.attr == "data"
        if not (
            (subscript or attribute)
            and isinstance(node, ast.Subscript | ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id == "_event"
        ):
            continue
        up = parents.get(id(node))
        if (
            isinstance(up, ast.Subscript)
            and up.value is node
            and isinstance(up.slice, ast.Constant)
            and isinstance(up.slice.value, str)
        ):
            keys.add(up.slice.value)
        elif isinstance(up, ast.Attribute) and up.value is node:
            keys.add(up.attr)  # _event.data.x, the documented spelling
        else:
            whole = True
    return keys, whole


def fits_declared(declared: dict[str, str], value: Any) -> bool:
    """Whether ``value`` is data an event declaring ``declared`` fields accepts."""
    if not isinstance(value, dict):
        return False
    return all(k in declared and field_accepts(declared[k], v) for k, v in value.items())


#: A value of each declared field type, for a field a guard reads but compares with nothing.
_TYPE_VALUES: dict[str, list[Any]] = {
    "int": [0, 1],
    "float": [0.0, 1.0],
    "str": ["x"],
    "bool": [True, False],
    "list": [[]],
    "dict": [{}],
}


def _field_values(chart: Chart, guards: list[str], key: str, declared: dict[str, str]) -> list[Any]:
    """The values tried for the event field ``key``: what its conditions compare it with,
    fitting its declared type (rule 2)."""
    defaults = dict(default_data(chart)) if chart.data else {}
    names = frozenset(defaults)
    found: list[Any] = []
    for guard in guards:
        found += input_values(guard, names, defaults).get(("event", key), [])
    if not found:
        found = [v for g in guards for v in _literals(g)]
    kind = declared.get(key)
    if kind is not None:
        found = [v for v in found if field_accepts(kind, v)] or _TYPE_VALUES.get(kind, [])
    out: list[Any] = []
    for v in found:
        if not any(type(v) is type(w) and v == w for w in out):
            out.append(v)
    return out


def candidate_event_data(chart: Chart) -> dict[str, tuple[Any, ...]]:
    """Per event, the data a test sends with it: none first, then data for its guards.

    A guard reading ``_event.data.x`` gets ``{"x": v, ...}`` for each combination of
    the values its conditions compare each field with (rule 2,
    :func:`~statectl.out.testgen.conditions.input_values`: literals and their
    neighbours, both booleans for a bare read), fitting the event's declared field
    types; one reading ``_event.data`` whole gets the literals themselves.
    """
    out: dict[str, tuple[Any, ...]] = {}
    guards: dict[str, list[str]] = {}
    for t in chart.transitions:
        if t.guard and "_event" in t.guard:
            for event in t.events:
                guards.setdefault(event, []).append(t.guard)
    for event, sources in guards.items():
        keys: set[str] = set()
        whole = False
        for g in sources:
            k, w = _event_data_reads(g)
            keys |= k
            whole = whole or w
        known = chart.event(event)
        declared = dict(known.fields) if known is not None else {}
        values: list[Any] = []
        if keys:
            ordered = sorted(keys)
            per_key = [_field_values(chart, sources, k, declared) for k in ordered]
            for combo in itertools.product(*per_key):
                values.append(dict(zip(ordered, combo, strict=True)))
                if len(values) >= MAX_DATA:
                    break
        if whole:
            values += [v for g in sources for v in _literals(g)]
        found: list[Any] = [None]
        for v in values:
            if declared and not fits_declared(declared, v):
                continue  # the runtime would refuse it as it is posted
            if not any(type(v) is type(w) and v == w for w in found):
                found.append(v)
        out[event] = tuple(found[:MAX_DATA])
    return out


def explore(
    chart: Chart,
    *,
    max_nodes: int = MAX_NODES,
    progress: Callable[[int, int], None] | None = None,
) -> Graph:
    """Breadth-first over every sendable event from the default state (rules 1-4).

    ``progress`` is called after each node is expanded, with the nodes expanded and
    the nodes found so far (the CLI shows it on a long run)."""
    m = compiled(chart)
    datas = candidate_data(chart, m)
    sendable = sendable_events(chart)
    event_datas = candidate_event_data(chart)
    parent: dict[Node, Edge | None] = {}
    starts: list[Node] = []
    firsts: list[Step] = []
    queue: deque[Node] = deque()
    for i, data in enumerate(datas):
        first = initial(m, dict(data))
        node = Node(i, first.target)
        starts.append(node)
        firsts.append(first)
        if node not in parent:
            parent[node] = None
            if not first.final:
                queue.append(node)
    edges: list[Edge] = []
    complete = True
    offers = Offers(m, sendable)
    stepped: dict[Node, frozenset[str]] = {}
    while queue:
        node = queue.popleft()
        values = dict(datas[node.data])
        active = node.snapshot.active
        asked = sorted(offers.offered(active) | offers.ignored(active))
        stepped[node] = frozenset(sendable[i] for i in asked)
        if progress is not None:
            progress(len(stepped), len(parent))
        for event in (sendable[i] for i in asked):  # rule 4: the rest is no transition
            for sent in event_datas.get(event, (None,)):
                decided = step(m, node.snapshot, event, values, sent)
                if decided.unhandled is Unhandled.GUARD_ERROR:
                    continue  # data the guard cannot read: no scenario, the runtime refuses it
                target = Node(node.data, decided.target)
                edge = Edge(node, event, decided, target, sent)
                edges.append(edge)
                if target in parent:
                    continue
                if len(parent) >= max_nodes:
                    complete = False
                    continue
                parent[target] = edge
                if not decided.final:
                    queue.append(target)
    return Graph(
        chart,
        datas,
        datas[0],
        sendable,
        tuple(starts),
        tuple(firsts),
        parent,
        tuple(edges),
        complete,
        event_datas,
        stepped,
    )


# -- what a step shows a test ------------------------------------------------------------------


def leaves(chart: Chart, snapshot: Snapshot) -> tuple[str, ...]:
    """The active atomic (and final) states in document order: "the state reached"."""
    m = compiled(chart)
    return tuple(
        s
        for s in sorted(snapshot.active, key=m.order.__getitem__)
        if m.kind[s] in (StateKind.ATOMIC, StateKind.FINAL)
    )


def notifies(s: Step) -> tuple[Notify, ...]:
    return tuple(a for a in s.actions if isinstance(a, Notify))


def rows(chart: Chart) -> Iterator[tuple[int, Transition]]:
    """The chart's transitions, numbered from 1 in table order: the Event Definition rows."""
    return enumerate(chart.transitions, 1)
