"""The paper's step 2: build a device's statechart from its two tables.

Rules:
1. Each state row becomes a :class:`~statectl.model.State`: atomic, or compound
   when other rows name it as ``parent``, unless its ``type`` says ``parallel``,
   ``final``, ``history`` or ``deep history``. A compound's initial is its child
   marked ``default``, else its first child that is not a history; a parallel
   enters all its children (its regions). Controls, description, component (with
   the API text: ``Motor / Movement()``) and the row's location are kept.
1a. A history state's ``default`` cell names where it goes before it has recorded
   anything; blank means its parent's initial child (or, in a parallel, every
   region). Misuse is reported: a history at the top, with children, with a
   control, or with a default outside its parent (B212); a final with children
   (B213); a parallel with fewer than two regions (B214); an explicit ``atomic``
   with children or ``compound`` without (B215); an event row leaving a history
   or a final state (B216); a ``default`` cell on a state that is not a history
   (B217).
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
   they contradict each other on component, parent, type or default (T109,
   error); a state with no control and no explicit type that no event row
   touches and that has no children left is removed (B207, warning), repeatedly,
   so a parent whose children all went goes too.
6. An event row's old or new state must exist (B201), a parent too (B209), parents
   must not form a cycle (B210), an ignore cell names known events only (B208).
   States nest at most :data:`MAX_STATE_DEPTH` levels deep (B218), so no later
   stage (semantics, checks, codegen) meets a hierarchy deeper than it handles.
7. Guards are checked by :mod:`statectl.expr` against the data names plus
   ``previous`` and ``_event`` (X301-X303).
8. Any error: no chart, all diagnostics. The chart keeps the device name, the
   first state row's component, ignored (state, event) pairs and data as
   ``DataItem(name, repr(value))``.
"""

from __future__ import annotations

import ast
import dataclasses
import difflib
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from statectl.codes import family
from statectl.errors import Diagnostic, DiagnosticError, Location, Severity, has_errors
from statectl.expr import Expression, check_names, compile_expression
from statectl.model import (
    Action,
    Chart,
    ControlKind,
    DataItem,
    EventDef,
    EventKind,
    Invoke,
    Notify,
    State,
    StateKind,
    Transition,
)
from statectl.observers import DRIVING_KINDS, EventSpec, derive_invokes
from statectl.tables import DeviceTables, load
from statectl.tables.schema import (
    TYPE_NAMES,
    Bad,
    EventRow,
    StateRow,
    normalize_value,
    validate_for_writing,
)

__all__ = [
    "CODES",
    "GUARD_NAMES",
    "build",
    "chart_to_tables",
    "load_and_build",
    "load_chart",
    "strip_origins",
]

#: Names a guard may read besides the device's data.
GUARD_NAMES = frozenset({"previous", "_event"})

#: Deepest state hierarchy a device file may build (B218; docs/limits.md).
MAX_STATE_DEPTH = 100

#: Code -> one-line summary of every B2xx code (a view of statectl.codes.REGISTRY).
CODES: Mapping[str, str] = family("B2")


def _compile(guard: str, where: Location) -> tuple[Expression | None, list[Diagnostic]]:
    """``compile_expression``, with a guard nested too deeply to compile as X301."""
    try:
        return compile_expression(guard, where)
    except (RecursionError, MemoryError):
        shown = guard if len(guard) <= 40 else guard[:37] + "..."
        return None, [
            _d(
                "X301",
                Severity.ERROR,
                where,
                f"guard {shown!r} is nested too deeply to analyse",
                "write it with fewer nested parts; see docs/limits.md",
            )
        ]


def _d(code: str, severity: Severity, where: Location, message: str, hint: str = "") -> Diagnostic:
    return Diagnostic(code, severity, where, message, hint)


def _rows_text(places: Sequence[Location]) -> str:
    return ", ".join(str(p) for p in places)


#: Names a hint lists at most, and candidates a did-you-mean compares at most: a file
#: with thousands of wrong names gets thousands of short hints, found in linear time.
_HINT_LISTED = 20
_HINT_SEARCHED = 200


def _listed(names: Sequence[str]) -> str:
    shown = ", ".join(names[:_HINT_LISTED])
    return shown + (f" and {len(names) - _HINT_LISTED} more" if len(names) > _HINT_LISTED else "")


