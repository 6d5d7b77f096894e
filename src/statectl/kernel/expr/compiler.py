"""Rules 1-4 of :mod:`statectl.kernel.expr`: parse, check and compile an expression once, at load.

The checker walks the tree and reports every refused node as a diagnostic
(X301-X305); the bound rewriter routes costly operators through
:mod:`statectl.kernel.expr.bounds`; the result is an :class:`Expression` that runs
with no builtins at all."""

from __future__ import annotations

import ast
import functools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from types import CodeType
from typing import Any, ClassVar

from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.expr.bounds import (
    FUNCTIONS,
    MAX_DEPTH,
    MAX_INT_BITS,
    MAX_SOURCE,
    ExpressionRefused,
    _op_add,
    _op_attr,
    _op_display,
    _op_mod,
    _op_mul,
)

CALLABLE_NAMES = frozenset(FUNCTIONS) | {"In"}


ALLOWED_PRIVATE = frozenset({"_event"})

#: Attributes that lead from a value to the interpreter's frames and code: a frame's
#: globals hold its builtins, so they are refused at load like dunders (X302), whatever
#: object they are read from. ``co_`` (code objects) is refused as a prefix.
INTERNAL_ATTRIBUTES = frozenset(
    {
        *("f_back", "f_builtins", "f_code", "f_generator", "f_globals", "f_lasti"),
        *("f_lineno", "f_locals", "f_trace", "f_trace_lines", "f_trace_opcodes"),
        *("tb_frame", "tb_lasti", "tb_lineno", "tb_next"),
        *("gi_code", "gi_frame", "gi_running", "gi_suspended", "gi_yieldfrom"),
        *("cr_await", "cr_code", "cr_frame", "cr_origin", "cr_running", "cr_suspended"),
        *("ag_await", "ag_code", "ag_frame", "ag_running", "ag_suspended"),
    }
)


def in_target(node: ast.AST) -> str | None:
    """The state an ``In('name')`` call names (one text literal); ``None`` for any other node.

    Whoever reads a guard's ``In`` calls (a cell's cross-device references, the explorer)
    recognises them here, so they all agree on what counts as one.
    """
    if (
        isinstance(node, ast.Call)
        and isinstance(node.func, ast.Name)
        and node.func.id == "In"
        and len(node.args) == 1
        and isinstance(node.args[0], ast.Constant)
        and isinstance(node.args[0].value, str)
    ):
        return node.args[0].value
    return None


def internal_attribute(name: str) -> bool:
    """Whether an attribute read would reach the interpreter's internals (private or frame)."""
    return name.startswith(("_", "co_")) or name in INTERNAL_ATTRIBUTES


_SAFE_GLOBALS: dict[str, Any] = {
    "__builtins__": {},
    "<*>": _op_mul,
    "<+>": _op_add,
    "<%>": _op_mod,
    "<.>": _op_attr,
    "<display>": _op_display,
    **{f"<{name}>": f for name, f in FUNCTIONS.items()},
}


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


#: Helper names the bounded code calls; they win over any variable of the same name.
_HELPERS: dict[str, Any] = {k: v for k, v in _SAFE_GLOBALS.items() if k != "__builtins__"}


@dataclass(frozen=True, slots=True)
class Expression:
    """A checked, compiled expression; ``names`` are the free names it reads."""

    source: str
    code: CodeType
    names: frozenset[str]

    def evaluate(self, env: Mapping[str, Any]) -> Any:
        """Evaluate with ``env`` as the only namespace (plus the bounded functions).

        Raises :class:`ExpressionRefused` when an operation would exceed a bound.
        """
        # The helpers' names ('<len>', '<*>') are no identifier: no variable can shadow them.
        return eval(self.code, _SAFE_GLOBALS, dict(env))  # checked, bounded AST, no builtins


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


def _call(helper: str, node: ast.AST, *args: ast.expr) -> ast.expr:
    func = ast.copy_location(ast.Name(helper, ast.Load()), node)
    return ast.copy_location(ast.Call(func, list(args), []), node)


