"""Which free choices a cell decides: another device's state, and the data a link sends.

Rules:
1. A device guard's ``In('axis1.Standstill')`` naming another device of the cell is
   a free choice of the device alone (:mod:`statectl.cell.explore.local`); in the cell it
   is decided by the global state before the step: an outcome that took it the
   other way is not a way the cell can go.
2. A link sends exactly its data (``None`` without any) unless it forwards the
   triggering event's data: a guard part that reads only ``_event`` and data with
   values is evaluated with that data, as the runtime evaluates it; an outcome that
   took it the other way is dropped, and a part that raises there (a field the link
   does not send) makes the delivery a guard error, as the runtime refuses it.
   Forwarded data, and data of environment commands, stay free choices (the
   outside may send anything).
3. The runtime honours rule 1 through :func:`bind_cross_guards`: a Subject of a
   cell gets its own compiled machine whose guards that name another device read
   that device's live state; every other guard is the shared one.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from statectl.cell.explore.local import LocalSpace, Reaction
from statectl.cell.options import foreign_in
from statectl.kernel.errors import Location
from statectl.kernel.expr import Expression, compile_expression
from statectl.kernel.semantics import Machine, Unhandled
from statectl.kernel.semantics.eventview import EventView

if TYPE_CHECKING:
    from statectl.run.runtime import Subject

__all__ = [
    "FOREIGN_IN",
    "UNTRACKED",
    "assumptions",
    "bind_cross_guards",
    "foreign_leaf",
    "under_link",
]

#: What a free choice over data assumes (``Delivery.assumed``; the report names it).
UNTRACKED = "a free choice over data verify does not track"

#: ``In('device.State')`` as the explorer writes a free guard part.
FOREIGN_IN = re.compile(r"^In\((['\"])([A-Za-z_][A-Za-z0-9_]*)\.(.+)\1\)$")


def foreign_leaf(leaf: str) -> tuple[str, str] | None:
    """(device, state) when a free guard part is ``In('device.State')``, else ``None``."""
    found = FOREIGN_IN.match(leaf.strip())
    return (found.group(2), found.group(3)) if found else None


_leaf_cache: dict[tuple[str, frozenset[str]], Expression | None] = {}


def _decidable(leaf: str, tracked: frozenset[str]) -> Expression | None:
    """The compiled part when it reads only ``_event`` and tracked data (rule 2)."""
    key = (leaf, tracked)
    if key not in _leaf_cache:
        expr, _ = compile_expression(leaf, Location("<guard part>"), what="guard part")
        ok = expr is not None and "_event" in expr.names and expr.names <= {"_event", *tracked}
        _leaf_cache[key] = expr if ok else None
    return _leaf_cache[key]


def under_link(space: LocalSpace, lid: int, o: Reaction, event: str, data: Any) -> Reaction | None:
    """Rule 2: ``o`` as a link sending ``data`` leaves it: ``o``, ``None`` when its free
    choices disagree with the data, or a guard error where a decided part raises (the
    runtime refuses the event; the explorer never reads that as false)."""
    values = space.valuations[lid] if lid < len(space.valuations) else ()
    known = space.tracker.values(space.data, values) if values else space.data
    tracked = frozenset(k for k, v in space.data.items() if v is not None)
    env: dict[str, Any] = {k: v for k, v in known.items() if v is not None}
    env["_event"] = EventView(event, data)
    for i, (leaf, value) in enumerate(o.choices):
        expr = _decidable(leaf, tracked)
        if expr is None:
            continue
        try:
            actual = bool(expr.evaluate(env))
        except Exception as exc:
            rows = (f"{g.guard!r} ({g.where})" for g in space.free_guards if leaf in g.parts)
            where = next(rows, "")
            return Reaction(
                lid,
                Unhandled.GUARD_ERROR,
                frozenset(),
                frozenset(),
                choices=o.choices[:i],
                failure=f"the guard {where or repr(leaf)} raised {type(exc).__name__}: {exc}",
            )
        if actual is not value:
            return None
    return o


def assumptions(space: LocalSpace, o: Reaction, data_sent: bool) -> tuple[str, ...]:
    """What outcome ``o`` assumes beyond the model: its own (a deferred release) and a free
    choice over untracked data, unless the cell decides it (another device's state, or
    the data a link sends: ``data_sent``)."""
    tracked = frozenset(k for k, v in space.data.items() if v is not None)
    free = any(
        foreign_leaf(leaf) is None and not (data_sent and _decidable(leaf, tracked) is not None)
        for leaf, _ in o.choices
    )
    return (*o.assumed, UNTRACKED) if free else o.assumed


@dataclass(frozen=True, slots=True)
class _CrossGuard(Expression):
    """A guard whose ``In('device.State')`` reads the cell's other devices (rule 3)."""

    resolve: Callable[[Callable[[str], bool]], Callable[[str], bool]] | None = None

    def evaluate(self, env: Mapping[str, Any]) -> Any:
        if self.resolve is None:
            return Expression.evaluate(self, env)
        local = dict(env)
        local["In"] = self.resolve(env["In"])
        return Expression.evaluate(self, local)


def bind_cross_guards(
    subjects: Mapping[str, Subject], read: Mapping[str, Any] | None = None
) -> list[str]:
    """Rule 3: give each Subject whose guards read another device a machine that can.

    Call before the Subjects start. Returns the names of the Subjects rebound.
    ``read`` (default ``subjects``) is where a guard looks another device up: anything
    with a ``snapshot`` (a node's stand-in for a device on another node).
    """
    seen = subjects if read is None else read

    def resolver(own: Callable[[str], bool]) -> Callable[[str], bool]:
        def is_in(name: str) -> bool:
            if own(name):
                return True
            device, dot, state = name.partition(".")
            other = seen.get(device) if dot else None
            if other is None:
                return False
            snap = other.snapshot
            return snap is not None and state in snap.active

        return is_in

    rebound: list[str] = []
    for name, s in subjects.items():
        chart = s.chart
        cross = {
            t.guard
            for t in chart.transitions
            if t.guard and any(foreign_leaf(ast.unparse(n)) for n in _in_calls(t.guard, chart))
        }
        if not cross:
            continue
        m = Machine(chart)
        for g in cross:
            old = m.guards[g]
            m.guards[g] = _CrossGuard(old.source, old.code, old.names, resolver)
        # they read more than the snapshot: never memoise a step they decide
        m.snapshot_guards = m.snapshot_guards - cross
        s.machine = m
        rebound.append(name)
    return rebound


def _in_calls(guard: str, chart: Any) -> list[ast.Call]:
    """The ``In('x.Y')`` calls of ``guard`` that name no state of ``chart`` itself."""
    try:
        tree = ast.parse(guard.strip(), mode="eval")
    except SyntaxError:
        return []
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call) and foreign_in(n, chart)]