def _hint(word: str, choices: Sequence[str]) -> str:
    names = list(choices)
    if len(names) > _HINT_SEARCHED:  # the likeliest: same first letter, similar length
        near = [n for n in names if n[:1] == word[:1] and abs(len(n) - len(word)) <= 2]
        names_searched = near[:_HINT_SEARCHED]
    else:
        names_searched = names
    close = difflib.get_close_matches(word, names_searched, n=1, cutoff=0.6)
    known = "known: " + _listed(names)
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
    type: StateKind | None = None
    default: tuple[str, ...] = ()


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
                ("type", _unique([r.type_text for r in group])),
                ("default", _unique([", ".join(r.default) for r in group])),
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
            type=next((r.type for r in group if r.type is not None), None),
            default=next((r.default for r in group if r.default), ()),
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
    depth: dict[str, int] = {}
    for s in states.values():  # depth first, parents before children, without recursion
        if s.parent and s.parent in states:
            continue
        pending = [(s.name, 1)]
        while pending:
            name, level = pending.pop()
            order.append(name)
            depth[name] = level
            pending.extend((child, level + 1) for child in reversed(children[name]))
    too_deep = [n for n in order if depth[n] == MAX_STATE_DEPTH + 1]
    for name in too_deep:
        diags.append(
            _d(
                "B218",
                Severity.ERROR,
                states[name].rows[0],
                f"state {name!r} is nested {MAX_STATE_DEPTH + 1} levels deep "
                f"(the limit is {MAX_STATE_DEPTH})",
                "flatten the parent chain; see docs/limits.md",
            )
        )
    for s in states.values():
        if s.name not in depth:
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
    touched.update(d for s in states.values() for d in s.default)
    for s in states.values():  # a parallel's children are its regions, always active with it
        if s.type is StateKind.PARALLEL:
            touched.update(children[s.name])
    removed: set[str] = set()
    changed = True
    while changed:
        changed = False
        for s in states.values():
            if s.name in removed or s.controls or s.type is not None or s.name in touched:
                continue
            if any(c not in removed for c in children[s.name]):
                continue
            removed.add(s.name)
            changed = True
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


def _kind(m: _Merged, kids: Sequence[str], diags: list[Diagnostic]) -> StateKind:
    """The state's kind from its ``type`` cell and whether it has children (B212-B215)."""
    implied = StateKind.COMPOUND if kids else StateKind.ATOMIC
    kind = m.type if m.type is not None else implied
    where = m.rows[0]
    if kind is StateKind.ATOMIC and kids:
        diags.append(
            _d(
                "B215",
                Severity.ERROR,
                where,
                f"state {m.name!r} is typed atomic but has children: " + ", ".join(kids),
                "leave 'type' empty (or write compound) for a state with children",
            )
        )
    elif kind is StateKind.COMPOUND and not kids:
        diags.append(
            _d(
                "B215",
                Severity.ERROR,
                where,
                f"state {m.name!r} is typed compound but no row names it as parent",
                "add child rows with parent: " + m.name + ", or leave 'type' empty",
            )
        )
    elif kind is StateKind.FINAL and kids:
        diags.append(
            _d(
                "B213",
                Severity.ERROR,
                where,
                f"final state {m.name!r} has children: " + ", ".join(kids),
                "a final state is atomic: move the children to another state",
            )
        )
    elif kind is StateKind.PARALLEL and len(kids) < 2:
        diags.append(
            _d(
                "B214",
                Severity.ERROR,
                where,
                f"parallel state {m.name!r} has {len(kids)} region(s)",
                "a parallel state needs at least two child rows (its regions); "
                "with one, leave 'type' empty",
            )
        )
    elif kind.is_history:
        problem = ""
        if not m.parent:
            problem = "is at the top level"
        elif kids:
            problem = "has children"
        elif m.controls:
            problem = "has a control (" + ", ".join(c.value for c in m.controls) + ")"
        if problem:
            diags.append(
                _d(
                    "B212",
                    Severity.ERROR,
                    where,
                    f"history state {m.name!r} {problem}",
                    "a history row only names its parent (a compound or parallel state) "
                    "and optionally a default; it is never active itself",
                )
            )
    return kind


