"""The OPC UA server's methods: every call checked, then sent through the System's door.

Rules (rule 3 of :mod:`statectl.channels.opcua.server` in detail):
1. A method belongs to one object: a device's event methods to the device object, a
   PackML command to the machine that holds it. Called on any other object it is
   ``BadMethodInvalid`` (asyncua only checks that both nodes exist).
2. Inputs. A device's method takes at most one, ``Data``: a String holding the event's
   data as a JSON object (empty or absent: no data), at most :data:`MAX_DATA` bytes,
   its numbers finite. A second input is ``BadTooManyArguments``; an input of another
   type (a Double NaN, say), too long, not JSON, NaN or infinite, or not an object is
   ``BadInvalidArgument`` with the input's own status. A PackML command takes none.
   A command event that declares its data fields (the tables' ``data``) takes
   those fields instead, one typed input each in declaration order
   (:data:`FIELD_TYPES`: ``amount: float`` is a Double): all of them (fewer is
   ``BadArgumentsMissing``), each of its type (an int field takes any integer
   type, a float field a Double, a Float or an integer; else ``BadTypeMismatch``),
   a number finite, a text at most :data:`MAX_DATA` bytes (else ``BadOutOfRange``),
   and a ``list`` / ``dict`` / ``any`` field as JSON text of that shape. A bad
   input is ``BadInvalidArgument`` with its own status, Good for the others.
3. Who. The session's user (:func:`~statectl.channels.opcua.access.caller`) is the
   command's origin, ``Origin("opcua", user)``, anonymous when the session has none;
   the System's commands policy decides at its door (:mod:`statectl.run.commands`)
   whatever asyncua's own rules let through. A refusal is ``BadUserAccessDenied``; the
   System journals it and nothing moves.
4. Then the call submits the event at the System's one door and answers once the
   device's step on it ran, with or without a journal; whether the loop's thread runs
   the step itself is the door's to decide (system.py rule 8), not this module's.
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Awaitable, Callable
from typing import Any

from statectl.channels.opcua.access import caller
from statectl.channels.opcua.access import ua_module as _ua
from statectl.kernel.errors import StatectlError
from statectl.kernel.semantics import Outcome
from statectl.run.commands import CommandRefused, Origin
from statectl.run.system import System

__all__ = ["DATA_ARGUMENT", "FIELD_TYPES", "MAX_DATA", "Calls", "read_data", "read_fields"]

#: The most bytes of JSON a method's ``Data`` input may hold (the dashboard's body bound).
MAX_DATA = 65536
#: The name of a device method's one optional input (rule 2).
DATA_ARGUMENT = "Data"

#: A declared field's type (docs/tables.md, "Event data") -> the OPC UA DataType of its
#: input (rule 2); ``list``, ``dict`` and ``any`` travel as JSON text.
FIELD_TYPES = {
    "int": "Int64",
    "float": "Double",
    "str": "String",
    "bool": "Boolean",
    "list": "String",
    "dict": "String",
    "any": "String",
}
_INTEGERS = ("SByte", "Byte", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
#: The variant types an input of a declared field's type takes (rule 2).
_TAKES = {
    "int": _INTEGERS,
    "float": ("Double", "Float", *_INTEGERS),
    "str": ("String",),
    "bool": ("Boolean",),
    "list": ("String",),
    "dict": ("String",),
    "any": ("String",),
}
_SHAPES: dict[str, type | None] = {"list": list, "dict": dict, "any": None}

#: ``run(data, origin)``: post the event and answer the call.
Run = Callable[[Any, Origin], Awaitable[Any]]
#: Reads a call's inputs into the event's data (rule 2), raising :class:`_Bad`.
Reader = Callable[[tuple[Any, ...]], Any]


class _Bad(Exception):
    """An input refused (rule 2): the call's status and the inputs' own (one for all
    when ``inputs`` is None)."""

    def __init__(self, call: str, argument: str, inputs: list[str] | None = None) -> None:
        super().__init__(call)
        self.call, self.argument, self.inputs = call, argument, inputs


def read_data(args: tuple[Any, ...], takes_data: bool) -> Any:
    """The event data the inputs carry (rule 2); raises :class:`_Bad` for inputs refused."""
    if len(args) > (1 if takes_data else 0):
        raise _Bad("BadTooManyArguments", "BadTooManyArguments")
    if not args:
        return None
    ua = _ua()
    arg = args[0]
    if getattr(arg, "VariantType", None) != ua.VariantType.String:
        raise _Bad("BadInvalidArgument", "BadTypeMismatch")
    text = arg.Value
    if text is None or text == "":
        return None
    if not isinstance(text, str):  # an array of Strings
        raise _Bad("BadInvalidArgument", "BadTypeMismatch")
    if len(text) > MAX_DATA or len(text.encode("utf-8", "surrogatepass")) > MAX_DATA:
        raise _Bad("BadInvalidArgument", "BadOutOfRange")
    try:
        data = json.loads(text, parse_constant=_not_finite, parse_float=_finite)
    except (ValueError, RecursionError):  # not JSON, NaN/Infinity, too deep, a huge int
        raise _Bad("BadInvalidArgument", "BadInvalidArgument") from None
    if not isinstance(data, dict):
        raise _Bad("BadInvalidArgument", "BadInvalidArgument")
    return data


def read_fields(args: tuple[Any, ...], fields: tuple[tuple[str, str], ...]) -> Any:
    """The event data of a typed method's inputs (rule 2): ``{field: value}``, in order."""
    if len(args) > len(fields):
        raise _Bad("BadTooManyArguments", "BadTooManyArguments")
    if len(args) < len(fields):
        raise _Bad("BadArgumentsMissing", "Good", ["Good"] * len(args))
    data: dict[str, Any] = {}
    for at, ((name, kind), arg) in enumerate(zip(fields, args, strict=True)):
        problem = _field(arg, kind)
        if isinstance(problem, _Problem):
            inputs = ["Good"] * len(args)
            inputs[at] = problem.status
            raise _Bad("BadInvalidArgument", problem.status, inputs)
        data[name] = problem
    return data


