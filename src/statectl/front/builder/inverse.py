"""The inverse of step 2: a chart back to device tables (:func:`chart_to_tables`), or
info diagnostics (B220-B223) saying why it stays SCXML. Its own module: it reads a
Chart and writes tables, the other direction from the rest of :mod:`statectl.front.builder.build`.
"""

from __future__ import annotations

import ast
import dataclasses
import math

from statectl.front.builder.chart import build, strip_origins
from statectl.front.builder.common import GUARD_NAMES, _compile, _literal
from statectl.front.observers import EventSpec, derive_invokes
from statectl.front.tables import DeviceTables
from statectl.front.tables.literals import normalize_value
from statectl.front.tables.rows import Bad, EventRow, StateRow
from statectl.front.tables.schema import validate_for_writing
from statectl.front.tables.timeouts import format_timeout
from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.expr import check_names
from statectl.kernel.model import (
    Assign,
    Chart,
    ControlKind,
    DataItem,
    EventKind,
    Notify,
    State,
    StateKind,
    Transition,
)

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
    return [*_document_misfits(chart), *_state_misfits(chart), *_transition_misfits(chart)]


#: What each misfit's hint opens with: the chart is fine as SCXML, just not as tables.
_KEEP = "keep it as SCXML"


def _document_misfits(chart: Chart) -> list[Diagnostic]:
    """B220 for what the whole document holds beyond tables: datamodel, script, initial, data."""
    out: list[Diagnostic] = []
    if chart.datamodel not in ("safe", "null"):
        out.append(
            _info(
                "B220",
                chart.origin,
                f"datamodel {chart.datamodel!r}: device tables use the safe expression language",
                _KEEP + "; datamodel='python' is explicit trust, which tables never grant",
            )
        )
    if chart.script:
        out.append(_info("B220", chart.origin, "the document has a top-level <script>", _KEEP))
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
    return out


def _state_misfits(chart: Chart) -> list[Diagnostic]:
    """B220 for states tables cannot say: executable content, a compound's odd initial."""
    out: list[Diagnostic] = []
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
                    _KEEP + "; tables hold states, transitions and their notifications only",
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
    return out


def _transition_misfits(chart: Chart) -> list[Diagnostic]:
    """B220-B222 for transitions that are not one event row: shape, content, guard."""
    out: list[Diagnostic] = []
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
        elif any(not _table_action(a) for a in t.actions):
            out.append(
                _info(
                    "B220",
                    t.origin,
                    f"the transition from {t.source!r} has executable content",
                    _KEEP + "; an event row can only notify its API's observer",
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
                        _KEEP + "; table guards are safe expressions over the data names",
                    )
                )
    return out


def _table_action(a: object) -> bool:
    """An action an event row holds: its notification, or an assignment (``assign``)."""
    return isinstance(a, Notify) or (isinstance(a, Assign) and a.expr is not None)


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
    top = [s.name for s in chart.states if s.parent is None]
    states, expected_states = _state_rows(chart, _marked_default(chart, top))
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
    first_row: dict[str, Transition] = {}  # an event's data is declared on its first row
    for t in chart.transitions:
        first_row.setdefault(t.events[0], t)
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
            fields=declared[t.events[0]].fields
            if t.events[0] in declared and first_row.get(t.events[0]) is t
            else (),
            assign=tuple((a.location, a.expr or "") for a in t.actions if isinstance(a, Assign)),
            unasked=t.events[0] in declared and declared[t.events[0]].unasked,
            severity=declared[t.events[0]].severity if t.events[0] in declared else None,
        )
        for t, spec in zip(chart.transitions, specs, strict=True)
    )
    data = tuple((d.name, _data_value(d.expr)[1]) for d in chart.data)
    tables = DeviceTables(
        chart.name, tuple(states), events, data, chart.origin, profile=chart.profile
    )
    expected = dataclasses.replace(
        chart,
        states=tuple(expected_states),
        initial=(chart.initial[0] if chart.initial else top[0],),
        datamodel="safe",
        data=tuple(DataItem(n, _literal(v), chart.origin) for n, v in data),
    )
    return tables, expected


def _marked_default(chart: Chart, top: list[str]) -> set[str]:
    """The states whose row says ``default``: the initial, and each compound's initial child
    unless build would pick it anyway (its first non-history child, none marked)."""
    by_name = {s.name: s for s in chart.states}
    defaults: set[str] = {chart.initial[0] if chart.initial else top[0]}
    for s in chart.states:
        if s.kind is StateKind.COMPOUND:
            kids = [c.name for c in chart.states if c.parent == s.name and not c.kind.is_history]
            marked = [k for k in kids if ControlKind.DEFAULT in by_name[k].controls]
            if s.initial[0] not in marked and (marked or kids[:1] != [s.initial[0]]):
                defaults.add(s.initial[0])
    return defaults


def _state_rows(chart: Chart, defaults: set[str]) -> tuple[list[StateRow], list[State]]:
    """One state row per state, and the state as build will make it (with its defaults)."""
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
                number="" if s.number is None else str(s.number),
                timeout=format_timeout(s.timeout.seconds, s.timeout.event) if s.timeout else "",
                defer=s.defer,
            )
        )
        expected_states.append(dataclasses.replace(s, controls=frozenset(controls)))
    return states, expected_states


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
