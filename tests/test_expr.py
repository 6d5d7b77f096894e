"""The safe expression language: what it accepts, what it refuses, and how it evaluates."""

from __future__ import annotations

import ast
import re
from typing import Any

import pytest

from statectl.kernel.errors import Location
from statectl.kernel.expr import (
    MAX_DEPTH,
    MAX_SIZE,
    MAX_SOURCE,
    ExpressionRefused,
    check_names,
    compile_expression,
    in_target,
    value_size,
)

HERE = Location("motor.yaml", 12)


@pytest.mark.parametrize(
    ("source", "env", "expected"),
    [
        ("previous == 'Moving'", {"previous": "Moving"}, True),
        ("previous == 'Moving'", {"previous": "Blocked"}, False),
        ("a + b * 2 > 10 and not done", {"a": 1, "b": 5, "done": False}, True),
        ("x in (1, 2, 3)", {"x": 2}, True),
        ("abs(d) <= tol", {"d": -0.5, "tol": 1}, True),
        ("max(a, b) if a else min(a, b)", {"a": 0, "b": 3}, 0),
        ("p.speed >= 2", {"p": type("P", (), {"speed": 3})()}, True),
        ("items[1] == 'b'", {"items": ["a", "b"]}, True),
        ("In('Moving')", {"In": {"Moving"}.__contains__}, True),
        ("x is None", {"x": None}, True),
    ],
)
def test_accepted_expressions_evaluate(
    source: str, env: dict[str, object], expected: object
) -> None:
    """A checked expression evaluates like Python over the given names."""
    expr, diags = compile_expression(source, HERE)
    assert diags == []
    assert expr is not None
    assert expr.evaluate(env) == expected


@pytest.mark.parametrize(
    ("source", "fragment"),
    [
        ("__import__('os').system('true')", "private name"),
        ("open('/etc/passwd')", "calls 'open'"),
        ("x.__class__", "private attribute"),
        ("(lambda: 1)()", "lambda"),
        ("[y for y in x]", "comprehension"),
        ("2 ** 1000000", "'**'"),
        ("x.upper()", "calls 'x.upper'"),
        ("f'{x}'", "f-string"),
        ("(y := 3)", "assignment expression"),
        ("max(x, key=len)", "no keywords"),
    ],
)
def test_refused_constructs_are_diagnosed(source: str, fragment: str) -> None:
    """Anything outside the safe subset is refused at load time with X302 and a reason."""
    expr, diags = compile_expression(source, HERE)
    assert expr is None
    assert diags and all(d.code == "X302" for d in diags)
    assert any(fragment in (d.message + d.hint) for d in diags), [str(d) for d in diags]
    assert all(d.where == HERE for d in diags)


def test_syntax_error_names_the_column() -> None:
    """A guard that does not parse gives X301 with the parser's column."""
    expr, diags = compile_expression("previous == ", HERE)
    assert expr is None
    assert [d.code for d in diags] == ["X301"]
    assert "column" in diags[0].message


def test_undefined_names_are_reported_each() -> None:
    """Every free name the chart does not define is one X303 diagnostic, sorted by name."""
    expr, _ = compile_expression("speed > limit and previous == 'Moving' and In('Moving')", HERE)
    assert expr is not None
    diags = check_names(expr, {"previous"}, HERE)
    assert [d.code for d in diags] == ["X303", "X303"]
    assert ["'limit'" in diags[0].message, "'speed'" in diags[1].message] == [True, True]


def test_evaluation_has_no_builtins() -> None:
    """Even a name that escaped the check could not reach Python's builtins."""
    expr, _ = compile_expression("len(x)", HERE)
    assert expr is not None
    assert expr.evaluate({"x": [1, 2]}) == 2
    probe, _ = compile_expression("open", HERE)
    assert probe is not None
    with pytest.raises(NameError):
        probe.evaluate({})


