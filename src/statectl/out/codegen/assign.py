"""Data assignments (the Event Definition table's ``assign``) in generated C++.

Rules:
1. A transition's :class:`~statectl.kernel.model.Assign` actions become one ASSIGN
   effect, first in its microstep's effects as the Python runtime applies the
   data before it performs the step: every new value is computed over the
   context as it was, then all are stored, so ``a = b; b = a`` swaps as it does
   in Python.
2. The target must be an integer context field and the expression must translate
   as a runtime guard does (integer fields, ``+ - *``, comparisons, ``and/or/not``,
   ``a if c else b``); reading ``_event``, ``previous`` or ``In()``, or anything
   else, is G713: refused with the row, never dropped.
"""

from __future__ import annotations

import ast
from collections.abc import Sequence

from statectl.kernel.errors import Diagnostic, Severity
from statectl.kernel.model import Assign
from statectl.out.codegen.flat import Assignments
from statectl.out.codegen.translate import _Translator, _Untranslatable

__all__ = ["AssignTable"]


class AssignTable:
    """The groups of assignments a chart's steps perform, numbered in first-use order."""

    def __init__(self, fields: dict[str, str], diags: list[Diagnostic]) -> None:
        self.fields = fields
        self.diags = diags
        self.groups: list[Assignments] = []
        self.ids: dict[tuple[tuple[str, str | None], ...], int] = {}
        self.reported: set[tuple[str, str | None]] = set()

    def group(self, assigns: Sequence[Assign]) -> int:
        """The group number of these assignments (translated, or G713 reported)."""
        key = tuple((a.location, a.expr) for a in assigns)
        found = self.ids.get(key)
        if found is not None:
            return found
        stores = tuple(self._store(a) for a in assigns)
        found = self.ids[key] = len(self.groups)
        source = "; ".join(f"{a.location} = {a.expr}" for a in assigns)
        self.groups.append(Assignments(found, source, stores))
        return found

    def _store(self, a: Assign) -> tuple[str, str]:
        target = self.fields.get(a.location)
        if target is None:
            self._refuse(a, f"assigns {a.location!r}, which is not an integer context field")
            return ("", "V(0)")
        try:
            tree = ast.parse((a.expr or "").strip(), mode="eval").body
        except SyntaxError:
            self._refuse(a, "does not parse")
            return (target, "V(0)")
        names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
        if names & {"_event", "previous", "In"}:
            self._refuse(
                a, "reads _event, previous or In(), which generated code does not keep as data"
            )
            return (target, "V(0)")
        try:
            return (target, _Translator(self.fields, {}).cpp(tree))
        except _Untranslatable as exc:
            self._refuse(a, f"does not translate to C++: {exc}")
            return (target, "V(0)")

    def _refuse(self, a: Assign, why: str) -> None:
        if (a.location, a.expr) in self.reported:
            return
        self.reported.add((a.location, a.expr))
        self.diags.append(
            Diagnostic(
                "G713",
                Severity.ERROR,
                a.origin,
                f"assignment {a.location} = {a.expr} {why}",
                "generated code keeps integer data: assign integer fields from integer "
                "fields and literals with + - *, comparisons, and/or/not, a if c else b",
            )
        )