def _history_default(
    m: _Merged,
    kinds: dict[str, StateKind],
    merged: dict[str, _Merged],
    children: dict[str, list[str]],
    removed: set[str],
    diags: list[Diagnostic],
) -> tuple[str, ...]:
    """Where a history goes before it recorded anything (B212, B217)."""
    kind = kinds[m.name]
    if not kind.is_history:
        if m.default:
            diags.append(
                _d(
                    "B217",
                    Severity.ERROR,
                    m.rows[0],
                    f"state {m.name!r} has a default cell but is not a history state",
                    "'default' belongs to history rows; mark a compound's initial child "
                    "with control: default",
                )
            )
        return ()
    parent = m.parent
    if not parent or parent not in kinds:
        return ()
    siblings = [c for c in children[parent] if c not in removed and not kinds[c].is_history]
    if not m.default:
        if kinds[parent] is StateKind.PARALLEL:
            return tuple(siblings)
        marked = [c for c in siblings if ControlKind.DEFAULT in merged[c].controls]
        return (marked[0],) if marked else tuple(siblings[:1])
    for target in m.default:
        inside = target in kinds and target != parent
        p = merged[target].parent if target in merged else ""
        while inside and p and p != parent:
            p = merged[p].parent if p in merged else ""
        if (
            not inside
            or p != parent
            or (kind is StateKind.HISTORY_SHALLOW and merged[target].parent != parent)
        ):
            where = "a child" if kind is StateKind.HISTORY_SHALLOW else "inside"
            diags.append(
                _d(
                    "B212",
                    Severity.ERROR,
                    m.rows[0],
                    f"history state {m.name!r} defaults to {target!r}, which is not "
                    f"{where} of its parent {parent!r}",
                    _hint(target, siblings),
                )
            )
    return m.default


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
    kept = [n for n in order if n not in removed]  # removed is a set

    kinds = {
        name: _kind(merged[name], [c for c in children[name] if c not in removed], diags)
        for name in kept
    }
    states: list[State] = []
    for name in kept:
        m = merged[name]
        kids = [c for c in children[name] if c not in removed]
        kind = kinds[name]
        initial: tuple[str, ...] = ()
        if kind is StateKind.COMPOUND:
            entries = [c for c in kids if not kinds[c].is_history]
            if not entries:
                diags.append(
                    _d(
                        "B212",
                        Severity.ERROR,
                        m.rows[0],
                        f"state {name!r} holds only history states: " + ", ".join(kids),
                        "a history returns to a sibling state: add the states it returns to",
                    )
                )
            marked = _defaults(entries, merged, m.rows[0], f"{name!r} child", diags)
            initial = (marked[0],) if marked else tuple(entries[:1])
        component = f"{m.component} / {m.api}" if m.component and m.api else m.component or m.api
        states.append(
            State(
                name=name,
                kind=kind,
                parent=m.parent or None,
                initial=initial,
                controls=frozenset(m.controls),
                description=m.description,
                component=component,
                history_default=_history_default(m, kinds, merged, children, removed, diags),
                origin=m.rows[0],
            )
        )
    top = [n for n in kept if not merged[n].parent]
    marked = _defaults(top, merged, source, "top-level", diags)
    for r in tables.events:
        left = kinds.get(r.old)
        if left is not None and (left.is_history or left is StateKind.FINAL):
            diags.append(
                _d(
                    "B216",
                    Severity.ERROR,
                    r.where,
                    f"event {r.event!r} leaves {r.old!r}, a {TYPE_NAMES[left]} state",
                    "a final state is the end of its parent and a history only points back: "
                    "start the row from the parent (or another state) instead",
                )
            )
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
            expression, problems = _compile(r.guard, r.where)
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
    declared = set(event_names)
    ignored: set[tuple[str, str]] = set()
    for name in kept:
        m = merged[name]
        for event in m.ignore:
            if event in declared:
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


