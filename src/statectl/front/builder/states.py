"""Step 2 for the State Definition table: rows merged per state (B205, T109), the
hierarchy ordered and checked (B209, B210, B218), defaults at one level (B203), removals
(B207), each state's kind (B212-B215) and history defaults (B212, B217). Split from
:mod:`statectl.front.builder.chart` because the hierarchy is its own set of rules.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from statectl.front.builder.common import MAX_STATE_DEPTH, _d, _hint, _rows_text, _unique
from statectl.front.tables.rows import EventRow, StateRow
from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.model import (
    ControlKind,
    StateKind,
)


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
    number: str = ""  # the state number's text, checked by statectl.front.builder.numbers
    timeout: str = ""
    defer: tuple[str, ...] = ()


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
                ("number", _unique([r.number for r in group])),
                ("timeout", _unique([r.timeout for r in group])),
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
        if len(group) == 1:  # the usual state: one row, nothing to merge
            merged[name] = _one_row(first)
            continue
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
            number=next((r.number for r in group if r.number), ""),
            timeout=next((r.timeout for r in group if r.timeout), ""),
            defer=tuple(_unique([d for r in group for d in r.defer])),
        )
    return merged


def _one_row(r: StateRow) -> _Merged:
    """A state of one row as :func:`_merge_states` merges a group of one, without the
    group's walks (each ``next(...)`` over one row is that row's cell)."""
    return _Merged(
        name=r.state,
        component=r.component,
        api=r.api,
        controls=tuple(dict.fromkeys(r.controls)),
        description=r.description,
        ignore=tuple(_unique(r.ignore)),
        parent=r.parent,
        rows=(r.where,),
        type=r.type,
        default=r.default,
        number=r.number,
        timeout=r.timeout,
        defer=tuple(_unique(r.defer)),
    )


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
