"""Test cases from the explored graph, one criterion at a time.

Rules:
1. A :class:`Case` is a path (the events sent first, each checked as handled),
   then one event whose outcome the kernel decided: the states reached, the invoke
   numbers issued with their observer methods, or why nothing happened.
2. ``rows``: per Event Definition row the shortest path that takes it; per guarded
   row also one where its guard is false (both outcomes); per row into a history
   state also one per other configuration the history resumes. ``transitions``: per
   distinct edge of the state graph (configuration, event, configuration, rows).
   ``states``: per reachable configuration. ``pairs``: per transition, each
   transition that can follow it; then the guards' parts
   (:mod:`~statectl.out.testgen.guardcases`): a guard over ``previous`` at every
   previous state its row meets, every guard to MC/DC, every comparison over
   numbers at its boundary values. Every criterion ends with the :class:`Table` of
   each reachable configuration's unhandled events and the kernel's reason.
3. A case's name and docstring say what it covers in the paper's words: row
   number, file:line, ``event [condition]: old -> new``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart, Transition
from statectl.kernel.semantics import Step, Unhandled
from statectl.out.escape.python import identifier
from statectl.out.testgen.paths import Edge, Graph, Node, leaves, notifies

__all__ = ["CRITERIA", "Case", "Expect", "Suite", "Table", "cases_for"]

CRITERIA = ("rows", "transitions", "states", "pairs")
#: The reason of a quiet event (paths rule 4), as the kernel gives it.
NO_TRANSITION = Unhandled.NO_TRANSITION.value


@dataclass(frozen=True, slots=True)
class Expect:
    """What the device must show after an event: states, invokes issued, or the reason."""

    states: tuple[str, ...]
    invokes: tuple[tuple[int, str], ...] = ()  # (invoke number, observer method)
    unhandled: str | None = None


@dataclass(frozen=True, slots=True)
class Case:
    name: str
    doc: str
    data: tuple[tuple[str, Any], ...]  # datamodel values to start with (none: defaults)
    given: tuple[str, ...]  # events sent first, each must be handled
    event: str | None  # None: only the start is checked
    expect: Expect
    skip: str = ""  # why the case cannot run (a row the search never reached)
    given_data: tuple[Any, ...] = ()  # per given event, its data (empty: none at all)
    event_data: Any = None  # the data sent with ``event``
    #: a timeout case: seconds waited, driver stalled (statectl.out.testgen.timing)
    wait: float = 0.0
    wait_states: tuple[str, ...] = ()  # the states before the wait, or around the kept event
    kept: str = ""  # a defer case: the event sent first and kept, released by ``event``


@dataclass(frozen=True, slots=True)
class Table:
    """The unhandled events of one configuration: one parametrised test, or one test
    that loops over them when the suite's tables are big (:mod:`~.writer` rule)."""

    name: str
    doc: str
    data: tuple[tuple[str, Any], ...]
    given: tuple[str, ...]
    states: tuple[str, ...]
    rows: tuple[tuple[str, str], ...]  # (event, reason) the kernel was asked about
    given_data: tuple[Any, ...] = ()
    #: with ``stepped``: every event a test can send (the graph's ``sendable``, shared);
    #: those not in ``stepped`` have no transition here and are not in ``rows`` (paths
    #: rule 4). Empty: ``rows`` is the whole table.
    events: tuple[str, ...] = ()
    stepped: frozenset[str] = frozenset()  # the events the kernel was asked about here

    @property
    def count(self) -> int:
        """How many events the table sends."""
        return len(self.rows) + len(self.events) - len(self.stepped)

    def skipped(self) -> frozenset[str]:
        """Events of ``events`` the table does not send (handled here, or refused)."""
        return self.stepped - {e for e, _ in self.rows}

    def all_rows(self) -> tuple[tuple[str, str], ...]:
        """Every (event, reason), those with no transition included, in table order."""
        if not self.events:
            return self.rows
        reasons = dict(self.rows)
        return tuple(
            (e, reasons.get(e, NO_TRANSITION))
            for e in self.events
            if e in reasons or e not in self.stepped
        )


