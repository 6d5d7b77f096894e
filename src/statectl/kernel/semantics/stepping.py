"""The pure step of a device chart: :func:`initial` and :func:`step`, memoised, and the
data a device starts with (:func:`initial_data`).

The W3C algorithm (:mod:`statectl.kernel.semantics.algorithm`) runs on a mutable
:class:`~statectl.kernel.semantics.records.Run`; these wrap it into decisions over
immutable snapshots that every host shares: a step whose guards read only the
snapshot is memoised and planned, one whose guards read data is memoised per
outcome of those guards, and a step forced through a guard oracle is never kept.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from statectl.kernel.errors import StatectlError
from statectl.kernel.expr import compile_expression
from statectl.kernel.model import Assign, Chart
from statectl.kernel.semantics.algorithm import enter_initial_states, macrostep, process_event
from statectl.kernel.semantics.eventview import EventView, GuardError, GuardFailure
from statectl.kernel.semantics.machine import Machine
from statectl.kernel.semantics.records import (
    MAX_GUARD_PATHS,
    MEMO_LIMIT,
    Consult,
    Event,
    GuardOracle,
    Microstep,
    Run,
    Snapshot,
    Step,
    Unhandled,
)

__all__ = ["initial", "initial_data", "step", "unhandled_reason"]


def initial_data(chart: Chart, given: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The chart's data items at start, in order, each evaluated over the earlier ones; a
    value in ``given`` stands for its item. The one answer for the runtime and the
    generated tests (the C++ generator reports each item's problem as a diagnostic
    instead). An item that does not compile or evaluate raises :class:`StatectlError`."""
    data = dict(given or {})
    for item in chart.data:
        if item.name in data:
            continue
        value = None
        if item.expr:
            expr, diags = compile_expression(item.expr, item.origin, what="data")
            if expr is None:
                raise StatectlError("; ".join(str(d) for d in diags))
            try:
                value = expr.evaluate(data)
            except Exception as exc:  # a value no check caught: said, not a traceback
                raise StatectlError(
                    f"{item.origin}: data item {item.name!r} = {item.expr!r} fails: {exc}"
                ) from None
        data[item.name] = value
    return data


def _snapshot(run: Run) -> Snapshot:
    return Snapshot(frozenset(run.active), tuple(sorted(run.history.items())), run.previous)


def initial(
    m: Machine, data: Mapping[str, Any] | None = None, *, oracle: GuardOracle | None = None
) -> Step:
    """Enter the chart's initial configuration and settle it (memoised when no guard ran).

    ``oracle`` forces guard outcomes (see :data:`~statectl.kernel.semantics.GuardOracle`).
    """
    cached = m._initial
    if cached is not None and oracle is None:
        return cached
    run = Run(set(), {}, None, data or {}, oracle=oracle)
    steps = [enter_initial_states(m, run)]
    macrostep(m, run, steps)
    if run.failures:
        failure: GuardFailure = run.failures[0]
        raise GuardError(failure.message(m.chart.name))
    empty = Snapshot(frozenset())
    target = m.intern(_snapshot(run))
    result = Step(None, empty, target, tuple(steps), True, False, run.final, run.guarded)
    if not run.guarded and oracle is None:
        m._initial = result
    return result


def unhandled_reason(m: Machine, snapshot: Snapshot, event: str) -> Unhandled:
    """Why ``event`` changed nothing in ``snapshot`` (a step that took no transition)."""
    active = snapshot.active
    if any((s, event) in m.ignored for s in active):
        return Unhandled.DECLARED_IGNORED
    if any(m.candidates(s, event) for s in active if m.is_atomic(s)):
        return Unhandled.GUARD_FALSE
    return Unhandled.NO_TRANSITION


def _assigns(result: Step) -> bool:
    """Whether the step changes data: the host must perform it in full, never as a plan."""
    return any(type(a) is Assign for a in result.actions)


def _replay(
    m: Machine,
    paths: list[tuple[tuple[Consult, ...], Step]],
    data: Mapping[str, Any] | None,
    event_data: Any,
) -> Step | None:
    """The memoised step whose guards over data answer now as they did then, if any."""
    base = data or {}
    for consults, result in paths:
        for c in consults:
            env: dict[str, Any] = dict(base)
            env["previous"] = c.previous
            env["In"] = c.active.__contains__
            env["_event"] = EventView(c.event, event_data if c.external else c.data)
            try:
                value = bool(m.guards[c.guard].evaluate(env))
            except Exception:  # a failing guard: take the full path, which reports it
                break
            if value is not c.value:
                break
        else:
            return result
    return None


def step(
    m: Machine,
    snapshot: Snapshot,
    event: str,
    data: Mapping[str, Any] | None = None,
    event_data: Any = None,
    *,
    oracle: GuardOracle | None = None,
) -> Step:
    """Process one external event to completion; return what happened, perform nothing.

    A step whose guards read only the snapshot is memoised (and kept as a plan); one
    whose guards read data is memoised per outcome of those guards, which are
    re-evaluated in order on the next call instead of rebuilding the step. With
    ``oracle`` the guards it answers are forced and nothing is memoised.
    """
    key = (snapshot, event)
    if oracle is None:
        hit = m._by_id.get(id(snapshot))
        if hit is not None and hit[0] is snapshot:
            plan = hit[1].get(event)
            if plan is not None:
                return plan.step
        cached = m._memo.get(key)
        if cached is not None:
            return cached
        paths = m._guarded.get(key)
        if paths is not None:
            found = _replay(m, paths, data, event_data)
            if found is not None:
                return found
    run = Run(
        set(snapshot.active),
        dict(snapshot.history),
        snapshot.previous,
        data or {},
        oracle=oracle,
        consulted=[] if oracle is None else None,
    )
    steps: list[Microstep] = []
    first = process_event(m, run, Event(event, event_data, "external"))
    handled = first is not None
    reason = None
    if first is not None:
        steps.append(first)
        macrostep(m, run, steps)
    else:
        reason = unhandled_reason(m, snapshot, event)
    if run.failures:  # a guard raised: nothing is taken, nothing memoised (eventview rule 3)
        return _guard_failed(event, snapshot, run.failures[0])
    result = Step(
        event,
        snapshot,
        m.intern(_snapshot(run)) if handled else snapshot,
        tuple(steps),
        handled,
        reason is Unhandled.DECLARED_IGNORED,
        run.final,
        run.guarded,
        reason,
    )
    if oracle is None:
        _remember(m, snapshot, event, run, result)
    return result


def _guard_failed(event: str, snapshot: Snapshot, failure: Any) -> Step:
    """The step when a guard raised: nothing taken, the first ``failure`` reported."""
    return Step(
        event,
        snapshot,
        snapshot,
        (),
        False,
        False,
        False,
        True,
        Unhandled.GUARD_ERROR,
        failure,
    )


def _remember(m: Machine, snapshot: Snapshot, event: str, run: Run, result: Step) -> None:
    """Memoise a fresh step so the next same event costs a lookup: outright when no
    guard read data (and as a plan when it assigns nothing), else per guard outcome."""
    key = (snapshot, event)
    if not run.guarded:
        if len(m._memo) < MEMO_LIMIT:
            m._memo[key] = result
            if event in m.event_names and not _assigns(result):
                m._install(snapshot, event, result)
    elif run.consulted is not None and len(m._guarded) < MEMO_LIMIT:
        paths = m._guarded.setdefault(key, [])
        if len(paths) < MAX_GUARD_PATHS:
            paths.append((tuple(run.consulted), result))
