"""The guard parts of the ``pairs`` criterion: history, MC/DC and boundary values.

Rules (the conditions and their inputs are :mod:`~statectl.out.testgen.conditions`'):
1. A *context* of a guarded row is an explored edge that sends one of its events
   where its source is active: the path gives ``previous`` and the start data the
   datamodel, the edge the event's data. Shortest paths come first.
2. History: a guard that reads ``previous`` is tested at every value of
   ``previous`` a context has (each previous state the row can meet), one case each,
   with a context where the conditions over ``previous`` decide the outcome if any.
3. MC/DC: for each condition of a guard, two contexts in which it decides the
   outcome (masking MC/DC), with the condition true in one and false in the
   other, and the guard's outcomes differing: the pair shows it matters on its own.
   A condition no pair shows is a note in the module docstring.
4. Boundaries: for each comparison over numbers, a context at distance -1, 0 and
   +1 (left side minus right side), one where the comparison decides if any; a
   ``<`` written ``<=``, or a limit off by one, fails one of them.
5. A case already in the suite (same data, path, event and event data) is not
   added again; the module docstring counts what each part adds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from statectl.kernel.model import Transition
from statectl.kernel.semantics import Run, compiled, guard_env
from statectl.out.escape.python import identifier
from statectl.out.testgen.conditions import Condition, Guard, analyse, decides, distance, value_of
from statectl.out.testgen.paths import Edge, Graph, default_data

__all__ = ["GUARD_PARTS", "Context", "guard_parts"]

#: The parts in the order they are added, as the module docstring names them.
GUARD_PARTS = ("guards over previous", "MC/DC", "boundaries")
#: Bound on the contexts looked at per row (rule 1): the shortest come first, so a
#: big chart's row is tested in the contexts nearest the start.
MAX_CONTEXTS = 400

#: makes a case of an edge: (base name, docstring, edge) -> whether it was added
#: (False: the suite has that case already, rule 5)
AddCase = Callable[[str, str, Edge], bool]


@dataclass(frozen=True, slots=True)
class Context:
    edge: Edge
    env: dict[str, Any]
    outcome: bool


def _contexts(g: Graph, t: Transition, by_event: dict[str, list[int]]) -> list[Context]:
    """The row's contexts in breadth-first order (rule 1), each with the guard's outcome."""
    m = compiled(g.chart)
    guard = m.guards.get(t.guard or "")
    if guard is None or not t.events:
        return []
    out = []
    for k in sorted(k for event in t.events for k in by_event.get(event, ())):
        e = g.edges[k]
        if t.source not in e.source.snapshot.active:
            continue
        run = Run(
            set(e.source.snapshot.active),
            dict(e.source.snapshot.history),
            e.source.snapshot.previous,
            dict(g.datas[e.source.data]),
        )
        run.event = e.event
        env = guard_env(run, e.data)
        outcome = value_of(guard, env)
        if outcome is None and not isinstance(outcome, bool):
            continue
        out.append(Context(e, env, bool(outcome)))
        if len(out) >= MAX_CONTEXTS:
            break
    return out


def _slug(text: str) -> str:
    return identifier(text)


def _history(
    i: int, t: Transition, info: Guard, ctx: list[Context], add: AddCase, head: str
) -> int:
    """Rule 2: one case per value of ``previous`` the row meets."""
    over = [c for c in info.conditions if ("previous", "") in c.inputs]
    best: dict[Any, Context] = {}
    for c in ctx:
        prev = c.edge.source.snapshot.previous
        old = best.get(prev)
        deciding = any(decides(k, c.env) for k in over)
        if old is None or (deciding and not any(decides(k, old.env) for k in over)):
            best[prev] = c
    added = 0
    for prev, c in best.items():
        shown = "none (nothing left yet)" if prev is None else repr(prev)
        doc = (
            f"{head}; its guard {t.guard!r} with previous = {shown} (each previous state "
            f"the row meets): {'true' if c.outcome else 'false'}."
        )
        base = f"test_guard_row_{i:02d}_{_slug(c.edge.event)}_previous_{_slug(str(prev))}"
        added += add(base, doc, c.edge)
    return added


def _pair(cond: Condition, ctx: list[Context]) -> tuple[Context, Context] | None:
    """Two contexts showing ``cond`` matters on its own (rule 3), shortest first."""
    deciding = []
    for c in ctx:
        value = value_of(cond.own, c.env)
        if value is None and not isinstance(value, bool):
            continue
        if decides(cond, c.env):
            deciding.append((c, bool(value)))
    for a, va in deciding:
        for b, vb in deciding:
            if va and not vb and a.outcome != b.outcome:
                return a, b
    return None


def _mcdc(
    i: int,
    t: Transition,
    info: Guard,
    ctx: list[Context],
    add: AddCase,
    head: str,
    notes: list[str],
    place: str,
) -> int:
    added = 0
    for k, cond in enumerate(info.conditions, 1):
        found = _pair(cond, ctx)
        if found is None:
            notes.append(
                f"row {i} ({place}): no candidate values show that {cond.text!r} of its guard "
                f"{t.guard!r} matters on its own (MC/DC)"
            )
            continue
        for c, value in zip(found, ("true", "false"), strict=True):
            doc = (
                f"{head}; {cond.text!r} decides its guard {t.guard!r} here on its own "
                f"(MC/DC, condition {k}): it is {value}, the guard "
                f"{'true' if c.outcome else 'false'}."
            )
            added += add(f"test_mcdc_row_{i:02d}_condition_{k}_{value}", doc, c.edge)
    return added


def _boundaries(
    i: int, t: Transition, info: Guard, ctx: list[Context], add: AddCase, head: str
) -> int:
    added = 0
    for k, cond in enumerate(info.conditions, 1):
        if cond.sides is None:
            continue
        for d, word in ((-1.0, "below"), (0.0, "at"), (1.0, "above")):
            at = [c for c in ctx if distance(cond, c.env) == d]
            if not at:
                continue
            c = next((c for c in at if decides(cond, c.env)), at[0])
            doc = (
                f"{head}; {cond.text!r} of its guard {t.guard!r} at its boundary "
                f"{'+' if d > 0 else ''}{d:g} (left minus right): the guard "
                f"{'true' if c.outcome else 'false'}."
            )
            added += add(f"test_boundary_row_{i:02d}_condition_{k}_{word}", doc, c.edge)
    return added


def guard_parts(
    g: Graph, add: AddCase, words: Callable[[int, Transition], tuple[str, str]]
) -> tuple[list[tuple[str, int]], list[str]]:
    """Add the cases of rules 2-4 through ``add``; how many each part added, and notes.

    ``words(i, t)`` gives a row's docstring head and where it is (file:line)."""
    names = frozenset(k for k, _ in default_data(g.chart))
    notes: list[str] = []
    counts = dict.fromkeys(GUARD_PARTS, 0)
    rows: list[tuple[int, Transition, Guard, list[Context], str, str]] = []
    by_event: dict[str, list[int]] = {}
    for k, e in enumerate(g.edges):
        by_event.setdefault(e.event, []).append(k)
    for i, t in enumerate(g.chart.transitions, 1):
        if not t.guard:
            continue
        info = analyse(t.guard, names)
        if info is None:
            continue
        ctx = _contexts(g, t, by_event)
        if ctx:
            head, place = words(i, t)
            rows.append((i, t, info, ctx, head, place))
    for i, t, info, ctx, head, _ in rows:
        if info.reads_previous:
            counts["guards over previous"] += _history(i, t, info, ctx, add, head)
    for i, t, info, ctx, head, place in rows:
        counts["MC/DC"] += _mcdc(i, t, info, ctx, add, head, notes, place)
    for i, t, info, ctx, head, _ in rows:
        counts["boundaries"] += _boundaries(i, t, info, ctx, add, head)
    return list(counts.items()), notes
