"""Whether two guards can never both hold: the sound, incomplete prover behind C403.

Rules:
1. A guard becomes negation normal form, then disjunctive normal form (capped;
   too big means "not proven").
2. Two guards are exclusive when every conjunction of the one, joined with every
   conjunction of the other, is contradictory.
3. A conjunction is contradictory when it holds an opaque literal and its
   negation, or when its comparisons of one expression against constants leave
   no value (==, !=, <, <=, >, >=, in, not in; ``is`` only against
   None/True/False and never mixed with ==).
4. Anything else (two names compared, calls, arithmetic) is opaque: never
   assumed exclusive, so the answer is sound.
"""

from __future__ import annotations

import ast
import functools
import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["guards_exclusive"]

_MAX_CONJUNCTIONS = 256
_FLIP: dict[type[ast.cmpop], type[ast.cmpop]] = {
    ast.Lt: ast.Gt,
    ast.LtE: ast.GtE,
    ast.Gt: ast.Lt,
    ast.GtE: ast.LtE,
    ast.Eq: ast.Eq,
    ast.NotEq: ast.NotEq,
}
_NEGATE: dict[type[ast.cmpop], type[ast.cmpop]] = {
    ast.Eq: ast.NotEq,
    ast.NotEq: ast.Eq,
    ast.Lt: ast.GtE,
    ast.GtE: ast.Lt,
    ast.Gt: ast.LtE,
    ast.LtE: ast.Gt,
    ast.In: ast.NotIn,
    ast.NotIn: ast.In,
    ast.Is: ast.IsNot,
    ast.IsNot: ast.Is,
}
_IDENTITY_CONSTANTS = (None, True, False)


class _TooBig(Exception):
    """DNF exceeded the cap; the procedure answers "not proven"."""


@dataclass(frozen=True, slots=True)
class _Opaque:
    key: str
    positive: bool


@dataclass(frozen=True, slots=True)
class _Cmp:
    """``subject op value``: ``family`` is "eq" (==, <, in, ...) or "is"."""

    family: str
    subject: str
    op: type[ast.cmpop]
    value: Any  # a constant, or a tuple of constants for in / not in


_Literal = _Opaque | _Cmp
_Conj = tuple[_Literal, ...]


def _constant(node: ast.expr) -> tuple[bool, Any]:
    if isinstance(node, ast.Constant):
        return True, node.value
    if (
        isinstance(node, ast.UnaryOp)
        and isinstance(node.op, ast.USub | ast.UAdd)
        and isinstance(node.operand, ast.Constant)
        and isinstance(node.operand.value, int | float)
        and not isinstance(node.operand.value, bool)
    ):
        v = node.operand.value
        return True, -v if isinstance(node.op, ast.USub) else v
    return False, None


def _constants(node: ast.expr) -> tuple[bool, tuple[Any, ...]]:
    if isinstance(node, ast.Tuple | ast.List | ast.Set):
        values = []
        for elt in node.elts:
            ok, v = _constant(elt)
            if not ok:
                return False, ()
            values.append(v)
        return True, tuple(values)
    return False, ()


def _literal(node: ast.Compare, positive: bool) -> _Literal:
    """One comparison as a literal; comparisons we cannot reason about stay opaque."""
    op = type(node.ops[0])
    left, right = node.left, node.comparators[0]
    if not positive:
        op = _NEGATE.get(op, op)
    if _constant(left)[0] and op in _FLIP:
        left, right, op = right, left, _FLIP[op]
    if not _constant(left)[0]:
        subject = ast.dump(left)
        is_const, value = _constant(right)
        if op in (ast.In, ast.NotIn):
            ok, values = _constants(right)
            if ok:
                return _Cmp("eq", subject, op, values)
        elif op in (ast.Is, ast.IsNot):
            if is_const and any(value is c for c in _IDENTITY_CONSTANTS):
                return _Cmp("is", subject, op, value)
        elif is_const:
            return _Cmp("eq", subject, op, value)
    # opaque: canonical op with polarity so `a >= b` and `a < b` still meet
    base = type(node.ops[0])
    pol = positive
    if base in (ast.NotEq, ast.GtE, ast.Gt, ast.NotIn, ast.IsNot):
        base, pol = _NEGATE[base], not pol
    key = f"{ast.dump(node.left)} {base.__name__} {ast.dump(node.comparators[0])}"
    return _Opaque(key, pol)