@dataclass(frozen=True, slots=True)
class Suite:
    criterion: str
    cases: tuple[Case, ...]
    tables: tuple[Table, ...]
    notes: tuple[str, ...]  # what the module docstring must admit
    #: (part, cases it adds) when the criterion has parts (pairs: guardcases rule 5)
    parts: tuple[tuple[str, int], ...] = ()


def _slug(text: str) -> str:
    return identifier(text)


def where(t: Transition) -> str:
    """``motor.yaml:47``: the row's file (name only) and line."""
    o = t.origin
    name = Path(o.file).name
    if o.sheet is not None:
        name += f"[{o.sheet}]"
    return f"{name}:{o.line}" if o.line is not None else name


def describe(t: Transition) -> str:
    """The paper's words for a row: ``event [condition]: old -> new``."""
    event = " ".join(t.events) or "(eventless)"
    cond = t.condition or t.guard or ""
    text = f"{event} [{cond}]" if cond else event
    return f"{text}: {t.source} -> {', '.join(t.targets) or t.source + ' (stays)'}"


def _expect(chart: Chart, s: Step) -> Expect:
    return Expect(
        leaves(chart, s.target),
        tuple((n.invoke, n.method) for n in notifies(s)),
        s.unhandled.value if s.unhandled is not None else None,
    )


class _Names:
    def __init__(self) -> None:
        self.used: set[str] = set()

    def __call__(self, base: str) -> str:
        name = base[:90]
        n = 2
        while name in self.used:
            name = f"{base[:86]}_{n}"
            n += 1
        self.used.add(name)
        return name


def _sent(path: Iterable[Edge]) -> tuple[tuple[str, ...], tuple[Any, ...]]:
    """The events of a path, and their data (empty when none carries any)."""
    edges = tuple(path)
    data = tuple(e.data for e in edges)
    return tuple(e.event for e in edges), data if any(d is not None for d in data) else ()


def _case(g: Graph, names: _Names, base: str, doc: str, edge: Edge, skip: str = "") -> Case:
    given, given_data = _sent(g.path(edge.source))
    if edge.data is not None:
        doc += f" Sent with the data {edge.data!r}."
    return Case(
        names(base),
        doc,
        tuple(g.overrides(edge.source).items()),
        given,
        edge.event,
        _expect(g.chart, edge.step),
        skip,
        given_data,
        edge.data,
    )


def _configs(g: Graph) -> dict[tuple[str, ...], Node]:
    """Per reachable configuration, the node first reached with the default data if any."""
    found: dict[tuple[str, ...], Node] = {}
    for node in g.parent:
        key = leaves(g.chart, node.snapshot)
        old = found.get(key)
        if old is None or (old.data != 0 and node.data == 0):
            found[key] = node
    return found


def _by_source(g: Graph) -> dict[Node, list[Edge]]:
    out: dict[Node, list[Edge]] = {}
    for e in g.edges:
        out.setdefault(e.source, []).append(e)
    return out


def _tables(g: Graph, names: _Names) -> list[Table]:
    by_source = _by_source(g)
    out = []
    for key, node in _configs(g).items():
        pairs = tuple(
            (e.step.event or "", e.step.unhandled.value)
            for e in by_source.get(node, ())
            if e.step.unhandled is not None and e.data is None
        )
        stepped = g.stepped.get(node)
        quiet = stepped is not None and len(stepped) < len(g.sendable)
        if not pairs and not quiet:
            continue
        shown = ", ".join(key)
        given, given_data = _sent(g.path(node))
        out.append(
            Table(
                names(f"test_unhandled_in_{_slug('_'.join(key))}"),
                f"In {shown}, each event the tables do not take there changes nothing, "
                "for the reason given.",
                tuple(g.overrides(node).items()),
                given,
                key,
                pairs,
                given_data,
                g.sendable if quiet else (),
                stepped if quiet and stepped is not None else frozenset(),
            )
        )
    return out


