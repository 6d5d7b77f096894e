"""The safe expression language of device tables.

A model file from someone else must never run code on the controller, so guards
are a checked subset of Python expressions. Rules:

1. Allowed: names, literals (numbers, strings, booleans, ``None``, tuples,
   lists, sets, dicts), comparisons (including ``in`` and ``is``), ``and`` /
   ``or`` / ``not``, arithmetic (``+ - * / // %``, unary ``-`` and ``+``),
   conditional expressions, indexing, and attribute reads of public names.
2. Calls are allowed only to the whitelisted functions in :data:`FUNCTIONS`
   and :func:`In`; nothing else is callable, so no method of any object is.
3. Names starting with ``_`` are refused (``_event`` is the one exception, the
   SCXML system variable), as are lambdas, comprehensions, walrus, ``**``,
   f-strings and starred arguments.
4. The check happens when the model loads and reports every offending node as
   a diagnostic with its column; evaluation then runs the compiled code with no
   builtins at all.
"""

from __future__ import annotations

import ast
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from types import CodeType
from typing import Any

from statectl.errors import Diagnostic, Location, Severity

__all__ = ["FUNCTIONS", "Expression", "check_names", "compile_expression"]

#: Functions a guard may call, besides ``In(state)`` which the runtime supplies.
FUNCTIONS: Mapping[str, Callable[..., Any]] = {
    "abs": abs,
    "min": min,
    "max": max,
    "len": len,
    "round": round,
    "int": int,
    "float": float,
    "str": str,
    "bool": bool,
}
CALLABLE_NAMES = frozenset(FUNCTIONS) | {"In"}
ALLOWED_PRIVATE = frozenset({"_event"})

_ALLOWED_NODES: tuple[type[ast.AST], ...] = (
    ast.Expression,
    ast.BoolOp,
    ast.And,
    ast.Or,
    ast.UnaryOp,
    ast.Not,
    ast.USub,
    ast.UAdd,
    ast.BinOp,
    ast.Add,
    ast.Sub,
    ast.Mult,
    ast.Div,
    ast.FloorDiv,
    ast.Mod,
    ast.Compare,
    ast.Eq,
    ast.NotEq,
    ast.Lt,
    ast.LtE,
    ast.Gt,
    ast.GtE,
    ast.In,
    ast.NotIn,
    ast.Is,
    ast.IsNot,
    ast.IfExp,
    ast.Name,
    ast.Load,
    ast.Constant,
    ast.Tuple,
    ast.List,
    ast.Set,
    ast.Dict,
    ast.Subscript,
    ast.Slice,
    ast.Attribute,
    ast.Call,
)

_SAFE_GLOBALS: dict[str, Any] = {"__builtins__": {}, **FUNCTIONS}


@dataclass(frozen=True, slots=True)
class Expression:
    """A checked, compiled expression; ``names`` are the free names it reads."""

    source: str
    code: CodeType
    names: frozenset[str]

    def evaluate(self, env: Mapping[str, Any]) -> Any:
        """Evaluate with ``env`` as the only namespace (plus the whitelisted functions)."""
        return eval(self.code, _SAFE_GLOBALS, dict(env))  # checked AST, no builtins


def _describe(node: ast.AST) -> str:
    return {
        "Lambda": "lambda",
        "ListComp": "comprehension",
        "SetComp": "comprehension",
        "DictComp": "comprehension",
        "GeneratorExp": "generator expression",
        "NamedExpr": "assignment expression ':='",
        "JoinedStr": "f-string",
        "Starred": "starred argument",
        "Await": "await",
        "Yield": "yield",
    }.get(type(node).__name__, type(node).__name__)


def compile_expression(
    source: str, where: Location, *, what: str = "guard"
) -> tuple[Expression | None, list[Diagnostic]]:
    """Parse and check ``source``; return the expression or the reasons it was refused."""
    diagnostics: list[Diagnostic] = []
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except SyntaxError as exc:
        diagnostics.append(
            Diagnostic(
                "X301",
                Severity.ERROR,
                where,
                f"{what} {source!r} does not parse: {exc.msg} at column {exc.offset or 0}",
                "write a Python-style expression such as: previous == 'Moving'",
            )
        )
        return None, diagnostics

    names: set[str] = set()
    for node in ast.walk(tree):
        col = getattr(node, "col_offset", None)
        at = f" at column {col + 1}" if col is not None else ""
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            diagnostics.append(
                Diagnostic(
                    "X302",
                    Severity.ERROR,
                    where,
                    f"{what} {source!r} uses '**'{at}, which the safe language refuses",
                    "multiply explicitly; unbounded powers can stall a controller",
                )
            )
            continue
        if not isinstance(node, _ALLOWED_NODES):
            diagnostics.append(
                Diagnostic(
                    "X302",
                    Severity.ERROR,
                    where,
                    f"{what} {source!r} uses a {_describe(node)}{at}, "
                    "which the safe expression language refuses",
                    "use names, literals, comparisons, and/or/not, arithmetic and In()",
                )
            )
            continue
        if isinstance(node, ast.Name):
            if node.id.startswith("_") and node.id not in ALLOWED_PRIVATE:
                diagnostics.append(
                    Diagnostic(
                        "X302",
                        Severity.ERROR,
                        where,
                        f"{what} {source!r} reads the private name {node.id!r}{at}",
                        "names starting with '_' are not available in guards",
                    )
                )
            elif node.id not in CALLABLE_NAMES:
                names.add(node.id)
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_"):
            diagnostics.append(
                Diagnostic(
                    "X302",
                    Severity.ERROR,
                    where,
                    f"{what} {source!r} reads the private attribute {node.attr!r}{at}",
                    "only public attributes can be read in guards",
                )
            )
        elif isinstance(node, ast.Call):
            ok = isinstance(node.func, ast.Name) and node.func.id in CALLABLE_NAMES
            if not ok or node.keywords:
                callee = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
                diagnostics.append(
                    Diagnostic(
                        "X302",
                        Severity.ERROR,
                        where,
                        f"{what} {source!r} calls {callee!r}{at}, which is not allowed",
                        "callable: " + ", ".join(sorted(CALLABLE_NAMES)) + " (no keywords)",
                    )
                )
    if diagnostics:
        return None, diagnostics
    code = compile(tree, f"<{what} {where}>", "eval")
    return Expression(source.strip(), code, frozenset(names)), diagnostics


def check_names(
    expression: Expression, known: Iterable[str], where: Location, *, what: str = "guard"
) -> list[Diagnostic]:
    """Report names the expression reads that the chart does not define."""
    known_set = set(known)
    return [
        Diagnostic(
            "X303",
            Severity.ERROR,
            where,
            f"{what} {expression.source!r} reads undefined name {name!r}",
            "known names: " + (", ".join(sorted(known_set)) or "none")
            + "; declare it under 'data:' in the device file",
        )
        for name in sorted(expression.names - known_set)
    ]
