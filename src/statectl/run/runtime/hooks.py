"""What can hook a running device, as types: listeners, step listeners, watchers, loggers.

Each hook hears less than the one before it and costs less (docs/runtime.md, "One
path, and hooks that cost nothing when unused"): a record listener gets every typed
record, a step listener each event's outcome, a :class:`StateWatcher` only the states
it watches. None of them builds a record it did not ask for.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Literal, Protocol, runtime_checkable

from statectl.run.runtime.records import ApiCall, Record

__all__ = [
    "ApiLogging",
    "ErrorHandler",
    "Listener",
    "Policy",
    "StateWatcher",
    "StepListener",
]

Policy = Literal["ignore", "error"]
Listener = Callable[[Record], None]
#: ``(event, data, outcome)`` after an event ran; outcome is ``"handled"`` or the
#: :class:`~statectl.kernel.semantics.Unhandled` reason (a ``str`` enum: stored as its value).
StepListener = Callable[[str, Any, str], None]
ErrorHandler = Callable[[BaseException], None]


class StateWatcher(Protocol):
    """Hears the states it watches entered and exited, and the end of the run; no records.

    A monitor is one: it polls its device only while its state is active. Calls
    come on the owner, inside the step, in the order a trace would show them.
    """

    def entered(self, state: str) -> None: ...
    def exited(self, state: str) -> None: ...
    def finished(self) -> None: ...


@runtime_checkable
class ApiLogging(Protocol):
    """An observer that logs the device API calls it makes (every driver does)."""

    @property
    def api_log(self) -> Sequence[ApiCall]: ...
