"""Guards split into their conditions: what the ``pairs`` criterion makes true and false.

Rules:
1. A guard's *conditions* are its atomic parts: the operands of ``and``, ``or``
   and ``not``, down to comparisons, calls (``In``) and bare reads. A compound
   guard has two or more.
2. Its *inputs* are what a test controls: ``previous`` (the path), a datamodel
   name (the ``statectl_data`` marker) and a field of the event's data (sent with
   the event).
3. Candidate values of an input (:func:`input_values`): each number a condition
   compares it with, one below and one above; each text, and another text; both
   booleans for an input read bare (a condition of its own, ``_event.data.enable``)
   or compared with a boolean; for a comparison of two inputs, each one's default
   and its neighbours for the other. Declared field types filter them.
4. A condition *decides* a context when the guard, with that condition forced true
   and forced false and everything else as the context has it, gives two outcomes
   (masking MC/DC): a pair of contexts in which a condition decides, has two values,
   and the guard two outcomes shows that condition matters on its own.
5. A comparison over numbers has a *distance*, left side minus right side; its
   boundary values are the contexts at distance -1, 0 and +1.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from statectl.kernel.errors import Location
from statectl.kernel.expr import Expression, compile_expression

__all__ = [
    "Condition",
    "Guard",
    "Input",
    "analyse",
    "input_values",
]

#: An input of a guard: ("previous", ""), ("data", name) or ("event", field) ("": whole).
Input = tuple[str, str]

#: The name a forced condition reads (rule 4); no table can define it (no '_' start
#: is allowed in tables, and this one is no identifier a guard could spell).
_FORCED = "statectl_forced_condition"


@dataclass(frozen=True, slots=True)
class Condition:
    """One atomic condition of a guard (rule 1)."""

    text: str
    inputs: frozenset[Input]
    #: for a comparison of numbers: its left and right sides (rule 5)
    sides: tuple[Expression, Expression] | None
    forced: Expression  # the guard with this condition replaced by _FORCED
    own: Expression  # the condition alone


@dataclass(frozen=True, slots=True)
class Guard:
    """A guard's conditions and inputs."""

    source: str
    conditions: tuple[Condition, ...]
    inputs: frozenset[Input]

    @property
    def compound(self) -> bool:
        return len(self.conditions) > 1

    @property
    def reads_previous(self) -> bool:
        return ("previous", "") in self.inputs


def _compile(text: str) -> Expression | None:
    expr, _ = compile_expression(text, Location(), what="guard")
    return expr


def _input_of(node: ast.AST, data_names: frozenset[str]) -> Input | None:
    """The input a node reads directly, if it is one (rule 2)."""
    if isinstance(node, ast.Name):
        if node.id == "previous":
            return ("previous", "")
        if node.id in data_names:
            return ("data", node.id)
        return None
    inner: ast.AST | None = None
    key: str | None = None
    if isinstance(node, ast.Attribute):
        inner, key = node.value, node.attr
    elif (
        isinstance(node, ast.Subscript)
        and isinstance(node.slice, ast.Constant)
        and isinstance(node.slice.value, str)
    ):
        inner, key = node.value, node.slice.value
    if inner is None or key is None:
        return None
    if _is_event_data(inner):
        return ("event", key)
    if _is_event(inner) and key == "data":
        return ("event", "")
    return None


def _is_event(node: ast.AST) -> bool:
    return isinstance(node, ast.Name) and node.id == "_event"


def _is_event_data(node: ast.AST) -> bool:
    if isinstance(node, ast.Attribute):
        return _is_event(node.value) and node.attr == "data"
    return (
        isinstance(node, ast.Subscript)
        and _is_event(node.value)
        and isinstance(node.slice, ast.Constant)
        and node.slice.value == "data"
    )


def _inputs(node: ast.AST, data_names: frozenset[str]) -> frozenset[Input]:
    found: set[Input] = set()
    for sub in ast.walk(node):
        got = _input_of(sub, data_names)
        if got is not None:
            found.add(got)
    if any(k == "event" and f for k, f in found):
        found.discard(("event", ""))  # the inner ``_event.data`` of ``_event.data.x``
    return frozenset(found)


def _atoms(node: ast.expr) -> list[ast.expr]:
    """The atomic conditions of ``node`` in reading order (rule 1)."""
    if isinstance(node, ast.BoolOp):
        return [a for v in node.values for a in _atoms(v)]
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        return _atoms(node.operand)
    return [node]


class _Replace(ast.NodeTransformer):
    def __init__(self, target: ast.AST) -> None:
        self.target = target

    def visit(self, node: ast.AST) -> Any:
        if node is self.target:
            return ast.copy_location(ast.Name(_FORCED, ast.Load()), node)
        return super().visit(node)


