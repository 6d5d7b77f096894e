"""Implementations under test: one small protocol, one adapter per kind of implementation.

A generated suite checks *an implementation* of the tables, not statectl's runtime
only. Everything a test does to a device goes through :class:`Implementation`:

Rules:
1. ``send(event, data)`` processes one event to completion and returns what the
   implementation showed (:class:`Observed`): why nothing happened, the invoke numbers
   issued (when it shows them), the device API calls it made (observer method and
   arguments, when it shows them), the driver's own API calls per notification it
   served (``served``: statectl's runtime reads them from the driver's API log) and the
   events it took by itself meanwhile.
2. ``states()`` is the active atomic states in document order.
3. ``advance(seconds)`` lets time run (a simulated clock, or a bounded wall wait for a
   real device); what the implementation did meanwhile is the returned ``Observed``.
4. ``inject_fault(detail)`` makes the *device* report a fault (its monitor must find it);
   ``monitoring()`` says which states' monitors run and how often they polled;
   ``restart()`` stops the device as a power loss would and resumes it from what it
   persisted (a journal), returning what resuming did; ``stall()`` silences the device's
   own reports. An implementation that cannot do one raises :class:`Unsupported`, and
   the test that needs it is skipped saying why.
5. An adapter is chosen by a spec (:func:`parse_spec`): ``runtime`` (statectl's
   runtime with the test's driver), ``cpp:PROGRAM`` (the harness program
   ``statectl codegen --harness`` writes, over stdin/stdout), ``opcua:URL`` (a device
   served over OPC UA as ``statectl run --opcua`` serves it) and
   ``python:MODULE:CLASS`` (a hand-written class, :mod:`.python`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from statectl.kernel.errors import StatectlError

__all__ = [
    "KINDS",
    "ApiMade",
    "Call",
    "Implementation",
    "Observed",
    "Served",
    "Unsupported",
    "parse_spec",
]

#: The adapter kinds a ``--statectl-impl`` spec may name.
KINDS = ("runtime", "cpp", "opcua", "python")


class Unsupported(StatectlError):
    """The implementation cannot do what a test asks (inject a fault, restart, ...)."""


@dataclass(frozen=True, slots=True)
class Call:
    """One device API call: the observer method the tables name, with its arguments."""

    method: str
    data: Any = None

    def __str__(self) -> str:
        return f"{self.method}({'' if self.data is None else repr(self.data)})"


@dataclass(frozen=True, slots=True)
class ApiMade:
    """One call a driver really made to its device: ``SimMotor.move_to(5.0)``."""

    owner: str
    function: str
    args: tuple[Any, ...] = ()

    def __str__(self) -> str:
        return f"{self.owner}.{self.function}({', '.join(map(repr, self.args))})"


@dataclass(frozen=True, slots=True)
class Served:
    """The API calls a driver made serving one notification (``method`` and its event's
    ``data``), or by itself between notifications (``method`` None)."""

    method: str | None
    data: Any
    calls: tuple[ApiMade, ...]


@dataclass(frozen=True, slots=True)
class Observed:
    """What an implementation showed for one event or one stretch of time (rule 1)."""

    #: why the event changed nothing (the kernel's words, or ``unhandled`` when the
    #: implementation does not say why); ``None``: handled
    unhandled: str | None = None
    #: (invoke number, observer method) issued; ``None``: the implementation does not show them
    invokes: tuple[tuple[int, str], ...] | None = None
    #: the API calls made; ``None``: the implementation does not show them
    calls: tuple[Call, ...] | None = None
    #: events the implementation took by itself (completions, faults, timeouts, recovery)
    events: tuple[str, ...] = ()
    #: every (event, reason) left unhandled on the way (``statectl_strict`` reads it)
    unhandled_all: tuple[tuple[str, str], ...] = ()
    #: the runtime's driver-level calls, (observer method, ``Owner.fn(args)``)
    driver_calls: tuple[tuple[str, str], ...] | None = None
    #: the driver's own API calls, per notification served (its API log); ``None``: not shown
    served: tuple[Served, ...] | None = None


@runtime_checkable
class Implementation(Protocol):
    """What a generated test needs of an implementation of the tables (rules 1-4)."""

    def send(self, event: str, data: Any = None) -> Observed: ...

    def states(self) -> tuple[str, ...]: ...

    def advance(self, seconds: float) -> Observed: ...

    def inject_fault(self, detail: str) -> None: ...

    def monitoring(self) -> Mapping[str, int]: ...

    def restart(self) -> Observed: ...

    def stall(self) -> None: ...

    def close(self) -> None: ...


def parse_spec(spec: str) -> tuple[str, str]:
    """``cpp:./motor_harness`` -> ``("cpp", "./motor_harness")``; a bad spec says what to give."""
    kind, _, rest = spec.partition(":")
    if kind not in KINDS:
        raise StatectlError(
            f"--statectl-impl {spec!r}: unknown kind {kind!r}; give runtime, cpp:PROGRAM, "
            "opcua:opc.tcp://HOST:PORT or python:MODULE:CLASS"
        )
    if kind == "runtime" and rest:
        raise StatectlError(f"--statectl-impl {spec!r}: runtime takes nothing after it")
    if kind != "runtime" and not rest:
        raise StatectlError(f"--statectl-impl {spec!r}: {kind} needs what to test after '{kind}:'")
    if kind == "python" and rest.count(":") != 1:
        raise StatectlError(
            f"--statectl-impl {spec!r}: give python:MODULE:CLASS (e.g. python:mymotor:Motor)"
        )
    return kind, rest
