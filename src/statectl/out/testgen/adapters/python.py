"""A hand-written Python class as the implementation under test (``python:MODULE:CLASS``).

The class has its own state logic (a vendor's driver, a prototype); statectl knows
nothing of it but this small contract:

- ``Class(api)``: ``api`` is the device API the tables name; the class calls
  ``api.Movement(data)`` where the tables notify ``Movement()`` (its data: the event's).
- ``send(event, data)``: take one event; return ``None`` or ``True`` when handled,
  ``False`` when it changed nothing, or the reason text (``declared ignored``, ...).
- ``states``: the active atomic states (a sequence of names, or one name).
- optional: ``advance(seconds)`` returning the events the class took by itself meanwhile
  (its completions, a fault its monitor raised); ``inject_fault(detail)``;
  ``monitoring()`` (state -> polls so far); ``restart()`` returning the events resuming
  took; ``stall()``. A test needing one the class lacks is skipped.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

from statectl.kernel.errors import StatectlError
from statectl.out.testgen.adapters import Call, Observed, Unsupported

__all__ = ["ApiRecorder", "PythonImpl", "load_class"]


class ApiRecorder:
    """The ``api`` a class is given: every method called on it is a recorded API call."""

    def __init__(self) -> None:
        self.calls: list[Call] = []

    def __getattr__(self, method: str) -> Any:
        if method.startswith("_"):
            raise AttributeError(method)

        def call(data: Any = None) -> None:
            self.calls.append(Call(method, data))

        return call


def load_class(spec: str) -> type:
    """``mymotor:Motor`` -> the class; a missing module or class is one clear error."""
    module, _, name = spec.partition(":")
    try:
        found = getattr(importlib.import_module(module), name)
    except ImportError as exc:
        raise StatectlError(f"python:{spec}: cannot import {module!r} ({exc})") from None
    except AttributeError:
        raise StatectlError(f"python:{spec}: module {module!r} has no {name!r}") from None
    if not isinstance(found, type):
        raise StatectlError(f"python:{spec}: {name!r} is not a class")
    return found


class PythonImpl:
    """The :class:`~statectl.out.testgen.adapters.Implementation` of a hand-written class."""

    def __init__(self, cls: type) -> None:
        self.api = ApiRecorder()
        self.name = cls.__name__
        self.obj = cls(self.api)

    def _optional(self, name: str) -> Any:
        found = getattr(self.obj, name, None)
        if not callable(found):
            raise Unsupported(f"{self.name} has no {name}()")
        return found

    def _observed(self, outcome: Any = None, events: Any = ()) -> Observed:
        calls = tuple(self.api.calls)
        self.api.calls.clear()
        if outcome is None or outcome is True:
            reason = None
        elif outcome is False:
            reason = "unhandled"
        else:
            reason = str(outcome)
        return Observed(unhandled=reason, calls=calls, events=tuple(events or ()))

    def states(self) -> tuple[str, ...]:
        found = self.obj.states
        found = found() if callable(found) else found
        return (found,) if isinstance(found, str) else tuple(found)

    def send(self, event: str, data: Any = None) -> Observed:
        self.api.calls.clear()
        return self._observed(self.obj.send(event, data))

    def advance(self, seconds: float) -> Observed:
        self.api.calls.clear()
        return self._observed(None, self._optional("advance")(seconds))

    def inject_fault(self, detail: str) -> None:
        self._optional("inject_fault")(detail)

    def monitoring(self) -> Mapping[str, int]:
        found: Mapping[str, int] = self._optional("monitoring")()
        return found

    def restart(self) -> Observed:
        self.api.calls.clear()
        return self._observed(None, self._optional("restart")())

    def stall(self) -> None:
        self._optional("stall")()

    def close(self) -> None:
        closing = getattr(self.obj, "close", None)
        if callable(closing):
            closing()