def _rows(g: Graph, names: _Names) -> tuple[list[Case], list[str]]:
    cases: list[Case] = []
    notes: list[str] = []
    first: dict[int, Edge] = {}
    false: dict[int, Edge] = {}
    no_data: dict[int, Edge] = {}
    guarded = [t for t in g.chart.transitions if t.guard]
    #: rows into a history state: each configuration the history resumes, first edge
    resumes: dict[int, dict[tuple[str, ...], Edge]] = {}
    into_history = {
        id(t)
        for t in g.chart.transitions
        if any(g.chart.has_state(x) and g.chart.state(x).kind.is_history for x in t.targets)
    }
    for e in g.edges:
        for t in e.step.transitions:
            first.setdefault(id(t), e)
            if id(t) in into_history:
                resumes.setdefault(id(t), {}).setdefault(leaves(g.chart, e.step.target), e)
        for t in guarded:
            if (
                id(t) not in false
                and e.event in t.events
                and t.source in e.source.snapshot.active
                and t not in e.step.transitions
                and not g.guard_holds(e.source, t, e.data)
            ):
                if e.data is None and "_event" in (t.guard or ""):
                    no_data.setdefault(id(t), e)  # false for want of data: a last resort
                else:
                    false[id(t)] = e
    for k, e in no_data.items():
        false.setdefault(k, e)
    for i, t in enumerate(g.chart.transitions, 1):
        words = describe(t)
        base = f"test_row_{i:02d}_{_slug(' '.join(t.events) or 'eventless')}_{_slug(t.source)}"
        base += f"_to_{_slug('_'.join(t.targets) or 'itself')}"
        doc = f"Row {i}, {where(t)}: {words}."
        edge = first.get(id(t))
        if edge is None:
            why = "the search from the default state never takes this row"
            cases.append(Case(names(base), doc, (), (), None, Expect(()), why))
            notes.append(f"row {i} ({where(t)}) is never taken: {why}")
            continue
        if edge.event not in t.events:
            doc += f" Taken inside the step of {edge.event!r} (the chart raises {t.label!r})."
        cases.append(_case(g, names, base, doc, edge))
        for key, other in resumes.get(id(t), {}).items():
            if other is edge:
                continue
            shown = ", ".join(key)
            more = f"{doc} Its history resumes {shown} here (each configuration it resumes)."
            cases.append(_case(g, names, f"{base}_resumes_{_slug('_'.join(key))}", more, other))
        if t.guard:
            fe = false.get(id(t))
            if fe is None:
                notes.append(f"row {i} ({where(t)}): no path makes its guard {t.guard!r} false")
                continue
            doc = (
                f"Row {i}, {where(t)}: {words}; its guard {t.guard!r} is false here, "
                "so the row is not taken."
            )
            cases.append(_case(g, names, base + "_guard_false", doc, fe))
    return cases, notes


def _edge_key(g: Graph, e: Edge) -> tuple[Any, ...]:
    """An edge of the state graph: configuration, event, configuration, and the rows taken.

    The target is part of it: a row into a history state goes where the history says,
    so Continue from Paused is one edge per configuration it resumes.
    """
    return (
        leaves(g.chart, e.source.snapshot),
        e.event,
        leaves(g.chart, e.step.target),
        tuple(id(t) for t in e.step.transitions),
    )


def _transition_edges(g: Graph) -> list[Edge]:
    seen: dict[tuple[Any, ...], Edge] = {}
    for e in g.edges:
        if e.step.handled:
            seen.setdefault(_edge_key(g, e), e)
    return list(seen.values())


def _edge_words(g: Graph, e: Edge) -> str:
    src = ", ".join(leaves(g.chart, e.source.snapshot))
    dst = ", ".join(leaves(g.chart, e.step.target))
    rows = "; ".join(f"{where(t)} {describe(t)}" for t in e.step.transitions)
    return f"{e.event}: {src} -> {dst} (rows: {rows})"


def _transitions(g: Graph, names: _Names) -> list[Case]:
    out = []
    for e in _transition_edges(g):
        src = "_".join(leaves(g.chart, e.source.snapshot))
        base = f"test_transition_{_slug(e.event)}_from_{_slug(src)}"
        out.append(_case(g, names, base, f"Transition {_edge_words(g, e)}.", e))
    return out


