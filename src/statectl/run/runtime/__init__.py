"""The runtime around the pure kernel: clock, Subject (owner + queue), monitors, trace records."""

from statectl.run.runtime.clock import Clock, SimClock, Timer, WallClock
from statectl.run.runtime.hooks import ApiLogging, Listener, Policy, StateWatcher
from statectl.run.runtime.monitors import DEFAULT_PERIOD, FaultSource, Monitor, attach_monitors
from statectl.run.runtime.records import (
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
from statectl.run.runtime.subject import Subject
from statectl.run.runtime.trace import TraceWriter, format_data, format_record

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