def _dnf(node: ast.expr, positive: bool = True) -> list[_Conj]:
    """Disjunctive normal form of ``node`` (negated when not ``positive``)."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        return _dnf(node.operand, not positive)
    if isinstance(node, ast.BoolOp):
        parts = [_dnf(v, positive) for v in node.values]
        conjunctive = isinstance(node.op, ast.And) == positive
        if not conjunctive:
            out = [c for p in parts for c in p]
        else:
            out = [()]
            for p in parts:
                out = [a + b for a in out for b in p]
                if len(out) > _MAX_CONJUNCTIONS:
                    raise _TooBig
        if len(out) > _MAX_CONJUNCTIONS:
            raise _TooBig
        return out
    if isinstance(node, ast.Compare):
        if len(node.ops) > 1:  # a < b < c is a < b and b < c
            pairs = [
                ast.Compare(left=a, ops=[op], comparators=[b])
                for a, op, b in zip(
                    [node.left, *node.comparators[:-1]], node.ops, node.comparators, strict=True
                )
            ]
            return _dnf(ast.BoolOp(op=ast.And(), values=list(pairs)), positive)
        return [(_literal(node, positive),)]
    return [(_Opaque(ast.dump(node), positive),)]


@dataclass(slots=True)
class _Range:
    """What a conjunction allows for one subject."""

    allowed: list[Any] | None = None  # None: any value
    excluded: list[Any] = field(default_factory=list)
    low: tuple[Any, bool] | None = None  # (bound, inclusive)
    high: tuple[Any, bool] | None = None


def _member(value: Any, values: Sequence[Any]) -> bool:
    return any(value == v for v in values)


_ORDER: dict[type[ast.cmpop], Callable[[Any, Any], bool]] = {
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
}


def _tighten(r: _Range, op: type[ast.cmpop], value: Any) -> None:
    if op in (ast.Gt, ast.GtE):
        bound = (value, op is ast.GtE)
        if r.low is None or value > r.low[0] or (value == r.low[0] and not bound[1]):
            r.low = bound
    else:
        bound = (value, op is ast.LtE)
        if r.high is None or value < r.high[0] or (value == r.high[0] and not bound[1]):
            r.high = bound


def _in_bounds(r: _Range, value: Any) -> bool:
    if r.low is not None and not (value >= r.low[0] if r.low[1] else value > r.low[0]):
        return False
    return r.high is None or (value <= r.high[0] if r.high[1] else value < r.high[0])


def _empty(r: _Range) -> bool:
    """Whether no value satisfies ``r``; a TypeError (mixed types) means not proven."""
    try:
        candidates = r.allowed
        if candidates is None and r.low is not None and r.high is not None:
            lo, hi = r.low, r.high
            if lo[0] > hi[0] or (lo[0] == hi[0] and not (lo[1] and hi[1])):
                return True
            if lo[0] == hi[0]:
                candidates = [lo[0]]
        if candidates is None:
            return False
        return all(_member(v, r.excluded) or not _in_bounds(r, v) for v in candidates)
    except TypeError:
        return False


def _contradictory(conj: _Conj) -> bool:
    opaque: dict[str, bool] = {}
    ranges: dict[tuple[str, str], _Range] = {}
    try:
        for lit in conj:
            if isinstance(lit, _Opaque):
                if opaque.setdefault(lit.key, lit.positive) != lit.positive:
                    return True
                continue
            r = ranges.setdefault((lit.family, lit.subject), _Range())
            if lit.op in (ast.Eq, ast.Is, ast.In):
                values = list(lit.value) if lit.op is ast.In else [lit.value]
                if r.allowed is None:
                    r.allowed = values
                elif lit.family == "is":
                    r.allowed = [v for v in r.allowed if any(v is w for w in values)]
                else:
                    r.allowed = [v for v in r.allowed if _member(v, values)]
            elif lit.op in (ast.NotEq, ast.IsNot, ast.NotIn):
                r.excluded.extend(lit.value if lit.op is ast.NotIn else (lit.value,))
            elif lit.op in _ORDER:
                _tighten(r, lit.op, lit.value)
    except TypeError:
        return False  # bounds of mixed types: not proven
    return any(_empty(r) for r in ranges.values())


@functools.lru_cache(maxsize=4096)
def _normal_form(guard: str) -> tuple[_Conj, ...] | None:
    """The guard's DNF, once per guard text (C403 compares each guard with many);
    ``None`` when it does not parse, is too deep to walk, or is too big."""
    try:
        return tuple(_dnf(ast.parse(guard.strip(), mode="eval").body))
    except (SyntaxError, ValueError, RecursionError, MemoryError, _TooBig):
        return None


def guards_exclusive(first: str | None, second: str | None) -> bool:
    """Whether the two guards can never both hold (``None`` is no guard, always true).

    Sound but incomplete: ``True`` is a proof, ``False`` means "not proven".
    """
    return _exclusive(first or None, second or None)


@functools.lru_cache(maxsize=4096)
def _exclusive(first: str | None, second: str | None) -> bool:
    """:func:`guards_exclusive`, once per pair of guard texts: a table repeats a few
    guards on many rows, and C403 and C419 ask of each state's pair again."""
    left = _normal_form(first) if first else ((),)
    right = _normal_form(second) if second else ((),)
    if left is None or right is None:
        return False
    return all(_contradictory(x + y) for x in left for y in right)


def guards_cover(guards: Sequence[str]) -> bool:
    """Whether at least one of ``guards`` holds whatever the values (C419).

    Sound but incomplete, as :func:`guards_exclusive`: ``True`` is a proof that
    ``not (g1 or g2 ...)`` is contradictory; ``False`` means "not proven" (``x > 3``
    and ``x <= 3`` cover; ``previous == 'A'`` alone does not; two opaque calls
    ``f(x)`` and ``not f(x)`` cover, as one literal and its negation).
    """
    if not guards:
        return False
    neither = "not (" + " or ".join(f"({g})" for g in guards) + ")"
    return guards_exclusive(neither, neither)