def _number_sides(atom: ast.expr) -> tuple[Expression, Expression] | None:
    """The two sides of a single ordering or equality comparison (rule 5)."""
    if not (isinstance(atom, ast.Compare) and len(atom.ops) == 1):
        return None
    if not isinstance(atom.ops[0], ast.Lt | ast.LtE | ast.Gt | ast.GtE | ast.Eq | ast.NotEq):
        return None
    left, right = _compile(ast.unparse(atom.left)), _compile(ast.unparse(atom.comparators[0]))
    return None if left is None or right is None else (left, right)


@functools.lru_cache(maxsize=1024)
def analyse(source: str, data_names: frozenset[str]) -> Guard | None:
    """The guard's conditions and inputs; ``None`` when it does not parse."""
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except SyntaxError:
        return None
    conditions = []
    for atom in _atoms(tree.body):
        copy = ast.parse(source.strip(), mode="eval")
        # the same atom in the copy: walk both trees in step
        twin = next(b for a, b in zip(ast.walk(tree), ast.walk(copy), strict=True) if a is atom)
        forced = _compile(ast.unparse(_Replace(twin).visit(copy)))
        own = _compile(ast.unparse(atom))
        if forced is None or own is None:
            return None
        inputs = _inputs(atom, data_names)
        conditions.append(Condition(ast.unparse(atom), inputs, _number_sides(atom), forced, own))
    return Guard(source, tuple(conditions), _inputs(tree, data_names))


def _neighbours(v: Any) -> list[Any]:
    if isinstance(v, bool) or v is None:
        return [True, False]
    if isinstance(v, int | float):
        return [v, v - 1, v + 1]
    if isinstance(v, str):
        return [v, v + "_other" if v else "x"]
    return [v]


def _constant(node: ast.AST) -> tuple[bool, Any]:
    """Whether ``node`` is a literal (a negative number too), and its value."""
    if isinstance(node, ast.Constant):
        return True, node.value
    if (
        isinstance(node, ast.UnaryOp)
        and isinstance(node.op, ast.USub)
        and isinstance(node.operand, ast.Constant)
        and isinstance(node.operand.value, int | float)
    ):
        return True, -node.operand.value
    if isinstance(node, ast.Tuple | ast.List | ast.Set):
        values = [_constant(e) for e in node.elts]
        if all(ok for ok, _ in values):
            return True, [v for _, v in values]
    return False, None


def _add(out: dict[Input, list[Any]], key: Input, values: list[Any]) -> None:
    have = out.setdefault(key, [])
    for v in values:
        if not any(type(v) is type(w) and v == w for w in have):
            have.append(v)


def input_values(
    source: str, data_names: frozenset[str], defaults: Mapping[str, Any]
) -> dict[Input, list[Any]]:
    """Candidate values per input of a guard (rule 3), in the order found."""
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except SyntaxError:
        return {}
    out: dict[Input, list[Any]] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            parts = [node.left, *node.comparators]
            for i, op in enumerate(node.ops):
                pair = (parts[i], parts[i + 1])
                for mine, other in (pair, pair[::-1]):
                    key = _input_of(mine, data_names)
                    if key is None:
                        continue
                    ok, value = _constant(other)
                    if ok and isinstance(op, ast.In | ast.NotIn) and isinstance(value, list):
                        for v in value:
                            _add(out, key, _neighbours(v))
                    elif ok:
                        _add(out, key, _neighbours(value))
                    theirs = _input_of(other, data_names)
                    if theirs is not None and theirs[0] == "data" and theirs[1] in defaults:
                        _add(out, key, _neighbours(defaults[theirs[1]]))
    for atom in _atoms(tree.body):
        key = _input_of(atom, data_names)
        if key is not None:
            _add(out, key, [True, False])
    return out


def decides(c: Condition, env: Mapping[str, Any]) -> bool | None:
    """Whether ``c`` decides the guard in ``env`` (rule 4); ``None`` if it cannot say."""
    try:
        on = bool(c.forced.evaluate({**env, _FORCED: True}))
        off = bool(c.forced.evaluate({**env, _FORCED: False}))
    except Exception:  # a context the guard cannot read: no evidence
        return None
    return on != off


def value_of(expr: Expression, env: Mapping[str, Any]) -> Any:
    """``expr`` in ``env``, or ``None`` when it fails there."""
    try:
        return expr.evaluate(env)
    except Exception:  # a context the condition cannot read: no evidence
        return None


def distance(c: Condition, env: Mapping[str, Any]) -> float | None:
    """Left side minus right side of a comparison of numbers (rule 5), else ``None``."""
    if c.sides is None:
        return None
    left, right = (value_of(s, env) for s in c.sides)
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (left, right))
    return float(left - right) if numbers else None
