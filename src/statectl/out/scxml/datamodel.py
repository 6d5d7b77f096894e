"""SCXML datamodels: where a session's variables live and how its expressions run.

Rules:
1. ``null``: no variables; the only expression is ``In('state')`` (with ``not``,
   ``and``, ``or``); everything else is an error, which the session turns into
   ``error.execution``.
2. ``python``: full Python, trusted like a script you chose to run. One global
   namespace per session holds every ``<data>`` id, the system variables and
   ``In``; expressions are stripped, then ``eval``'d there, ``<script>`` is
   dedented and ``exec``'d there.
3. ``safe``: statectl's checked, bounded expression language
   (:mod:`statectl.kernel.expr`); locations are plain declared names; ``<script>`` is
   refused. A variable may not be named like a callable (``len``, ``In``, ...) or
   start with ``_``, and no value it holds may be a function or exceed
   :data:`statectl.kernel.expr.MAX_SIZE`: data never makes a callable reachable.
4. Every datamodel refuses to assign an undeclared location or a system
   variable (``_event``, ``_sessionid``, ``_name``, ``_ioprocessors``, ``_x``);
   that and every failing evaluation raise :class:`EvaluationError`.
5. Inline values (``<data>``, ``<content>``, ``<assign>`` bodies and ``src``
   files) that parse as JSON become that value, anything else the
   whitespace-normalised string; JSON nested too deeply to decode is an error.
"""

from __future__ import annotations

import ast
import json
import textwrap
from collections.abc import Callable
from typing import Any, Protocol

from statectl.kernel.errors import Location, StatectlError
from statectl.kernel.expr import (
    CALLABLE_NAMES,
    MAX_SIZE,
    MAX_SOURCE,
    Expression,
    ExpressionRefused,
    compile_expression,
    value_size,
)

__all__ = [
    "SYSTEM_VARIABLES",
    "Datamodel",
    "EvaluationError",
    "NullDatamodel",
    "PythonDatamodel",
    "SafeDatamodel",
    "inline_value",
    "make_datamodel",
]

SYSTEM_VARIABLES = frozenset({"_event", "_sessionid", "_name", "_ioprocessors", "_x"})


class EvaluationError(StatectlError):
    """An expression, location or script failed; the session raises ``error.execution``."""


def inline_value(text: str) -> Any:
    """JSON if the text parses as JSON, else the whitespace-normalised string."""
    try:
        return json.loads(text)
    except ValueError:
        return " ".join(text.split())
    except RecursionError as exc:
        raise EvaluationError("inline JSON value is nested too deeply to decode") from exc


class Datamodel(Protocol):
    """What a session needs from a datamodel."""

    name: str

    def declare(self, name: str, value: Any) -> None: ...
    def set_system(self, name: str, value: Any) -> None: ...
    def evaluate(self, expr: str) -> Any: ...
    def condition(self, expr: str) -> bool: ...
    def assign(self, location: str, value: Any) -> None: ...
    def is_location(self, location: str) -> bool: ...
    def run_script(self, source: str) -> None: ...
    def declared(self, name: str) -> bool: ...


def _root_name(location: str) -> tuple[ast.expr, str]:
    """Parse a location (name, attribute or subscript) and return it with its root name."""
    try:
        node = ast.parse(location.strip(), mode="eval").body
    except SyntaxError as exc:
        raise EvaluationError(f"location {location!r} does not parse") from exc
    root = node
    while isinstance(root, ast.Attribute | ast.Subscript):
        root = root.value
    if not isinstance(root, ast.Name):
        raise EvaluationError(f"{location!r} is not a location")
    return node, root.id


class PythonDatamodel:
    """``datamodel="python"``: one namespace, full Python."""

    name = "python"

    def __init__(self, in_state: Callable[[str], bool]) -> None:
        self.namespace: dict[str, Any] = {"__builtins__": __builtins__, "In": in_state}
        self._declared: set[str] = set()

    def declare(self, name: str, value: Any) -> None:
        self._declared.add(name)
        self.namespace[name] = value

    def declared(self, name: str) -> bool:
        return name in self._declared or name in self.namespace

    def set_system(self, name: str, value: Any) -> None:
        self.namespace[name] = value

    def evaluate(self, expr: str) -> Any:
        try:
            return eval(expr.strip(), self.namespace)  # trusted: datamodel="python" is explicit
        except Exception as exc:
            raise EvaluationError(f"{expr.strip()!r} failed: {exc!r}") from exc

    def condition(self, expr: str) -> bool:
        return bool(self.evaluate(expr))

    def is_location(self, location: str) -> bool:
        try:
            node, root = _root_name(location)
        except EvaluationError:
            return False
        if root not in self.namespace:
            return False
        if isinstance(node, ast.Name):
            return True
        try:
            self.evaluate(location)
        except EvaluationError:
            return False
        return True

    def assign(self, location: str, value: Any) -> None:
        node, root = _root_name(location)
        if root in SYSTEM_VARIABLES:
            raise EvaluationError(f"{root} is a system variable and cannot be assigned")
        if root not in self.namespace:
            raise EvaluationError(f"{root!r} is not declared; declare it with <data id={root!r}>")
        target = ast.parse(location.strip(), mode="eval").body
        target.ctx = ast.Store()  # type: ignore[attr-defined]  # Name/Attribute/Subscript
        for sub in ast.walk(target):
            if sub is not target and hasattr(sub, "ctx"):
                sub.ctx = ast.Load()
        slot = "__statectl_value__"
        statement = ast.Module(
            body=[ast.Assign(targets=[target], value=ast.Name(slot, ast.Load()), lineno=1)],
            type_ignores=[],
        )
        ast.fix_missing_locations(statement)
        self.namespace[slot] = value
        try:
            exec(compile(statement, "<assign>", "exec"), self.namespace)
        except Exception as exc:
            raise EvaluationError(f"assigning {location!r} failed: {exc!r}") from exc
        finally:
            self.namespace.pop(slot, None)
        if isinstance(node, ast.Name):
            self._declared.add(root)

    def run_script(self, source: str) -> None:
        try:
            exec(textwrap.dedent(source).strip("\n"), self.namespace)  # trusted, as above
        except Exception as exc:
            raise EvaluationError(f"<script> failed: {exc!r}") from exc