class _Bound(ast.NodeTransformer):
    """Route every operation with non-linear cost, and every attribute read, via a guard.

    On the way it marks the parts built from literals only (``literal``, by node
    id) and notes whether any of them calls a guard (``foldable``).
    """

    _OPS: ClassVar[dict[type[ast.operator], str]] = {
        ast.Mult: "<*>",
        ast.Add: "<+>",
        ast.Mod: "<%>",
    }

    def __init__(self) -> None:
        self.literal: set[int] = set()
        self.foldable = False
        self.big: list[ast.Constant] = []

    def _is_literal(self, node: ast.AST) -> bool:
        return isinstance(node, ast.Constant) or id(node) in self.literal

    def visit(self, node: ast.AST) -> Any:
        new = super().visit(node)
        if isinstance(new, ast.Constant):
            if isinstance(new.value, int) and new.value.bit_length() > MAX_INT_BITS:
                self.big.append(new)
        elif isinstance(new, ast.Call):
            func = new.func
            helper = isinstance(func, ast.Name) and func.id in _HELPERS
            if helper and all(self._is_literal(a) for a in new.args):
                self.literal.add(id(new))
                self.foldable = True
        elif isinstance(new, ast.expr) and not isinstance(new, ast.Name):
            children = [c for c in ast.iter_child_nodes(new) if isinstance(c, ast.expr)]
            if all(self._is_literal(c) for c in children):
                self.literal.add(id(new))
        return new

    def visit_BinOp(self, node: ast.BinOp) -> ast.expr:
        self.generic_visit(node)
        helper = self._OPS.get(type(node.op))
        return node if helper is None else _call(helper, node, node.left, node.right)

    def visit_Attribute(self, node: ast.Attribute) -> ast.expr:
        self.generic_visit(node)
        name = ast.copy_location(ast.Constant(node.attr), node)
        return _call("<.>", node, node.value, name)

    def visit_Call(self, node: ast.Call) -> ast.expr:
        self.generic_visit(node)
        if isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS:
            node.func = ast.copy_location(ast.Name(f"<{node.func.id}>", ast.Load()), node.func)
        return node

    def _display(self, node: ast.expr) -> ast.expr:
        self.generic_visit(node)
        parts = [c for c in ast.iter_child_nodes(node) if isinstance(c, ast.expr)]
        if isinstance(node, ast.Dict) and None in node.keys:
            parts.append(node)  # '**' unpacking: not all literal
        if all(isinstance(p, ast.Constant) for p in parts):
            return node
        if all(self._is_literal(p) for p in parts):
            self.literal.add(id(node))
        return _call("<display>", node, node)

    visit_List = visit_Tuple = visit_Set = visit_Dict = _display


def _fold(tree: ast.AST, bound: _Bound) -> list[tuple[ast.AST, str]]:
    """Evaluate each largest literal-only part once: the bounds it breaks, found at load."""
    problems: list[tuple[ast.AST, str]] = [
        (c, f"integer literal of more than {MAX_INT_BITS} bits") for c in bound.big
    ]
    if not bound.foldable:
        return problems
    stack: list[ast.AST] = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.expr) and id(node) in bound.literal:
            try:
                code = compile(ast.Expression(node), "<literal part>", "eval")
                eval(code, _SAFE_GLOBALS, {})  # bounded helpers, literals only
            except ExpressionRefused as exc:
                problems.append((node, str(exc)))
            except Exception:  # other failures surface when it is evaluated
                pass
            continue
        stack.extend(ast.iter_child_nodes(node))
    return problems


def _too_deep(what: str, source: str, where: Location, why: str) -> Diagnostic:
    shown = source if len(source) <= 60 else source[:57] + "..."
    return Diagnostic(
        "X305",
        Severity.ERROR,
        where,
        f"{what} {shown!r} {why}",
        f"expressions are limited to {MAX_SOURCE:,} characters and {MAX_DEPTH} nested levels;"
        " split it or move data into <data>/'data:'",
    )


def _parse(
    source: str, where: Location, what: str
) -> tuple[ast.Expression | None, list[Diagnostic]]:
    text = source.strip()
    if len(text) > MAX_SOURCE:
        return None, [_too_deep(what, text, where, f"is longer than {MAX_SOURCE:,} characters")]
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        if "too many nested" in (exc.msg or ""):
            return None, [_too_deep(what, text, where, f"nests deeper than {MAX_DEPTH} levels")]
        return None, [
            Diagnostic(
                "X301",
                Severity.ERROR,
                where,
                f"{what} {source!r} does not parse: {exc.msg} at column {exc.offset or 0}",
                "write a Python-style expression such as: previous == 'Moving'",
            )
        ]
    except (RecursionError, MemoryError):
        return None, [_too_deep(what, text, where, f"nests deeper than {MAX_DEPTH} levels")]
    return tree, []