@pytest.mark.parametrize(
    ("source", "fragment"),
    [
        ("'a' * 10000000000", "repetition '*'"),
        ("len([0] * 100000000 * 3) > 0", "repetition '*'"),
        ("x + ('a' * 1000000 + 'b')", "concatenation '+'"),
        ("'%0999999999d' % 1", "format width is larger than 1000"),
        ("'%.999999999f' % 1.5", "format precision is larger than 1000"),
        ("'%*d' % (5, 1)", "'*' is not allowed"),
        ("'%((a))0999999d' % {'(a)': 1}", "format width"),
        ("round(1, -1000000000)", "round() digits"),
        ("int('9' * 6000)", "int() of a text longer than 5000"),
        ("int('1' * 4000) * 3", "integer of more than 10000 bits"),
        ("9" * 3500, "integer literal of more than 10000 bits"),
        ("'x'.join", "is a method or function"),
        ("1 if x else [[0] * 1000] * 10000", "repetition '*'"),
    ],
)
def test_literal_parts_beyond_a_bound_are_refused_at_load(source: str, fragment: str) -> None:
    """A literal-only part that would exceed a bound is X304 at load, naming the bound."""
    expr, diags = compile_expression(source, HERE)
    assert expr is None
    assert [d.code for d in diags] == ["X304"]
    assert fragment in diags[0].message, diags[0].message


@pytest.mark.parametrize(
    "source",
    [
        "-" * 1000 + "1",
        "[" * 2000 + "]" * 2000,
        "(" * 1000 + "1" + ")" * 1000,
        "-" * 100_000 + "1",
        "1 + " * (MAX_DEPTH + 1) + "1",
        "x" * (MAX_SOURCE + 1),
    ],
    ids=["unary-1000", "lists-2000", "parens-1000", "unary-100000", "chain", "long"],
)
def test_too_deep_or_too_long_is_a_diagnostic_not_a_recursion_error(source: str) -> None:
    """Nesting past MAX_DEPTH or text past MAX_SOURCE gives X305 naming the limits."""
    expr, diags = compile_expression(source, HERE)
    assert expr is None
    assert [d.code for d in diags] == ["X305"]
    assert str(MAX_DEPTH) in diags[0].hint and f"{MAX_SOURCE:,}" in diags[0].hint


def test_nesting_up_to_the_limit_evaluates() -> None:
    """An expression exactly MAX_DEPTH deep still compiles and evaluates."""
    expr, diags = compile_expression("-" * (MAX_DEPTH - 1) + "1", HERE)
    assert diags == []
    assert expr is not None
    assert expr.evaluate({}) == (-1) ** (MAX_DEPTH - 1)


@pytest.mark.parametrize(
    ("source", "env", "fragment"),
    [
        ("x * n", {"x": [0], "n": 100_000_000}, "repetition '*'"),
        ("n * x", {"x": "ab", "n": 600_000}, "repetition '*'"),
        ("x + x", {"x": "a" * 600_000}, "concatenation '+'"),
        ("[x, x]", {"x": "a" * 600_000}, "display"),
        ("str([x, x])", {"x": "a" * 600_000}, "display"),
        ("('%0' + str(n) + 'd') % 1", {"n": 999_999_999}, "format width"),
        ("'%s' % x", {"x": ["a" * 600_000, "a" * 600_000]}, "'%' formatting"),
        ("round(1, n)", {"n": -1_000_000_000}, "round() digits"),
        ("x * x", {"x": 2**6000}, "integer of more than"),
        ("x + x", {"x": 2**10_000 - 1}, "integer of more than"),
        ("int(s)", {"s": "9" * 6000}, "int() of a text"),
        ("float(s)", {"s": "1" * 6000}, "float() of a text"),
        ("s.upper", {"s": "abc"}, "is a method"),
        ("d.get", {"d": {}}, "is a method"),
        ("str(x)", {"x": [[0] * 1000] * 2000}, "str()"),
    ],
)
def test_operations_beyond_a_bound_are_refused_at_run_time(
    source: str, env: dict[str, object], fragment: str
) -> None:
    """What only data makes too big raises ExpressionRefused before the work is done."""
    expr, diags = compile_expression(source, HERE)
    assert expr is not None, [str(d) for d in diags]
    with pytest.raises(ExpressionRefused, match=re.escape(fragment)):
        expr.evaluate(env)


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("len('a' * 1000000)", 1_000_000),
        ("len([0] * 500000)", 500_000),
        ("len('%1000d' % 1)", 1000),
        ("len('%.1000f' % 1.5)", 1002),
        ("round(1234, -3)", 1000),
        ("round(2.5, 1000)", 2.5),
        ("len(str(int('9' * 3000)))", 3000),
        ("'%05d|%-3s|%(k)s' % {'k': 'v'} if False else '%05d' % 42", "00042"),
        ("len(x + x)", 1_000_000),
    ],
)
def test_values_within_the_bounds_still_evaluate(source: str, expected: object) -> None:
    """The bounds refuse only what exceeds them: values up to each limit still work."""
    expr, diags = compile_expression(source, HERE)
    assert diags == []
    assert expr is not None
    assert expr.evaluate({"x": "a" * 500_000}) == expected