class NullDatamodel:
    """``datamodel="null"``: no data, only ``In()`` conditions."""

    name = "null"

    def __init__(self, in_state: Callable[[str], bool]) -> None:
        self._in = in_state

    def declare(self, name: str, value: Any) -> None:
        pass

    def declared(self, name: str) -> bool:
        return False

    def set_system(self, name: str, value: Any) -> None:
        pass

    def _check(self, node: ast.AST) -> None:
        ok = (
            ast.Expression,
            ast.BoolOp,
            ast.And,
            ast.Or,
            ast.UnaryOp,
            ast.Not,
            ast.Call,
            ast.Name,
            ast.Load,
            ast.Constant,
        )
        for sub in ast.walk(node):
            if not isinstance(sub, ok) or (isinstance(sub, ast.Name) and sub.id != "In"):
                raise EvaluationError("the null datamodel only evaluates In('state')")

    def evaluate(self, expr: str) -> Any:
        if len(expr) > MAX_SOURCE:
            raise EvaluationError(f"expression longer than {MAX_SOURCE:,} characters")
        try:
            tree = ast.parse(expr.strip(), mode="eval")
        except SyntaxError as exc:
            raise EvaluationError(f"{expr[:60]!r} does not parse") from exc
        except (RecursionError, MemoryError) as exc:
            raise EvaluationError(f"{expr[:60]!r} is nested too deeply") from exc
        self._check(tree)
        try:
            return eval(compile(tree, "<null>", "eval"), {"__builtins__": {}, "In": self._in})
        except Exception as exc:
            raise EvaluationError(f"{expr!r} failed: {exc!r}") from exc

    def condition(self, expr: str) -> bool:
        return bool(self.evaluate(expr))

    def is_location(self, location: str) -> bool:
        return False

    def assign(self, location: str, value: Any) -> None:
        raise EvaluationError("the null datamodel has no locations to assign")

    def run_script(self, source: str) -> None:
        raise EvaluationError("the null datamodel runs no scripts")


class SafeDatamodel:
    """``datamodel="safe"``: the checked, bounded expression language; no scripts."""

    name = "safe"

    def __init__(self, in_state: Callable[[str], bool]) -> None:
        self.values: dict[str, Any] = {"In": in_state}
        self._compiled: dict[str, Expression] = {}

    @staticmethod
    def _name(name: str) -> str:
        text = name.strip()
        if not text.isidentifier() or text.startswith("_") or text in CALLABLE_NAMES:
            raise EvaluationError(
                f"{text!r} cannot be a variable of the safe datamodel: names are plain, do "
                "not start with '_' and are not a callable name ("
                + ", ".join(sorted(CALLABLE_NAMES))
                + ")"
            )
        return text

    @staticmethod
    def _value(value: Any, what: str) -> Any:
        if callable(value):
            raise EvaluationError(
                f"{what} is a function, not a value; the safe datamodel holds data only"
            )
        if value_size(value) > MAX_SIZE:
            raise EvaluationError(
                f"{what} is larger than {MAX_SIZE:,} characters or elements (the safe limit)"
            )
        return value

    def declare(self, name: str, value: Any) -> None:
        self.values[self._name(name)] = self._value(value, f"the value of {name.strip()!r}")

    def declared(self, name: str) -> bool:
        return name in self.values

    def set_system(self, name: str, value: Any) -> None:
        self.values[name] = value

    def evaluate(self, expr: str) -> Any:
        compiled = self._compiled.get(expr)
        if compiled is None:
            compiled, problems = compile_expression(expr, Location(), what="expression")
            if compiled is None:
                raise EvaluationError("; ".join(d.message for d in problems))
            self._compiled[expr] = compiled
        try:
            result = compiled.evaluate(self.values)
        except ExpressionRefused as exc:
            raise EvaluationError(f"{expr.strip()!r} refused: {exc}") from exc
        except Exception as exc:
            raise EvaluationError(f"{expr.strip()!r} failed: {exc!r}") from exc
        return self._value(result, repr(expr.strip()))

    def condition(self, expr: str) -> bool:
        return bool(self.evaluate(expr))

    def is_location(self, location: str) -> bool:
        return location.strip() in self.values and location.strip() != "In"

    def assign(self, location: str, value: Any) -> None:
        name = location.strip()
        if name in SYSTEM_VARIABLES:
            raise EvaluationError(f"{name} is a system variable and cannot be assigned")
        if not name.isidentifier() or name not in self.values:
            raise EvaluationError(f"{name!r} is not a declared variable")
        self.values[self._name(name)] = self._value(value, f"the value for {name!r}")

    def run_script(self, source: str) -> None:
        raise EvaluationError("the safe datamodel runs no scripts; use datamodel='python'")


def make_datamodel(kind: str, in_state: Callable[[str], bool]) -> Datamodel:
    """The datamodel a document names; ``ecmascript`` and unknown names are refused."""
    if kind == "python":
        return PythonDatamodel(in_state)
    if kind == "null":
        return NullDatamodel(in_state)
    if kind == "safe":
        return SafeDatamodel(in_state)
    raise StatectlError(f"datamodel {kind!r} is not supported (python, null or safe)")