def _strip(value: Any) -> Any:
    if isinstance(value, Location):
        return Location()
    if isinstance(value, tuple):
        return tuple(_strip(v) for v in value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        changes = {
            f.name: _strip(getattr(value, f.name)) for f in dataclasses.fields(value) if f.init
        }
        return dataclasses.replace(value, **changes)
    return value


def strip_origins(chart: Chart) -> Chart:
    """The chart with every location (of states, transitions, events, actions) dropped.

    Two charts built from different files, or from a table and its SCXML export,
    are the same chart when their stripped values are equal.
    """
    stripped: Chart = _strip(chart)
    return stripped


# -- the inverse: a chart back to tables -------------------------------------------------


def _info(code: str, where: Location, message: str, hint: str) -> Diagnostic:
    return Diagnostic(code, Severity.INFO, where, message, hint)


def _data_value(expr: str | None) -> tuple[bool, object]:
    """A data expression as a table literal: ``(True, value)`` or ``(False, None)``."""
    if expr is None:
        return False, None
    text = expr.strip()
    special = {"float('inf')": math.inf, "float('-inf')": -math.inf}
    if text in special:
        return True, special[text]
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
        return False, None
    normal = normalize_value(value)
    if isinstance(normal, Bad):
        return False, None
    return True, normal


def _misfits(chart: Chart) -> list[Diagnostic]:
    """Why a chart cannot be written as device tables (B220-B222, info); empty if it can."""
    out: list[Diagnostic] = []
    keep = "keep it as SCXML"
    if chart.datamodel not in ("safe", "null"):
        out.append(
            _info(
                "B220",
                chart.origin,
                f"datamodel {chart.datamodel!r}: device tables use the safe expression language",
                keep + "; datamodel='python' is explicit trust, which tables never grant",
            )
        )
    if chart.script:
        out.append(_info("B220", chart.origin, "the document has a top-level <script>", keep))
    top = [s.name for s in chart.states if s.parent is None]
    if len(chart.initial) > 1 or (chart.initial and chart.initial[0] not in top):
        out.append(
            _info(
                "B220",
                chart.origin,
                "the initial configuration " + " ".join(chart.initial) + " is not one top-level "
                "state",
                "tables mark one top-level state default",
            )
        )
    for d in chart.data:
        if d.src is not None or d.body is not None or not _data_value(d.expr)[0]:
            out.append(
                _info(
                    "B220",
                    d.origin,
                    f"data {d.name!r} is not a literal value",
                    "table data holds literals: null, booleans, numbers, strings, lists",
                )
            )
    by_name = {s.name: s for s in chart.states}
    for s in chart.states:
        content = [
            what
            for what, present in (
                ("<onentry>", s.on_entry),
                ("<onexit>", s.on_exit),
                ("<initial> content", s.initial_actions),
                ("history default content", s.history_actions),
                ("<datamodel>", s.data),
                ("<invoke>", s.invokes),
                ("<donedata>", s.donedata is not None),
            )
            if present
        ]
        if content:
            out.append(
                _info(
                    "B220",
                    s.origin,
                    f"state {s.name!r} has executable content: " + ", ".join(content),
                    keep + "; tables hold states, transitions and their notifications only",
                )
            )
        if s.kind is StateKind.COMPOUND and (
            len(s.initial) != 1 or by_name.get(s.initial[0], s).parent != s.name
        ):
            out.append(
                _info(
                    "B220",
                    s.origin,
                    f"state {s.name!r} starts in " + " ".join(s.initial) + ", not one child",
                    "tables mark one child of a compound state default",
                )
            )
    known = {d.name for d in chart.data} | GUARD_NAMES
    for t in chart.transitions:
        shape = ""
        if not t.events:
            shape = "is eventless"
        elif len(t.events) > 1:
            shape = "has several events"
        elif len(t.targets) != 1:
            shape = "has no target" if not t.targets else "has several targets"
        elif t.internal:
            shape = "is internal"
        elif any(not isinstance(a, Notify) for a in t.actions):
            out.append(
                _info(
                    "B220",
                    t.origin,
                    f"the transition from {t.source!r} has executable content",
                    keep + "; an event row can only notify its API's observer",
                )
            )
        if shape:
            out.append(
                _info(
                    "B221",
                    t.origin,
                    f"the transition from {t.source!r} {shape}",
                    "an event row is one event from one old state to one new state",
                )
            )
        if t.guard:
            expression, problems = _compile(t.guard, t.origin)
            if expression is not None:
                problems = check_names(expression, known, t.origin)
            if problems:
                out.append(
                    _info(
                        "B222",
                        t.origin,
                        f"guard {t.guard!r} is not a table guard: {problems[0].message}",
                        keep + "; table guards are safe expressions over the data names",
                    )
                )
    return out


def _split_component(text: str, component: str) -> tuple[str, str]:
    """Undo build's ``component / api`` join, given the chart's component."""
    if component and text == component:
        return component, ""
    if component and text.startswith(component + " / "):
        return component, text[len(component) + 3 :]
    return text, ""


def _rows_of(chart: Chart) -> tuple[DeviceTables, Chart]:
    """The tables for a chart that fits, and the chart they are meant to build.

    The expected chart is ``chart`` plus what tables always say: the initial states
    marked ``default``, the safe datamodel, data as literals, an event declaration
    per event (when the chart declared none).
    """
    by_name = {s.name: s for s in chart.states}
    top = [s.name for s in chart.states if s.parent is None]
    defaults: set[str] = {chart.initial[0] if chart.initial else top[0]}
    for s in chart.states:
        if s.kind is StateKind.COMPOUND:
            kids = [c.name for c in chart.states if c.parent == s.name and not c.kind.is_history]
            marked = [k for k in kids if ControlKind.DEFAULT in by_name[k].controls]
            if s.initial[0] not in marked and (marked or kids[:1] != [s.initial[0]]):
                defaults.add(s.initial[0])
    event_names = chart.event_names
    states: list[StateRow] = []
    expected_states: list[State] = []
    for s in chart.states:
        controls = set(s.controls) | ({ControlKind.DEFAULT} if s.name in defaults else set())
        component, api = _split_component(s.component, chart.component)
        implied = s.kind in (StateKind.ATOMIC, StateKind.COMPOUND)
        kind: StateKind | None = None if implied else s.kind
        states.append(
            StateRow(
                component=component,
                api=api,
                state=s.name,
                controls=tuple(c for c in ControlKind if c in controls),
                description=s.description,
                ignore=tuple(e for e in event_names if (s.name, e) in chart.ignored),
                parent=s.parent or "",
                type=kind,
                default=s.history_default if s.kind.is_history else (),
            )
        )
        expected_states.append(dataclasses.replace(s, controls=frozenset(controls)))
    declared = {e.name: e for e in chart.events}
    specs = [
        EventSpec(
            t.events[0],
            declared[t.events[0]].kind if t.events[0] in declared else EventKind.COMMAND,
            declared[t.events[0]].api if t.events[0] in declared else None,
            t.targets[0],
        )
        for t in chart.transitions
    ]
    derived = {i.method: i.name for i in derive_invokes(specs)[1]}
    explicit = {i.method: i.name for i in chart.invokes if derived.get(i.method) != i.name}
    events = tuple(
        EventRow(
            event=t.events[0],
            condition=t.condition,
            guard=t.guard or "",
            old=t.source,
            new=t.targets[0],
            kind=spec.kind,
            api=spec.api or "",
            invoke=explicit.get(spec.api or "", ""),
        )
        for t, spec in zip(chart.transitions, specs, strict=True)
    )
    data = tuple((d.name, _data_value(d.expr)[1]) for d in chart.data)
    tables = DeviceTables(chart.name, tuple(states), events, data, chart.origin)
    expected = dataclasses.replace(
        chart,
        states=tuple(expected_states),
        initial=(chart.initial[0] if chart.initial else top[0],),
        datamodel="safe",
        data=tuple(DataItem(n, _literal(v), chart.origin) for n, v in data),
    )
    return tables, expected


def chart_to_tables(chart: Chart) -> tuple[DeviceTables | None, list[Diagnostic]]:
    """The device tables that :func:`build` turns back into ``chart``, or why there are none.

    A chart fits when it has no executable content beyond notifications, one event
    and one target per transition, safe guards and literal data (B220-B222). The
    tables are then built and compared with the chart, locations aside; any
    difference is B223. Every diagnostic is info: a chart that does not fit is
    not wrong, it simply stays SCXML.
    """
    misfits = _misfits(chart)
    if misfits or not chart.states:
        return None, misfits
    tables, expected = _rows_of(chart)
    problems = validate_for_writing(tables, chart.origin)
    built, diags = build(tables)
    errors = [*problems, *(d for d in diags if d.severity is Severity.ERROR)]
    if errors or built is None:
        first = errors[0] if errors else None
        return None, [
            _info(
                "B223",
                first.where if first is not None else chart.origin,
                "the tables would not build: " + (first.message if first else "unknown"),
                "keep it as SCXML",
            )
        ]
    if not chart.events:
        expected = dataclasses.replace(
            expected, events=built.events, apis=built.apis, invokes=built.invokes
        )
    want, got = strip_origins(expected), strip_origins(built)
    if want != got:
        field = next(
            f.name
            for f in dataclasses.fields(Chart)
            if f.compare and getattr(want, f.name) != getattr(got, f.name)
        )
        return None, [
            _info(
                "B223",
                chart.origin,
                f"the tables would build a different chart (its {field} differ)",
                "keep it as SCXML",
            )
        ]
    return tables, []


def load_and_build(path: str | os.PathLike[str]) -> tuple[Chart | None, list[Diagnostic]]:
    """Load a device file in any table format and build it; every diagnostic of both steps.

    Tables that loaded with errors are still built, so one run reports the
    problems of both steps; their chart is not returned, since it is not the
    file's.
    """
    tables, diags = load(path)
    if tables is None:
        return None, diags
    chart, more = build(tables)
    return (None if has_errors(diags) else chart), [*diags, *more]


def load_chart(path: str | os.PathLike[str]) -> Chart:
    """The chart of a device file; raises :class:`DiagnosticError` carrying every problem."""
    chart, diags = load_and_build(path)
    if chart is None or has_errors(diags):
        raise DiagnosticError(diags)
    return chart
