"""The paper's step 2: build a device's statechart from its tables (:func:`build`).

Rules:
1. Each state row becomes a :class:`~statectl.kernel.model.State`: atomic, or compound
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
   numbers and names come from :func:`statectl.front.observers.derive_invokes`.
4. One :class:`~statectl.kernel.model.EventDef` per distinct event name (kind, API, the
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
7. Guards are checked by :mod:`statectl.kernel.expr` against the data names plus
   ``previous`` and ``_event`` (X301-X303).
8. Any error: no chart, all diagnostics. The chart keeps the device name, the
   first state row's component, ignored (state, event) pairs and data as
   ``DataItem(name, repr(value))``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, TypeVar

from statectl.front.builder.common import GUARD_NAMES, _compile, _d, _hint, _literal
from statectl.front.builder.eventdata import Fields, assign_actions, check_guard, event_fields
from statectl.front.builder.events import _check_invokes, _event_defs, _merge_events
from statectl.front.builder.extras import check_apis, expand_ignore, state_extras
from statectl.front.builder.numbers import state_numbers
from statectl.front.builder.states import (
    _defaults,
    _history_default,
    _kind,
    _merge_states,
    _Merged,
    _order,
    _removed,
)
from statectl.front.observers import DRIVING_KINDS, EventSpec, derive_invokes
from statectl.front.tables import DeviceTables
from statectl.front.tables.rows import TYPE_NAMES, EventRow
from statectl.kernel.errors import Diagnostic, Location, Severity, has_errors
from statectl.kernel.model import (
    Action,
    Chart,
    DataItem,
    EventDef,
    InvokeNumber,
    Notify,
    State,
    StateKind,
    Transition,
)


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
    numbers = state_numbers({n: (merged[n].number, merged[n].rows[0]) for n in kept}, kept, diags)
    states = _states(kept, merged, children, removed, kinds, numbers, diags)
    top = [n for n in kept if not merged[n].parent]
    marked = _defaults(top, merged, source, "top-level", diags)
    _check_leaving(tables.events, kinds, diags)
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

    data_names = [name for name, _ in tables.data]
    fields = event_fields(tables.events, diags)
    assigns = _check_rows(tables, merged, data_names, fields, diags)

    rows = _merge_events(tables.events, diags)
    events = tuple(_with(e, fields=fields.get(e.name, ())) for e in _event_defs(rows, diags))
    _check_invokes(rows, diags)
    apis, invokes = derive_invokes(  # a row without an API derives nothing: not passed
        [EventSpec(r.event, r.kind, r.api, r.new, r.invoke or None) for r in rows if r.api]
    )
    by_method: dict[str, InvokeNumber] = {i.method: i for i in invokes}
    transitions = [_transition(r, assigns, by_method) for r in rows]

    event_names = [e.name for e in events]
    extras = state_extras(merged, kinds, rows, event_names, diags)
    states = [_with(s, timeout=extras[s.name][0], defer=extras[s.name][1]) for s in states]
    check_apis(merged, rows, diags)
    ignored = _ignored(kept, merged, rows, event_names, diags)

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
        profile=tables.profile,
    )
    return chart, diags


_T = TypeVar("_T", State, EventDef)


def _with(value: _T, **changes: object) -> _T:
    """``value`` with ``changes``; the very value when they change nothing (the usual
    state has no timeout and no defer, the usual event no data): a replace per row was
    a tenth of a 100,000-row build."""
    if all(getattr(value, name) == new for name, new in changes.items()):
        return value
    return dataclasses.replace(value, **changes)  # type: ignore[arg-type]  # the fields


def _states(
    kept: list[str],
    merged: dict[str, _Merged],
    children: dict[str, list[str]],
    removed: set[str],
    kinds: dict[str, StateKind],
    numbers: dict[str, int],
    diags: list[Diagnostic],
) -> list[State]:
    """One State per kept row (rules 1, 1a): a compound's initial child is found here."""
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
                number=numbers.get(name),
            )
        )
    return states


def _check_leaving(
    events: Sequence[EventRow], kinds: dict[str, StateKind], diags: list[Diagnostic]
) -> None:
    """B216: a final is its parent's end and a history only points back, so no row leaves one."""
    ends = {name: k for name, k in kinds.items() if k.is_history or k is StateKind.FINAL}
    for r in events:  # a kind asked per state, not per row
        left = ends.get(r.old)
        if left is not None:
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


def _check_rows(
    tables: DeviceTables,
    merged: dict[str, _Merged],
    data_names: list[str],
    fields: dict[str, Fields],
    diags: list[Diagnostic],
) -> dict[tuple[str, ...], tuple[Action, ...]]:
    """Check each event row's states and guard (B201, X301-X303); its assignments by row key.

    Every row is checked before the merge, so each duplicate's own location is reported.
    A guard found clean on one row is clean on every row of the same event: what it
    reports depends on its text, the event and the tables, not on the row.
    """
    state_names = list(merged)
    known = set(data_names) | GUARD_NAMES
    assigns: dict[tuple[str, ...], tuple[Action, ...]] = {}  # a row's assignments (eventdata)
    clean: set[tuple[str, str]] = set()  # (guard, event) that reported nothing
    assigning = any(r.assign for r in tables.events)  # else no row has actions to keep
    for r in tables.events:
        if r.old not in merged or r.new not in merged:
            _unknown_states(r, merged, state_names, diags)
        if r.guard and (r.guard, r.event) not in clean:
            expression, problems = _compile(r.guard, r.where)
            if expression is not None:
                problems += check_guard(expression, r, known, fields, data_names)
            diags.extend(problems)
            if expression is not None and not problems:
                clean.add((r.guard, r.event))
        if assigning:  # the first row of each merged group gives the transition's actions
            made = assign_actions(r, known, fields, data_names, diags)
            assigns.setdefault((r.event, r.old, r.new, r.guard), made)
    return assigns


def _unknown_states(
    r: EventRow, merged: dict[str, _Merged], state_names: list[str], diags: list[Diagnostic]
) -> None:
    """B201: the row's old or new state is not in the states table."""
    for column, target in (("old", r.old), ("new", r.new)):
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


def _transition(
    r: EventRow,
    assigns: dict[tuple[str, ...], tuple[Action, ...]],
    by_method: dict[str, InvokeNumber],
) -> Transition:
    """Rule 3: ``old + event [guard] = new``, notifying the API's invoke if it drives it."""
    actions: tuple[Action, ...] = (
        assigns.get((r.event, r.old, r.new, r.guard), ()) if assigns else ()
    )
    invoke = by_method.get(r.api)
    if r.kind in DRIVING_KINDS and invoke is not None:
        actions += (Notify(invoke.number, invoke.name, invoke.method, r.event),)
    return Transition(
        source=r.old,
        events=(r.event,),
        targets=(r.new,),
        guard=r.guard or None,
        condition=r.condition,
        actions=actions,
        origin=r.where,
    )


def _ignored(
    kept: list[str],
    merged: dict[str, _Merged],
    rows: Sequence[EventRow],
    event_names: list[str],
    diags: list[Diagnostic],
) -> set[tuple[str, str]]:
    """The (state, event) pairs each ignore cell names; an unknown event is B208."""
    declared = set(event_names)
    ignored: set[tuple[str, str]] = set()
    for name in kept:
        m = merged[name]
        for event in expand_ignore(name, merged, rows, event_names):
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
    return ignored


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
