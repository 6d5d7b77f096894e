"""Rule 5 of :mod:`statectl.kernel.expr`: every costly operation of an expression is bounded.

The limits, :class:`ExpressionRefused` and the guarded operators and
functions that compiled expressions call at run time live here, apart from the
checker that decides at load which expressions may run at all."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from statectl.kernel.errors import StatectlError

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