@pytest.mark.parametrize(
    ("name", "expected"), [("len", 3), ("str", "['3', '1', '2']"), ("max", "3"), ("min", "1")]
)
def test_a_variable_cannot_shadow_a_whitelisted_function(name: str, expected: object) -> None:
    """A call by a whitelisted name reaches the guarded function whatever the data holds."""
    expr, _ = compile_expression(f"{name}(['3', '1', '2'])", HERE)
    assert expr is not None
    assert expr.evaluate({name: "x".join}) == expected


def test_value_size_counts_shared_parts_without_walking_them() -> None:
    """A value doubled by sharing 40 times is measured as huge, and quickly."""
    value: object = [0]
    for _ in range(40):
        value = [value, value]
    assert value_size(value) > MAX_SIZE
    assert value_size(["ab", [1, 2.5, None], {"k": "v"}]) == 1 + 2 + 4 + 3


@pytest.mark.parametrize(
    "source",
    [
        "_event.data.gi_frame.f_back.f_globals",
        "_event.data.tb_frame",
        "_event.data.cr_frame",
        "_event.data.ag_frame",
        "x.f_builtins",
        "x.f_locals",
        "x.gi_code",
        "x.tb_next",
        "x.f_code",
        "x.co_consts",
        "x.co_anything_new",
        "x.gi_yieldfrom.cr_await",
    ],
)
def test_frame_and_code_attributes_are_refused_like_dunders(source: str) -> None:
    """Attributes that walk to frames, their globals or code objects are X302 at load."""
    expr, diags = compile_expression(source, HERE)
    assert expr is None
    assert diags and all(d.code == "X302" for d in diags)
    assert any("private attribute" in d.message for d in diags), [str(d) for d in diags]


def test_every_frame_family_attribute_of_this_python_is_refused() -> None:
    """Each public attribute of a frame, traceback, generator, coroutine and code object is refused.

    Read from live objects, so a Python that adds one (as 3.11 added co_qualname) fails here."""
    import sys
    import types

    def gen() -> Any:
        yield

    async def coro() -> None:
        return None

    async def agen() -> Any:
        yield

    try:
        raise ValueError
    except ValueError as exc:
        tb = exc.__traceback__
    c = coro()
    objects = [sys._getframe(), tb, gen(), c, agen(), gen.__code__]
    c.close()
    allowed_methods = {"clear", "close", "send", "throw", "aclose", "asend", "athrow", "replace"}
    for obj in objects:
        for attr in dir(obj):
            if attr.startswith("_") or attr in allowed_methods:
                continue
            expr, diags = compile_expression(f"x.{attr}", HERE)
            assert expr is None and [d.code for d in diags] == ["X302"], (type(obj), attr)
    assert isinstance(objects[-1], types.CodeType)


def test_ordinary_attributes_stay_readable() -> None:
    """Data attributes that merely look alike (fields of the user's event data) still load."""
    for source in ("_event.data.f_speed", "_event.data.frame", "_event.data.code", "x.tb"):
        expr, diags = compile_expression(source, HERE)
        assert diags == [] and expr is not None, source


@pytest.mark.parametrize(
    ("source", "named"),
    [
        ("In('Moving')", "Moving"),
        ("In('arm.Moving')", "arm.Moving"),
        ("In(x)", None),  # no text literal
        ("In('a', 'b')", None),
        ("In(3)", None),
        ("Out('arm.Moving')", None),
        ("p.In('arm.Moving')", None),
        ("'arm.Moving'", None),
    ],
)
def test_in_target_is_the_state_an_in_call_names(source: str, named: str | None) -> None:
    """in_target: the one text an In('...') call names; None for anything else."""
    assert in_target(ast.parse(source, mode="eval").body) == named