class _Problem:
    """Why one typed input is refused: its status (rule 2)."""

    def __init__(self, status: str) -> None:
        self.status = status


def _field(arg: Any, kind: str) -> Any:
    """One typed input's value, or the :class:`_Problem` that refuses it."""
    ua = _ua()
    variant = getattr(arg, "VariantType", None)
    value = getattr(arg, "Value", None)
    takes = tuple(getattr(ua.VariantType, name) for name in _TAKES.get(kind, ("String",)))
    if variant not in takes or value is None or isinstance(value, list | tuple):
        return _Problem("BadTypeMismatch")
    if isinstance(value, float) and not math.isfinite(value):
        return _Problem("BadOutOfRange")
    if kind == "float" and variant != ua.VariantType.Double and variant != ua.VariantType.Float:
        return float(value)
    if not isinstance(value, str):
        return value
    if len(value) > MAX_DATA or len(value.encode("utf-8", "surrogatepass")) > MAX_DATA:
        return _Problem("BadOutOfRange")
    if kind not in _SHAPES:
        return value
    try:
        parsed = json.loads(value, parse_constant=_not_finite, parse_float=_finite)
    except (ValueError, RecursionError):
        return _Problem("BadInvalidArgument")
    shape = _SHAPES[kind]
    if shape is not None and not isinstance(parsed, shape):
        return _Problem("BadTypeMismatch")
    return parsed


def _not_finite(name: str) -> Any:
    raise ValueError(f"{name} is not a number data may hold")


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text} is not finite")
    return value


class Calls:
    """The handlers of one server's methods, over its System (rules 1-4)."""

    def __init__(self, system: System) -> None:
        self.system = system

    def checked(self, holder: Any, takes: bool | Reader, run: Run) -> Callable[..., Any]:
        """A handler for a method of ``holder`` (a node id): rules 1-3, then ``run``.
        ``takes``: whether it has the ``Data`` input, or the reader of its typed inputs."""
        ua = _ua()

        def status(name: str, *inputs: str) -> Any:
            result = ua.CallMethodResult()
            result.StatusCode = ua.StatusCode(getattr(ua.StatusCodes, name))
            result.InputArgumentResults = [
                ua.StatusCode(getattr(ua.StatusCodes, i)) for i in inputs
            ]
            return result

        async def call(parent: Any, *args: Any) -> Any:
            if parent != holder:
                return status("BadMethodInvalid")
            try:
                data = takes(args) if callable(takes) else read_data(args, takes)
            except _Bad as bad:
                return status(bad.call, *(bad.inputs or [bad.argument] * len(args)))
            try:
                return await run(data, Origin("opcua", caller()))
            except CommandRefused:
                return status("BadUserAccessDenied")

        return call

    def event(
        self, device: str, event: str, holder: Any, fields: tuple[tuple[str, str], ...] = ()
    ) -> Callable[..., Any]:
        """A device's method: ``[Handled, Reason]`` (server rule 3); its inputs are the
        event's declared ``fields`` when it has some, else ``Data`` (rule 2)."""
        ua = _ua()

        async def run(data: Any, origin: Origin) -> list[Any]:
            outcome = await self.outcome(device, event, data, origin)
            handled = outcome == Outcome.HANDLED
            return [
                ua.Variant(handled, ua.VariantType.Boolean),
                ua.Variant("" if handled else str(outcome), ua.VariantType.String),
            ]

        if not fields:
            return self.checked(holder, True, run)
        return self.checked(holder, functools.partial(read_fields, fields=fields), run)

    async def outcome(self, device: str, event: str, data: Any, origin: Origin) -> str:
        """Rule 4: submit ``event`` at the System's door and wait for the device's step:
        ``handled`` or why not. A refusal of the commands policy is raised (rule 3), any
        other said."""
        try:
            return await self.system.submit(device, event, data, origin=origin)
        except CommandRefused:
            raise
        except StatectlError as exc:
            return str(exc)
