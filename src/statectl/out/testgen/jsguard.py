"""A guard or assignment of the safe language written as JavaScript, for GraphWalker.

Rules:
1. GraphWalker keeps a model's variables in a JavaScript context: ``previous`` and
   the datamodel names are variables there, set by the model's and the edges'
   actions; a guard is a JavaScript expression over them.
2. What one edge fixes is written as a literal: the event's data
   (``_event.data.x``, the value the edge sends) and ``In('S')`` (the edge's source
   configuration says whether S is active).
3. Only what means the same in both languages is written: ``and``/``or``/``not``,
   comparisons (``==`` as ``===``; ``in`` a literal list as ``includes``), ``+ - *
   /`` over numbers, literals and names. Anything else gives ``None``: the caller
   keeps the guard as text and says it could not be written.
"""

from __future__ import annotations

import ast
import json
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["js_expression"]

_COMPARE = {
    ast.Eq: "===",
    ast.NotEq: "!==",
    ast.Lt: "<",
    ast.LtE: "<=",
    ast.Gt: ">",
    ast.GtE: ">=",
    ast.Is: "===",
    ast.IsNot: "!==",
}
_ARITHMETIC = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}


class _Untranslatable(Exception):
    pass


def _literal(value: Any) -> str:
    try:
        return json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        raise _Untranslatable from None


class _Writer:
    def __init__(self, names: frozenset[str], event_data: Any, active: Callable[[str], bool]):
        self.names = names
        self.event_data = event_data
        self.active = active

    def __call__(self, node: ast.AST) -> str:
        method = getattr(self, f"_{type(node).__name__}", None)
        if method is None:
            raise _Untranslatable
        text: str = method(node)
        return text

    def _BoolOp(self, node: ast.BoolOp) -> str:
        op = " && " if isinstance(node.op, ast.And) else " || "
        return "(" + op.join(self(v) for v in node.values) + ")"

    def _UnaryOp(self, node: ast.UnaryOp) -> str:
        if isinstance(node.op, ast.Not):
            return f"!({self(node.operand)})"
        if isinstance(node.op, ast.USub):
            return f"(-{self(node.operand)})"
        raise _Untranslatable

    def _BinOp(self, node: ast.BinOp) -> str:
        op = _ARITHMETIC.get(type(node.op))
        if op is None:
            raise _Untranslatable
        return f"({self(node.left)} {op} {self(node.right)})"

    def _Compare(self, node: ast.Compare) -> str:
        parts = [node.left, *node.comparators]
        out = []
        for i, op in enumerate(node.ops):
            left, right = self(parts[i]), self(parts[i + 1])
            if isinstance(op, ast.In | ast.NotIn):
                if not isinstance(parts[i + 1], ast.Tuple | ast.List | ast.Set):
                    raise _Untranslatable
                test = f"{right}.includes({left})"
                out.append(test if isinstance(op, ast.In) else f"!{test}")
                continue
            out.append(f"({left} {_COMPARE[type(op)]} {right})")
        return out[0] if len(out) == 1 else "(" + " && ".join(out) + ")"

    def _Constant(self, node: ast.Constant) -> str:
        return _literal(node.value)

    def _Tuple(self, node: ast.Tuple | ast.List | ast.Set) -> str:
        return "[" + ", ".join(self(e) for e in node.elts) + "]"

    _List = _Set = _Tuple

    def _Name(self, node: ast.Name) -> str:
        if node.id == "previous" or node.id in self.names:
            return node.id
        raise _Untranslatable

    def _Call(self, node: ast.Call) -> str:
        ok = isinstance(node.func, ast.Name) and node.func.id == "In" and len(node.args) == 1
        arg = node.args[0] if ok else None
        if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
            return "true" if self.active(arg.value) else "false"
        raise _Untranslatable

    def _Attribute(self, node: ast.Attribute | ast.Subscript) -> str:
        value = _event_field(node, self.event_data)
        return _literal(value)

    _Subscript = _Attribute


def _event_field(node: ast.AST, data: Any) -> Any:
    """The value ``_event.data[.x]`` reads from the edge's event data (rule 2)."""
    chain: list[str] = []
    while isinstance(node, ast.Attribute | ast.Subscript):
        if isinstance(node, ast.Attribute):
            chain.append(node.attr)
        elif isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, str):
            chain.append(node.slice.value)
        else:
            raise _Untranslatable
        node = node.value
    if not (isinstance(node, ast.Name) and node.id == "_event") or chain[-1:] != ["data"]:
        raise _Untranslatable
    value = data
    for key in reversed(chain[:-1]):
        if not isinstance(value, Mapping) or key not in value:
            raise _Untranslatable
        value = value[key]
    return value


def js_expression(
    source: str,
    names: frozenset[str],
    event_data: Any = None,
    active: Callable[[str], bool] = lambda s: False,
) -> str | None:
    """``source`` as JavaScript (rules 1-3), or ``None`` when it cannot be written."""
    try:
        tree = ast.parse(source.strip(), mode="eval")
        return _Writer(names, event_data, active)(tree.body)
    except (SyntaxError, _Untranslatable, RecursionError):
        return None