def _states(g: Graph, names: _Names) -> list[Case]:
    out = []
    for key, node in _configs(g).items():
        base = f"test_state_{_slug('_'.join(key))}"
        doc = f"The device can be brought to {', '.join(key)}."
        edge = g.parent[node]
        if edge is None:  # the start: what entering the default configuration issued
            expect = _expect(g.chart, g.initial_steps[node.data])
            out.append(
                Case(
                    names(base),
                    doc + " It is where the device starts.",
                    tuple(g.overrides(node).items()),
                    (),
                    None,
                    expect,
                )
            )
        else:
            out.append(_case(g, names, base, doc, edge))
    return out


def _pairs(g: Graph, names: _Names) -> list[Case]:
    by_source = _by_source(g)
    out = []
    for e1 in _transition_edges(g):
        seen: set[tuple[Any, ...]] = set()
        for e2 in by_source.get(e1.target, ()):
            key = _edge_key(g, e2)
            if not e2.step.handled or key in seen:
                continue
            seen.add(key)
            given, given_data = _sent((*g.path(e1.source), e1))
            src = "_".join(leaves(g.chart, e1.source.snapshot))
            base = f"test_pair_{_slug(e1.event)}_from_{_slug(src)}_then_{_slug(e2.event)}"
            doc = f"Transition {_edge_words(g, e1)}, then {_edge_words(g, e2)}."
            out.append(
                Case(
                    names(base),
                    doc,
                    tuple(g.overrides(e1.source).items()),
                    given,
                    e2.event,
                    _expect(g.chart, e2.step),
                    given_data=given_data,
                    event_data=e2.data,
                )
            )
    return out


def cases_for(g: Graph, criterion: str) -> Suite:
    """The cases of one criterion (rule 2), with the unhandled tables."""
    names = _Names()
    notes: list[str] = []
    parts: list[tuple[str, int]] = []
    if criterion == "rows":
        cases, notes = _rows(g, names)
    elif criterion == "transitions":
        cases = _transitions(g, names)
    elif criterion == "states":
        cases = _states(g, names)
    elif criterion == "pairs":
        cases = _pairs(g, names)
        parts, more = _guard_parts(g, names, cases)
        notes += more
    else:
        raise StatectlError(f"unknown criterion {criterion!r}; choose one of {', '.join(CRITERIA)}")
    from statectl.out.testgen.timing import timing_cases  # it builds Cases: imported here

    timed, timing_notes = timing_cases(g, names)
    cases, notes = [*cases, *timed], [*notes, *timing_notes]
    if not g.complete:
        notes.append("the search stopped at its bound on nodes: some paths are missing")
    return Suite(criterion, tuple(cases), tuple(_tables(g, names)), tuple(notes), tuple(parts))


def _key(c: Case) -> tuple[Any, ...]:
    """What a case sends: two cases with one key are one test (guardcases rule 5)."""
    return (c.data, c.given, repr(c.given_data), c.event, repr(c.event_data))


def _guard_parts(
    g: Graph, names: _Names, cases: list[Case]
) -> tuple[list[tuple[str, int]], list[str]]:
    """Append the guard parts' cases to ``cases`` (pairs); what each part added."""
    from statectl.out.testgen.guardcases import guard_parts  # it builds Cases: imported here

    taken = {_key(c) for c in cases}
    first = len(cases)

    def add(base: str, doc: str, edge: Edge) -> bool:
        new = _case(g, _Names(), base, doc, edge)
        if _key(new) in taken:
            return False
        taken.add(_key(new))
        cases.append(replace(new, name=names(base)))
        return True

    def words(i: int, t: Transition) -> tuple[str, str]:
        return f"Row {i}, {where(t)}: {describe(t)}", where(t)

    counts, notes = guard_parts(g, add, words)
    return [("pairs", first), *counts], notes


def count_steps(cases: Iterable[Case]) -> int:
    """Events the cases send in all (the path, then the event)."""
    return sum(len(c.given) + (c.event is not None) for c in cases)
