"""The safe expression language of device tables and of the SCXML ``safe`` datamodel.

A model file from someone else must never run code on the controller, nor stall
it, so guards are a checked, bounded subset of Python expressions. Rules:

1. Allowed: names, literals (numbers, strings, booleans, ``None``, tuples,
   lists, sets, dicts), comparisons (including ``in`` and ``is``), ``and`` /
   ``or`` / ``not``, arithmetic (``+ - * / // %``, unary ``-`` and ``+``),
   conditional expressions, indexing, and attribute reads of public names.
2. Calls are allowed only to the whitelisted functions in :data:`FUNCTIONS`
   and :func:`In`; nothing else is callable, so no method of any object is.
   The whitelist holds *names*: a call ``len(x)`` always reaches the guarded
   ``len``, whatever a variable called ``len`` holds, and an attribute read that
   would yield a method (``'x'.join``) is refused at run time, so data never
   makes a callable reachable.
3. Names starting with ``_`` are refused (``_event`` is the one exception, the
   SCXML system variable), as are lambdas, comprehensions, walrus, ``**``,
   f-strings and starred arguments.
4. The check happens when the model loads and reports every offending node as
   a diagnostic with its column; evaluation then runs the compiled code with no
   builtins at all.
5. Every operation whose cost is not linear in the expression's size is bounded
   (see :data:`LIMITS` and docs/security.md): sequence and string repetition and
   concatenation, ``%``-formatting widths and precisions, integer size,
   ``round`` digits, ``int``/``float`` of text, and the size of every value
   built (:data:`MAX_SIZE` characters or elements, counted through nesting).
   Parts of an expression made of literals only are evaluated at load, so
   ``'a' * 10**10``-like bounds are X304 diagnostics; the rest raise
   :class:`ExpressionRefused` at run time. Expressions longer than
   :data:`MAX_SOURCE` characters or nested deeper than :data:`MAX_DEPTH` are X305.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from types import CodeType
from typing import Any, ClassVar

from statectl.errors import Diagnostic, Location, Severity, StatectlError

__all__ = [
    "FUNCTIONS",
    "LIMITS",
    "MAX_DEPTH",
    "MAX_SIZE",
    "MAX_SOURCE",
    "Expression",
    "ExpressionRefused",
    "check_names",
    "compile_expression",
    "value_size",
]

#: Longest expression text accepted (characters).
MAX_SOURCE = 10_000
#: Deepest nesting of sub-expressions accepted (1,000 unary minuses are refused).
MAX_DEPTH = 100
#: Largest value an expression may build: characters of a string or bytes, or
#: elements of a container counted through nesting (shared parts count each time).
MAX_SIZE = 1_000_000
#: Largest integer an operation may produce, in bits (about 3,000 decimal digits).
MAX_INT_BITS = 10_000
#: Largest ``%``-format width or precision.
MAX_WIDTH = 1_000
#: Largest ``ndigits`` of ``round`` in absolute value.
MAX_NDIGITS = 1_000
#: Longest text ``int()`` or ``float()`` converts.
MAX_NUMBER_TEXT = 5_000

#: Every bound, by name, for documentation and diagnostics.
LIMITS: Mapping[str, int] = {
    "source characters": MAX_SOURCE,
    "nesting depth": MAX_DEPTH,
    "value size": MAX_SIZE,
    "integer bits": MAX_INT_BITS,
    "format width or precision": MAX_WIDTH,
    "round digits": MAX_NDIGITS,
    "number text length": MAX_NUMBER_TEXT,
}


class ExpressionRefused(StatectlError):
    """An evaluation would exceed a bound or reach a callable: refused before it runs."""


# -- bounded values ---------------------------------------------------------------------------

_TEXT = (str, bytes, bytearray)
_CONTAINERS = (list, tuple, set, frozenset)
_SEQUENCES = (str, bytes, bytearray, list, tuple, set, frozenset)


def _leaf_size(v: Any) -> int | None:
    """Size of a value that holds no other values; ``None`` for a container."""
    if isinstance(v, _TEXT):
        return max(len(v), 1)
    if isinstance(v, int) and not isinstance(v, bool):
        return 1 + (v.bit_length() * 3) // 10
    if isinstance(v, (list, tuple, set, frozenset, dict)):
        return None
    return 1


def _flat_size(v: Any) -> int | None:
    """Size of a flat sequence of numbers or texts at C speed; ``None`` when it nests."""
    if isinstance(v, dict):
        return None
    kinds = set(map(type, v))
    if kinds <= {int, bool}:
        return 1 + len(v) + (sum(map(int.bit_length, v)) * 3) // 10
    if kinds <= {float, bool, type(None)}:
        return 1 + len(v)
    if kinds <= {str}:
        return 1 + len(v) + sum(map(len, v))
    return None


def _children(v: Any) -> list[Any]:
    return [*v.keys(), *v.values()] if isinstance(v, dict) else list(v)


def value_size(value: Any, budget: int = MAX_SIZE) -> int:
    """Characters plus elements of ``value`` through nesting, shared parts counted each time.

    Each distinct container is visited once (sizes are memoised by identity), so a
    value doubled by sharing (``x = [x, x]``) costs its number of objects, not its
    size; the walk stops as soon as the size passes ``budget``.
    """
    leaf = _leaf_size(value)
    if leaf is not None:
        return leaf
    memo: dict[int, int] = {}
    open_: set[int] = set()
    stack: list[tuple[Any, bool]] = [(value, False)]
    while stack:
        v, expanded = stack.pop()
        key = id(v)
        if key in memo:
            continue
        if not expanded:
            if len(v) > budget:
                return len(v)
            flat = _flat_size(v)
            if flat is not None:
                if flat > budget:
                    return flat
                memo[key] = flat
                continue
            open_.add(key)
            stack.append((v, True))
            for child in _children(v):
                if _leaf_size(child) is None and id(child) not in memo:
                    if id(child) in open_:
                        return budget + 1  # a value containing itself has no finite size
                    stack.append((child, False))
            continue
        size = 1
        for child in _children(v):
            child_leaf = _leaf_size(child)
            size += memo[id(child)] if child_leaf is None else child_leaf
            if size > budget:
                return size
        open_.discard(key)
        memo[key] = size
    return memo[id(value)]


def _refuse_size(size: int, what: str) -> None:
    if size > MAX_SIZE:
        raise ExpressionRefused(
            f"{what} would build a value of more than {MAX_SIZE:,} characters or elements"
        )


def _check_int(value: Any, what: str) -> Any:
    if isinstance(value, int) and value.bit_length() > MAX_INT_BITS:
        raise ExpressionRefused(f"{what} would build an integer of more than {MAX_INT_BITS} bits")
    return value


def _repeat_size(seq: Any, n: int) -> int:
    return value_size(seq) * max(n, 0)


def _op_mul(a: Any, b: Any) -> Any:
    if isinstance(a, int) and isinstance(b, int):
        if a.bit_length() + b.bit_length() > MAX_INT_BITS + 1:
            raise ExpressionRefused(f"'*' would build an integer of more than {MAX_INT_BITS} bits")
    elif isinstance(b, int) and isinstance(a, _SEQUENCES):
        _refuse_size(_repeat_size(a, b), "repetition '*'")
    elif isinstance(a, int) and isinstance(b, _SEQUENCES):
        _refuse_size(_repeat_size(b, a), "repetition '*'")
    return a * b


def _op_add(a: Any, b: Any) -> Any:
    if isinstance(a, _SEQUENCES) and isinstance(b, _SEQUENCES):
        _refuse_size(value_size(a) + value_size(b), "concatenation '+'")
    return _check_int(a + b, "'+'")


def _format_cost(fmt: str) -> int:
    """Length bound of ``fmt % args`` without the arguments; refuses big widths and ``*``."""
    cost, i, n = len(fmt), 0, len(fmt)
    while True:
        i = fmt.find("%", i)
        if i < 0:
            return cost
        i += 1
        if i < n and fmt[i] == "(":
            depth, i = 1, i + 1
            while i < n and depth:
                depth += {"(": 1, ")": -1}.get(fmt[i], 0)
                i += 1
        while i < n and fmt[i] in "-+ #0":
            i += 1
        for part in ("width", "precision"):
            if part == "precision":
                if i < n and fmt[i] == ".":
                    i += 1
                else:
                    break
            if i < n and fmt[i] == "*":
                raise ExpressionRefused(f"'%' format {part} '*' is not allowed; write a number")
            start = i
            while i < n and fmt[i] in "0123456789":
                i += 1
            if i > start:
                number = int(fmt[start:i]) if i - start <= 6 else MAX_WIDTH + 1
                if number > MAX_WIDTH:
                    raise ExpressionRefused(f"'%' format {part} is larger than {MAX_WIDTH}")
                cost += number
        while i < n and fmt[i] in "hlL":
            i += 1
        i += 1


def _op_mod(a: Any, b: Any) -> Any:
    if isinstance(a, _TEXT):
        text = a if isinstance(a, str) else bytes(a).decode("latin-1")  # width digits are ASCII
        _refuse_size(_format_cost(text) + value_size(b), "'%' formatting")
        return a % b
    return a % b


def _op_attr(value: Any, name: str) -> Any:
    result = getattr(value, name)
    if callable(result):
        raise ExpressionRefused(
            f"attribute {name!r} is a method or function; only data attributes can be read"
        )
    return result


def _op_display(value: Any) -> Any:
    _refuse_size(value_size(value), "a list, tuple, set or dict display")
    return value


def _fn_round(number: Any, ndigits: Any = None) -> Any:
    if isinstance(ndigits, int) and abs(ndigits) > MAX_NDIGITS:
        raise ExpressionRefused(f"round() digits beyond +/-{MAX_NDIGITS} are refused")
    return _check_int(round(number, ndigits), "round()")


def _number_text(value: Any, what: str) -> None:
    if isinstance(value, _TEXT) and len(value) > MAX_NUMBER_TEXT:
        raise ExpressionRefused(f"{what} of a text longer than {MAX_NUMBER_TEXT} characters")


def _fn_int(value: Any = 0, *base: Any) -> int:
    _number_text(value, "int()")
    result: int = _check_int(int(value, *base), "int()")
    return result


def _fn_float(value: Any = 0.0) -> float:
    _number_text(value, "float()")
    return float(value)


def _fn_str(value: Any = "") -> str:
    _refuse_size(value_size(value), "str()")
    return str(value)


#: Functions a guard may call, besides ``In(state)`` which the runtime supplies.
FUNCTIONS: Mapping[str, Callable[..., Any]] = {
    "abs": abs,
    "min": min,
    "max": max,
    "len": len,
    "round": _fn_round,
    "int": _fn_int,
    "float": _fn_float,
    "str": _fn_str,
    "bool": bool,
}
CALLABLE_NAMES = frozenset(FUNCTIONS) | {"In"}
ALLOWED_PRIVATE = frozenset({"_event"})

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
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_"):
            refuse(
                f"{what} {source!r} reads the private attribute {node.attr!r}{at}",
                "only public attributes can be read in guards",
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
    known_set = set(known)
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
