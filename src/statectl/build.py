"""The paper's step 2: build a device's statechart from its two tables.

Rules:
1. Each state row becomes a :class:`~statectl.model.State`: atomic, or compound
   when other rows name it as ``parent``; a compound's initial is its child marked
   ``default``, else its first child. Controls, description, component (with the
   API text: ``Motor / Movement()``) and the row's location are kept.
2. The top-level state marked ``default`` is the chart's initial state (B202
   when there is none, B203 when several top-level states, or several children
   of one compound, are marked ``default``).
3. Each event row becomes ``old + event [guard] = new`` with the row's condition
   and location; for ``command`` and ``fault`` events with an API the transition
   notifies the API's invoke: ``Notify(number, name, method, event)``. Invoke
   numbers and names come from :func:`statectl.observers.derive_invokes`.
4. One :class:`~statectl.model.EventDef` per distinct event name (kind, API, the
   conditions as description, the first row's location); rows that disagree on
   kind or API are B206. Two explicit invoke names for one API are B211.
5. Redundancy is removed and reported, naming the rows: identical event rows
   (same event, old, new, guard) merge into one transition (B204, info); several
   rows for one state merge, controls united and texts joined (B205, info), unless
   they contradict each other on component or parent (T109, error); a state with
   no control that no event row touches and that has no children is removed
   (B207, warning).
6. An event row's old or new state must exist (B201), a parent too (B209), parents
   must not form a cycle (B210), an ignore cell names known events only (B208).
7. Guards are checked by :mod:`statectl.expr` against the data names plus
   ``previous`` and ``_event`` (X301-X303).
8. Any error: no chart, all diagnostics. The chart keeps the device name, the
   first state row's component, ignored (state, event) pairs and data as
   ``DataItem(name, repr(value))``.
"""

from __future__ import annotations

import difflib
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

from statectl.errors import Diagnostic, DiagnosticError, Location, Severity, has_errors
from statectl.expr import check_names, compile_expression
from statectl.model import (
    Action,
    Chart,
    ControlKind,
    DataItem,
    EventDef,
    Invoke,
    Notify,
    State,
    StateKind,
    Transition,
)
from statectl.observers import DRIVING_KINDS, EventSpec, derive_invokes
from statectl.tables import DeviceTables, load
from statectl.tables.schema import EventRow, StateRow

__all__ = ["CODES", "GUARD_NAMES", "build", "load_and_build", "load_chart"]

#: Names a guard may read besides the device's data.
GUARD_NAMES = frozenset({"previous", "_event"})

CODES = {
    "B201": "an event row's old or new state is not in the State Definition table",
    "B202": "no state is marked default",
    "B203": "several states are marked default at one level",
    "B204": "identical event rows merged into one transition (info)",
    "B205": "several rows for one state merged (info)",
    "B206": "rows for one event disagree on kind or API",
    "B207": "a state without control that no event touches was removed (warning)",
    "B208": "an ignore cell names an unknown event",
    "B209": "a parent names an unknown state",
    "B210": "parents form a cycle",
    "B211": "one API has two explicit invoke names",
}


def _d(code: str, severity: Severity, where: Location, message: str, hint: str = "") -> Diagnostic:
    return Diagnostic(code, severity, where, message, hint)


def _rows_text(places: Sequence[Location]) -> str:
    return ", ".join(str(p) for p in places)


