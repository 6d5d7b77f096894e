"""statectl: state control for industrial robot devices (Ha, Yoo and Lee's method).

The stable API (docs/api.md) is what this package exports: ``load`` and ``check``
a device file, run it as a :class:`Subject` (one device) or a :class:`System`
(many, one owner), on a :class:`SimClock` or :class:`WallClock`, ``connect`` a
driver made by ``make_driver``, hear typed records, catch one error root. Names
are imported on first use, so ``import statectl`` stays cheap and the kernel's
modules can be imported alone.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from statectl.kernel.errors import (
    Diagnostic,
    DiagnosticError,
    Location,
    Severity,
    StatectlError,
    UnhandledEventError,
)
from statectl.kernel.model import Chart, ControlKind, EventKind, State, StateKind, Transition

if TYPE_CHECKING:
    from statectl.api import check, load
    from statectl.front.observers import Notification, Observer
    from statectl.run.devices import DeviceDriver, connect, make_driver
    from statectl.run.door import QueueFull, Submitted
    from statectl.run.runtime import (
        EventIgnored,
        EventReceived,
        EventRejected,
        FaultDetected,
        Finished,
        InvokeIssued,
        MicrostepTaken,
        MonitorStarted,
        MonitorStopped,
        ObserverCalled,
        Record,
        SimClock,
        Started,
        StateWatcher,
        StepRecord,
        Subject,
        Taken,
        WallClock,
    )
    from statectl.run.system import DeviceSetup, System

__version__ = "0.1.0"

#: name -> module it lives in, imported when the name is first used
_LAZY = {
    "check": "statectl.api",
    "load": "statectl.api",
    "DeviceDriver": "statectl.run.devices",
    "connect": "statectl.run.devices",
    "make_driver": "statectl.run.devices",
    "Notification": "statectl.front.observers",
    "Observer": "statectl.front.observers",
    "System": "statectl.run.system",
    "DeviceSetup": "statectl.run.system",
    "QueueFull": "statectl.run.door",
    "Submitted": "statectl.run.door",
    **dict.fromkeys(
        (
            "EventIgnored",
            "EventReceived",
            "EventRejected",
            "FaultDetected",
            "Finished",
            "InvokeIssued",
            "MicrostepTaken",
            "MonitorStarted",
            "MonitorStopped",
            "ObserverCalled",
            "Record",
            "SimClock",
            "Started",
            "StateWatcher",
            "StepRecord",
            "Subject",
            "Taken",
            "WallClock",
        ),
        "statectl.run.runtime",
    ),
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'statectl' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "Chart",
    "ControlKind",
    "DeviceDriver",
    "DeviceSetup",
    "Diagnostic",
    "DiagnosticError",
    "EventIgnored",
    "EventKind",
    "EventReceived",
    "EventRejected",
    "FaultDetected",
    "Finished",
    "InvokeIssued",
    "Location",
    "MicrostepTaken",
    "MonitorStarted",
    "MonitorStopped",
    "Notification",
    "Observer",
    "ObserverCalled",
    "QueueFull",
    "Record",
    "Severity",
    "SimClock",
    "Started",
    "State",
    "StateKind",
    "StateWatcher",
    "StatectlError",
    "StepRecord",
    "Subject",
    "Submitted",
    "System",
    "Taken",
    "Transition",
    "UnhandledEventError",
    "WallClock",
    "__version__",
    "check",
    "connect",
    "load",
    "make_driver",
]