def _refusals(
    tree: ast.AST, source: str, where: Location, what: str
) -> tuple[set[str], list[Diagnostic]]:
    diagnostics: list[Diagnostic] = []
    names: set[str] = set()

    def refuse(message: str, hint: str) -> None:
        diagnostics.append(Diagnostic("X302", Severity.ERROR, where, message, hint))

    stack: list[tuple[ast.AST, int]] = [(tree, 0)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, ast.expr):
            depth += 1
            if depth > MAX_DEPTH:
                return names, [
                    _too_deep(what, source, where, f"nests deeper than {MAX_DEPTH} levels")
                ]
        stack.extend((child, depth) for child in ast.iter_child_nodes(node))
        col = getattr(node, "col_offset", None)
        at = f" at column {col + 1}" if col is not None else ""
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            refuse(
                f"{what} {source!r} uses '**'{at}, which the safe language refuses",
                "multiply explicitly; unbounded powers can stall a controller",
            )
        elif not isinstance(node, _ALLOWED_NODES):
            refuse(
                f"{what} {source!r} uses a {_describe(node)}{at}, "
                "which the safe expression language refuses",
                "use names, literals, comparisons, and/or/not, arithmetic and In()",
            )
        elif isinstance(node, ast.Name):
            if node.id.startswith("_") and node.id not in ALLOWED_PRIVATE:
                refuse(
                    f"{what} {source!r} reads the private name {node.id!r}{at}",
                    "names starting with '_' are not available in guards",
                )
            elif node.id not in CALLABLE_NAMES:
                names.add(node.id)
        elif isinstance(node, ast.Attribute) and internal_attribute(node.attr):
            refuse(
                f"{what} {source!r} reads the private attribute {node.attr!r}{at}",
                "only public data attributes can be read in guards "
                "(no '_' names, no frame, traceback, generator or code attributes)",
            )
        elif isinstance(node, ast.Call):
            ok = isinstance(node.func, ast.Name) and node.func.id in CALLABLE_NAMES
            if not ok or node.keywords:
                callee = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
                refuse(
                    f"{what} {source!r} calls {callee!r}{at}, which is not allowed",
                    "callable: " + ", ".join(sorted(CALLABLE_NAMES)) + " (no keywords)",
                )
    return names, diagnostics


def compile_expression(
    source: str, where: Location, *, what: str = "guard"
) -> tuple[Expression | None, list[Diagnostic]]:
    """Parse, check and bound ``source``; return the expression or the reasons it was refused.

    The work is cached by text (a table repeats its guards), so only the location of
    each diagnostic is per call.
    """
    expression, diagnostics = _compile_cached(source, what)
    return expression, [replace(d, where=where) for d in diagnostics]


@functools.lru_cache(maxsize=4096)
def _compile_cached(source: str, what: str) -> tuple[Expression | None, tuple[Diagnostic, ...]]:
    where = Location()  # each caller puts its own location on the diagnostics
    tree, diagnostics = _parse(source, where, what)
    if tree is None:
        return None, tuple(diagnostics)
    names, diagnostics = _refusals(tree, source, where, what)
    if diagnostics:
        return None, tuple(diagnostics)
    bound = _Bound()
    bounded = bound.visit(tree)
    for node, why in _fold(bounded, bound):
        col = getattr(node, "col_offset", None)
        at = f" at column {col + 1}" if col is not None else ""
        diagnostics.append(
            Diagnostic(
                "X304",
                Severity.ERROR,
                where,
                f"{what} {source.strip()!r}{at}: {why}",
                "the safe language bounds every operation; see docs/security.md for the limits",
            )
        )
    if diagnostics:
        return None, tuple(diagnostics)
    code = compile(bounded, f"<{what}>", "eval")
    return Expression(source.strip(), code, frozenset(names)), ()


def check_names(
    expression: Expression, known: Iterable[str], where: Location, *, what: str = "guard"
) -> list[Diagnostic]:
    """Report names the expression reads that the chart does not define."""
    known_set = known if isinstance(known, set | frozenset) else set(known)  # not copied per row
    return [
        Diagnostic(
            "X303",
            Severity.ERROR,
            where,
            f"{what} {expression.source!r} reads undefined name {name!r}",
            "known names: "
            + (", ".join(sorted(known_set)) or "none")
            + "; declare it under 'data:' in the device file",
        )
        for name in sorted(expression.names - known_set)
    ]