def _hint(word: str, choices: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    known = "known: " + ", ".join(choices)
    return f"did you mean {close[0]!r}? {known}" if close else known


@dataclass(frozen=True, slots=True)
class _Merged:
    """One state after its rows were merged."""

    name: str
    component: str
    api: str
    controls: tuple[ControlKind, ...]
    description: str
    ignore: tuple[str, ...]
    parent: str
    rows: tuple[Location, ...]


def _unique(items: Sequence[str]) -> list[str]:
    return list(dict.fromkeys(i for i in items if i))


def _merge_states(rows: Sequence[StateRow], diags: list[Diagnostic]) -> dict[str, _Merged]:
    groups: dict[str, list[StateRow]] = {}
    for r in rows:
        groups.setdefault(r.state, []).append(r)
    merged: dict[str, _Merged] = {}
    for name, group in groups.items():
        first = group[0]
        places = tuple(r.where for r in group)
        if len(group) > 1:
            # an empty component is unspecified; an empty parent means top level
            for column, values in (
                ("component", _unique([r.component for r in group])),
                ("parent", list(dict.fromkeys(r.parent for r in group))),
            ):
                if len(values) > 1:
                    diags.append(
                        _d(
                            "T109",
                            Severity.ERROR,
                            group[1].where,
                            f"rows for state {name!r} disagree on {column}: "
                            + ", ".join(repr(v) for v in values),
                            f"rows at {_rows_text(places)}; give every row of a state "
                            f"the same {column}",
                        )
                    )
            diags.append(
                _d(
                    "B205",
                    Severity.INFO,
                    first.where,
                    f"{len(group)} rows for state {name!r} merged into one state",
                    f"rows at {_rows_text(places)}",
                )
            )
        controls: list[ControlKind] = []
        for r in group:
            controls.extend(c for c in r.controls if c not in controls)
        merged[name] = _Merged(
            name=name,
            component=next((r.component for r in group if r.component), ""),
            api=", ".join(_unique([r.api for r in group])),
            controls=tuple(controls),
            description="\n".join(_unique([r.description for r in group])),
            ignore=tuple(_unique([i for r in group for i in r.ignore])),
            parent=first.parent,
            rows=places,
        )
    return merged


def _order(
    states: dict[str, _Merged], diags: list[Diagnostic]
) -> tuple[list[str], dict[str, list[str]]]:
    """Document order (parents before children) and each state's children."""
    children: dict[str, list[str]] = {n: [] for n in states}
    for s in states.values():
        if s.parent and s.parent not in states:
            diags.append(
                _d(
                    "B209",
                    Severity.ERROR,
                    s.rows[0],
                    f"state {s.name!r} names unknown parent {s.parent!r}",
                    _hint(s.parent, list(states)),
                )
            )
        elif s.parent:
            children[s.parent].append(s.name)
    order: list[str] = []

    def visit(name: str) -> None:
        order.append(name)
        for child in children[name]:
            visit(child)

    for s in states.values():
        if not s.parent or s.parent not in states:
            visit(s.name)
    for s in states.values():
        if s.name not in order:
            diags.append(
                _d(
                    "B210",
                    Severity.ERROR,
                    s.rows[0],
                    f"state {s.name!r} is its own ancestor through its parents",
                    "a parent chain must end at a top-level state",
                )
            )
    return order, children


def _defaults(
    names: Sequence[str],
    states: dict[str, _Merged],
    where: Location,
    level: str,
    diags: list[Diagnostic],
) -> list[str]:
    marked = [n for n in names if ControlKind.DEFAULT in states[n].controls]
    if len(marked) > 1:
        diags.append(
            _d(
                "B203",
                Severity.ERROR,
                states[marked[1]].rows[0],
                f"several {level} states are marked default: " + ", ".join(marked),
                "mark exactly one state default at each level",
            )
        )
    return marked


def _removed(
    states: dict[str, _Merged],
    children: dict[str, list[str]],
    events: Sequence[EventRow],
    diags: list[Diagnostic],
) -> set[str]:
    touched = {e.old for e in events} | {e.new for e in events}
    removed: set[str] = set()
    for s in states.values():
        if not s.controls and s.name not in touched and not children[s.name]:
            removed.add(s.name)
            diags.append(
                _d(
                    "B207",
                    Severity.WARNING,
                    s.rows[0],
                    f"state {s.name!r} has no control and no event row reaches or leaves it: "
                    "removed",
                    f"rows at {_rows_text(s.rows)}; give it a control kind or an event row",
                )
            )
    return removed


def _merge_events(rows: Sequence[EventRow], diags: list[Diagnostic]) -> list[EventRow]:
    groups: dict[tuple[str, str, str, str], list[EventRow]] = {}
    for r in rows:
        groups.setdefault((r.event, r.old, r.new, r.guard), []).append(r)
    merged: list[EventRow] = []
    for (event, old, new, _), group in groups.items():
        first = group[0]
        if len(group) > 1:
            diags.append(
                _d(
                    "B204",
                    Severity.INFO,
                    first.where,
                    f"{len(group)} identical rows for {old} + {event} = {new} merged into "
                    "one transition",
                    f"rows at {_rows_text([r.where for r in group])}",
                )
            )
            conditions = "; ".join(_unique([r.condition for r in group]))
            first = EventRow(
                first.event,
                conditions,
                first.guard,
                first.old,
                first.new,
                first.kind,
                first.api,
                first.invoke or next((r.invoke for r in group if r.invoke), ""),
                first.where,
            )
        merged.append(first)
    return merged


def _event_defs(rows: Sequence[EventRow], diags: list[Diagnostic]) -> tuple[EventDef, ...]:
    groups: dict[str, list[EventRow]] = {}
    for r in rows:
        groups.setdefault(r.event, []).append(r)
    defs: list[EventDef] = []
    for name, group in groups.items():
        first = group[0]
        for column in ("kind", "api"):
            values = list(dict.fromkeys(getattr(r, column) for r in group))
            if len(values) > 1:
                shown = [v.value if column == "kind" else repr(v) for v in values]
                diags.append(
                    _d(
                        "B206",
                        Severity.ERROR,
                        next(r.where for r in group if getattr(r, column) != values[0]),
                        f"rows for event {name!r} disagree on {column}: " + ", ".join(shown),
                        f"rows at {_rows_text([r.where for r in group])}; "
                        f"give every row of an event the same {column}",
                    )
                )
        defs.append(
            EventDef(
                name,
                first.kind,
                first.api or None,
                "; ".join(_unique([r.condition for r in group])),
                first.where,
            )
        )
    return tuple(defs)


def _check_invokes(rows: Sequence[EventRow], diags: list[Diagnostic]) -> None:
    named: dict[str, EventRow] = {}
    for r in rows:
        if r.invoke and not r.api:
            diags.append(
                _d(
                    "B211",
                    Severity.ERROR,
                    r.where,
                    f"event {r.event!r} names invoke {r.invoke!r} but no API",
                    "an invoke number belongs to an API: fill in the 'api' cell",
                )
            )
        elif r.invoke:
            seen = named.setdefault(r.api, r)
            if seen.invoke != r.invoke:
                diags.append(
                    _d(
                        "B211",
                        Severity.ERROR,
                        r.where,
                        f"API {r.api!r} is named invoke {seen.invoke!r} at {seen.where} "
                        f"and {r.invoke!r} here",
                        "give one invoke name per API",
                    )
                )


def _literal(value: object) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return f"float({str(value)!r})"
    return repr(value)


def build(tables: DeviceTables) -> tuple[Chart | None, list[Diagnostic]]:
    """Build the chart; ``None`` and every diagnostic if any is an error."""
    diags: list[Diagnostic] = []
    source = tables.source
    merged = _merge_states(tables.states, diags)
    order, children = _order(merged, diags)
    removed = _removed(merged, children, tables.events, diags)
    kept = [n for n in order if n not in removed]

    states: list[State] = []
    for name in kept:
        m = merged[name]
        kids = [c for c in children[name] if c not in removed]
        initial: tuple[str, ...] = ()
        if kids:
            marked = _defaults(kids, merged, m.rows[0], f"{name!r} child", diags)
            initial = (marked[0] if marked else kids[0],)
        component = f"{m.component} / {m.api}" if m.component and m.api else m.component or m.api
        states.append(
            State(
                name=name,
                kind=StateKind.COMPOUND if kids else StateKind.ATOMIC,
                parent=m.parent or None,
                initial=initial,
                controls=frozenset(m.controls),
                description=m.description,
                component=component,
                origin=m.rows[0],
            )
        )
    top = [n for n in kept if not merged[n].parent]
    marked = _defaults(top, merged, source, "top-level", diags)
    if not marked:
        diags.append(
            _d(
                "B202",
                Severity.ERROR,
                source,
                "no top-level state is marked default, so the chart has no initial state",
                "set control: default on the state the device starts in",
            )
        )

    state_names = list(merged)
    data_names = [name for name, _ in tables.data]
    known = set(data_names) | GUARD_NAMES
    for r in tables.events:
        for column in ("old", "new"):
            target = getattr(r, column)
            if target not in merged:
                diags.append(
                    _d(
                        "B201",
                        Severity.ERROR,
                        r.where,
                        f"event {r.event!r}: {column} state {target!r} is not in the states table",
                        _hint(target, state_names),
                    )
                )
        if r.guard:
            expression, problems = compile_expression(r.guard, r.where)
            diags.extend(problems)
            if expression is not None:
                diags.extend(check_names(expression, known, r.where))

    rows = _merge_events(tables.events, diags)
    events = _event_defs(rows, diags)
    _check_invokes(rows, diags)
    apis, invokes = derive_invokes(
        [EventSpec(r.event, r.kind, r.api or None, r.new, r.invoke or None) for r in rows]
    )
    by_method: dict[str, Invoke] = {i.method: i for i in invokes}
    transitions: list[Transition] = []
    for r in rows:
        actions: tuple[Action, ...] = ()
        invoke = by_method.get(r.api)
        if r.kind in DRIVING_KINDS and invoke is not None:
            actions = (Notify(invoke.number, invoke.name, invoke.method, r.event),)
        transitions.append(
            Transition(
                source=r.old,
                events=(r.event,),
                targets=(r.new,),
                guard=r.guard or None,
                condition=r.condition,
                actions=actions,
                origin=r.where,
            )
        )

    event_names = [e.name for e in events]
    ignored: set[tuple[str, str]] = set()
    for name in kept:
        m = merged[name]
        for event in m.ignore:
            if event in event_names:
                ignored.add((name, event))
            else:
                diags.append(
                    _d(
                        "B208",
                        Severity.ERROR,
                        m.rows[0],
                        f"state {name!r} ignores unknown event {event!r}",
                        _hint(event, event_names),
                    )
                )

    if has_errors(diags):
        return None, diags
    chart = Chart(
        name=tables.device,
        states=tuple(states),
        transitions=tuple(transitions),
        initial=(marked[0],),
        events=events,
        apis=apis,
        invokes=invokes,
        ignored=frozenset(ignored),
        data=tuple(DataItem(n, _literal(v), source) for n, v in tables.data),
        component=tables.states[0].component if tables.states else "",
        origin=source,
    )
    return chart, diags


def load_and_build(path: str | os.PathLike[str]) -> tuple[Chart | None, list[Diagnostic]]:
    """Load a device file in any table format and build it; every diagnostic of both steps."""
    tables, diags = load(path)
    if tables is None:
        return None, diags
    chart, more = build(tables)
    return chart, [*diags, *more]


def load_chart(path: str | os.PathLike[str]) -> Chart:
    """The chart of a device file; raises :class:`DiagnosticError` carrying every problem."""
    chart, diags = load_and_build(path)
    if chart is None or has_errors(diags):
        raise DiagnosticError(diags)
    return chart
