"""Data the explorer tracks through a device's assignments, and the bound on it.

Rules:
1. A data item with a literal value is tracked: the runtime's guards over it are
   evaluated, not chosen. An item changed by an event row's ``assign`` is part of
   the device's local state, so ``indexed < limit`` is explored as the runtime
   takes it: true three times, then false.
2. An assignment that reads the event's data (``_event``), or data that is not
   tracked, makes its target untracked (a fixpoint over every assignment): a guard
   over it is then a *free choice*, both outcomes explored, the same abstraction as
   for guards over ``_event``. The explorer stays sound: every run the runtime can
   take with some event data is among the explored ones.
3. Tracked data must stay bounded: a device whose local states pass
   :data:`MAX_LOCAL_STATES` while some assignment keeps producing new values (a
   counter with no guard that stops it) is C412, naming the assignments, instead of
   an exploration that never ends.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping, Sequence
from typing import Any

from statectl.kernel.errors import Diagnostic, DiagnosticError, Severity
from statectl.kernel.expr import Expression, compile_expression
from statectl.kernel.model import Assign, Chart
from statectl.kernel.semantics import Step
from statectl.kernel.semantics.eventview import EventView

__all__ = ["MAX_LOCAL_STATES", "DataTracker"]

#: Most local states (snapshot x tracked values) one device may have (C412 beyond).
MAX_LOCAL_STATES = 20_000


def _names(source: str) -> set[str]:
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except SyntaxError:
        return set()
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}


class DataTracker:
    """Which data a device's local state carries, and how a step changes it."""

    def __init__(self, chart: Chart, initial: Mapping[str, Any]) -> None:
        self.chart = chart
        self.assigns: list[Assign] = [
            a for t in chart.transitions for a in t.actions if isinstance(a, Assign)
        ]
        known = {k for k, v in initial.items() if v is not None}
        untracked = set(initial) - known
        changed = True
        while changed:  # rule 2: a fixpoint
            changed = False
            for a in self.assigns:
                reads = _names(a.expr or "")
                if a.location in untracked:
                    continue
                if "_event" in reads or reads & untracked or a.expr is None:
                    untracked.add(a.location)
                    changed = True
        self.untracked = frozenset(untracked)
        self.dynamic: tuple[str, ...] = tuple(
            sorted(({a.location for a in self.assigns} - untracked) & set(initial))
        )
        self.initial: tuple[Any, ...] = tuple(initial.get(n) for n in self.dynamic)
        self._exprs: dict[str, Expression] = {}

    def values(self, base: Mapping[str, Any], valuation: Sequence[Any]) -> dict[str, Any]:
        """The data a step is taken over: ``base`` with the tracked values of a local state."""
        data = dict(base)
        data.update(zip(self.dynamic, valuation, strict=True))
        return data

    def _expr(self, a: Assign) -> Expression | None:
        source = a.expr or ""
        found = self._exprs.get(source)
        if found is None:
            found, _ = compile_expression(source, a.origin, what="assign")
            if found is None:
                return None
            self._exprs[source] = found
        return found

    def after(self, result: Step, data: Mapping[str, Any]) -> tuple[Any, ...]:
        """The tracked values after ``result``'s assignments (all read the values before)."""
        if not self.dynamic:
            return ()
        new = dict(zip(self.dynamic, (data[n] for n in self.dynamic), strict=True))
        env: dict[str, Any] = dict(data)
        env["previous"] = result.source.previous
        env["In"] = result.source.active.__contains__
        env["_event"] = EventView(result.event, None)
        for a in result.actions:
            if not isinstance(a, Assign) or a.location not in new:
                continue
            expr = self._expr(a)
            if expr is None:
                continue
            try:
                new[a.location] = expr.evaluate(env)
            except Exception:  # the runtime refuses such a step (AssignError): no change
                return tuple(data[n] for n in self.dynamic)
        return tuple(new[n] for n in self.dynamic)

    def unbounded(self, device: str, states: int) -> DiagnosticError:
        """C412: the local states passed the bound while tracked data kept changing."""
        growing = [a for a in self.assigns if a.location in self.dynamic]
        where = growing[0].origin if growing else self.chart.origin
        shown = "; ".join(f"{a.location} = {a.expr}" for a in growing[:3])
        return DiagnosticError(
            [
                Diagnostic(
                    "C412",
                    Severity.ERROR,
                    where,
                    f"device {device!r}: its data does not stay bounded: more than "
                    f"{states:,} local states as the assignments ({shown}) keep producing "
                    "new values",
                    "bound the data with a guard on the rows that assign it "
                    "(e.g. indexed < limit), so verify can explore every value",
                )
            ]
        )
