"""Runtime guards to C++ expressions (rule 4 of :mod:`statectl.out.codegen.flatten`):
``previous`` and ``In()`` folded away, integer context fields with ``+ - *``,
comparisons, ``and/or/not`` and ``a if c else b``; anything else is untranslatable,
which the flattener reports as G702. Its own module: it is a small compiler of its own.
"""

from __future__ import annotations

import ast
from typing import Any

from statectl.kernel.expr import FUNCTIONS
from statectl.out.codegen.checks import _is_int

# -- guard translation -------------------------------------------------------------------------


class _Untranslatable(Exception):
    pass


_SAFE: dict[str, Any] = {"__builtins__": {}, **FUNCTIONS}
_CMP = {ast.Eq: "==", ast.NotEq: "!=", ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">="}
_ARITH = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*"}


def _names(node: ast.AST) -> set[str]:
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}


def _literal(value: object) -> str:
    if isinstance(value, bool):
        return "V(1)" if value else "V(0)"
    if _is_int(value):
        return f"V({value})"
    raise _Untranslatable(f"the constant {value!r} is not an integer or boolean")


class _Translator:
    """Python guard AST -> C++ over ``c`` (the context), with ``previous``/``In`` folded."""

    def __init__(self, fields: dict[str, str], env: dict[str, Any]) -> None:
        self.fields = fields
        self.env = env

    def cpp(self, node: ast.expr) -> str:
        if not (_names(node) & self.fields.keys()):
            return _literal(self._fold(node))
        match node:
            case ast.Name(id=name):
                return f"c.{self.fields[name]}"
            case ast.BoolOp(op=op, values=values):
                return self._boolop(isinstance(op, ast.And), [self.cpp(v) for v in values])
            case ast.UnaryOp(op=ast.Not(), operand=x):
                return f"V(!({self.cpp(x)}))"
            case ast.UnaryOp(op=ast.USub(), operand=x):
                return f"(-({self.cpp(x)}))"
            case ast.UnaryOp(op=ast.UAdd(), operand=x):
                return f"(+({self.cpp(x)}))"
            case ast.BinOp(op=op, left=left, right=right) if type(op) in _ARITH:
                return f"(({self.cpp(left)}) {_ARITH[type(op)]} ({self.cpp(right)}))"
            case ast.Compare(left=left, ops=ops, comparators=comps) if all(
                type(o) in _CMP for o in ops
            ):
                operands = [self.cpp(x) for x in (left, *comps)]
                parts = [
                    f"(({a}) {_CMP[type(o)]} ({b}))"
                    for a, o, b in zip(operands, ops, operands[1:], strict=False)
                ]
                return f"V({' && '.join(parts)})"
            case ast.IfExp(test=test, body=body, orelse=orelse):
                return f"(({self.cpp(test)}) ? ({self.cpp(body)}) : ({self.cpp(orelse)}))"
        raise _Untranslatable(f"{ast.unparse(node)!r} ({type(node).__name__}) reads context fields")

    @staticmethod
    def _boolop(is_and: bool, values: list[str]) -> str:
        head = values[0]
        if len(values) == 1:
            return head
        rest = _Translator._boolop(is_and, values[1:])
        if is_and:
            return f"(({head}) ? ({rest}) : ({head}))"
        return f"(({head}) ? ({head}) : ({rest}))"

    def _fold(self, node: ast.expr) -> Any:
        code = compile(ast.fix_missing_locations(ast.Expression(node)), "<guard>", "eval")
        try:
            return eval(code, _SAFE, dict(self.env))  # checked by compile_expression already
        except Exception as exc:
            raise _Untranslatable(f"{ast.unparse(node)!r} fails when folded: {exc}") from exc
