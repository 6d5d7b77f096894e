"""Global expressions (rule 4 of :mod:`statectl.cell.model`): the safe expression language
restricted to ``In('device.State')``, ``and``, ``or``, ``not``, ``True`` and ``False``,
checked against the cell's devices (V807, V808, V810, V811). Its own module because
every host of a cell (the explorer, SPIN) relies on this one check.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping

from statectl.cell.values import GlobalExpr
from statectl.kernel.errors import Diagnostic, Location, Severity, did_you_mean
from statectl.kernel.expr import compile_expression, in_target
from statectl.kernel.model import Chart


def _d(code: str, where: Location, message: str, hint: str = "") -> Diagnostic:
    return Diagnostic(code, Severity.ERROR, where, message, hint)


def parse_global(
    source: str, where: Location, charts: Mapping[str, Chart], *, what: str = "expression"
) -> tuple[GlobalExpr | None, list[Diagnostic]]:
    """Check a global expression (rule 4) against the cell's devices and their states."""
    try:
        expr, diags = compile_expression(source, where, what=what)
    except (RecursionError, MemoryError):
        shown = source if len(source) <= 40 else source[:37] + "..."
        message = f"{what} {shown!r} is nested too deeply to analyse"
        return None, [_d("V810", where, message, "write it with fewer nested parts")]
    if expr is None:
        return None, diags
    tree = ast.parse(source.strip(), mode="eval")
    refs: list[tuple[str, str]] = []
    allowed = (ast.Expression, ast.BoolOp, ast.And, ast.Or, ast.UnaryOp, ast.Not, ast.Load)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            ref = _state_ref(node, source, where, charts, what)
            if isinstance(ref, Diagnostic):
                diags.append(ref)
            else:
                refs.append(ref)
        elif isinstance(node, ast.Name):
            if node.id != "In":
                diags.append(
                    _d(
                        "V810",
                        where,
                        f"{what} {source!r} reads {node.id!r}; the cell tracks only states",
                        "use In('device.State'), and, or, not, True, False",
                    )
                )
        elif isinstance(node, ast.Constant):
            if not isinstance(node.value, (bool, str)):
                diags.append(
                    _d(
                        "V810",
                        where,
                        f"{what} {source!r} uses the constant {node.value!r}",
                        "use True or False",
                    )
                )
        elif not isinstance(node, allowed):
            diags.append(
                _d(
                    "V810",
                    where,
                    f"{what} {source!r} uses {type(node).__name__}, which a global "
                    "expression does not allow",
                    "use In('device.State'), and, or, not, True, False",
                )
            )
    if diags:
        return None, diags
    return GlobalExpr(source.strip(), tuple(dict.fromkeys(refs)), where), diags


def _state_ref(
    node: ast.Call, source: str, where: Location, charts: Mapping[str, Chart], what: str
) -> tuple[str, str] | Diagnostic:
    """The (device, state) a call names, or why it is no ``In('device.State')`` of the cell.

    The only call a global expression may make is ``In`` on one text naming a state the
    cell has (V811, V807, V808): that is all a cell's global state holds.
    """
    named = in_target(node)
    if named is None:
        return _d(
            "V811",
            where,
            f"{what} {source!r}: {ast.unparse(node)} is not In('device.State')",
            "write In('arm.Moving'): one text argument naming device and state",
        )
    device, dot, state = named.partition(".")
    chart = charts.get(device)
    if not dot or chart is None:
        return _d(
            "V807",
            where,
            f"{what} {source!r}: In({named!r}) names no device of the cell",
            "devices: " + ", ".join(sorted(charts)),
        )
    if not chart.has_state(state):
        return _d(
            "V808",
            where,
            f"{what} {source!r}: device {device!r} has no state {state!r}",
            did_you_mean(state, [s.name for s in chart.states])
            + "states: "
            + ", ".join(s.name for s in chart.states),
        )
    return device, state
