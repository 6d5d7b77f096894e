"""The runtime around the pure kernel: clock, Subject (owner + queue), monitors, trace records."""

from statectl.runtime.clock import Clock, SimClock, Timer, WallClock
from statectl.runtime.monitors import DEFAULT_PERIOD, FaultSource, Monitor, attach_monitors
from statectl.runtime.records import (
    ApiCall,
    EventIgnored,
    EventReceived,
    EventRejected,
    FaultDetected,
    Finished,
    IgnoreReason,
    InvokeIssued,
    MicrostepTaken,
    MonitorStarted,
    MonitorStopped,
    ObserverCalled,
    Record,
    Started,
    StepRecord,
    Taken,
)
from statectl.runtime.subject import ApiLogging, Listener, Policy, StateWatcher, Subject
from statectl.runtime.trace import TraceWriter, format_data, format_record

__all__ = [
    "DEFAULT_PERIOD",
    "ApiCall",
    "ApiLogging",
    "Clock",
    "EventIgnored",
    "EventReceived",
    "EventRejected",
    "FaultDetected",
    "FaultSource",
    "Finished",
    "IgnoreReason",
    "InvokeIssued",
    "Listener",
    "MicrostepTaken",
    "Monitor",
    "MonitorStarted",
    "MonitorStopped",
    "ObserverCalled",
    "Policy",
    "Record",
    "SimClock",
    "Started",
    "StateWatcher",
    "StepRecord",
    "Subject",
    "Taken",
    "Timer",
    "TraceWriter",
    "WallClock",
    "attach_monitors",
    "format_data",
    "format_record",
]
