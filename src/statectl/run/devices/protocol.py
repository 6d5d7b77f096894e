"""The device driver protocol: what the runtime needs of a real device or its simulated twin.

Rules:
1. A driver is an observer (``update(Notification)``): it maps the observer
   method a notification names to one of its own API functions.
2. ``bind(report, clock)`` hands it the way back: ``report(event, data)``
   posts an event such as ``Movement completion`` to the Subject from any
   thread, and ``clock`` is the only source of time it may use.
3. ``poll_fault()`` returns a fault detail once, or ``None``; the monitor of a
   monitored state calls it on the Subject's owner.
4. ``api_log`` lists the API calls the driver made, in order, so a trace
   shows which function of which device actually ran. A driver may keep only
   the recent ones if it also counts them all in ``api_calls`` (the shipped
   drivers keep the last 1,000): the Subject then takes a notification's calls
   by that count. A driver that also has ``api_since(count)`` (the shipped base
   class does) is asked for them directly, without reading its log.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol, runtime_checkable

from statectl.front.observers import Observer
from statectl.run.runtime.clock import Clock
from statectl.run.runtime.records import ApiCall

__all__ = ["DeviceDriver", "Report"]

#: Posts an event (with its data) back to the Subject; safe from any thread.
Report = Callable[[str, Any], None]


@runtime_checkable
class DeviceDriver(Observer, Protocol):
    """A device with its API, real or simulated."""

    def bind(self, report: Report, clock: Clock) -> None: ...

    def poll_fault(self) -> str | None: ...

    @property
    def api_log(self) -> Sequence[ApiCall]: ...
