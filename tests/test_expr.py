"""The safe expression language: what it accepts, what it refuses, and how it evaluates."""

from __future__ import annotations

import pytest

from statectl.errors import Location
from statectl.expr import check_names, compile_expression

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
