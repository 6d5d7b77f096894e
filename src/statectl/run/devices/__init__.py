"""Device drivers: the protocol, the base class, simulated twins and driver configuration."""

from statectl.run.devices.base import Driver, connect, requested_target
from statectl.run.devices.config import (
    DRIVERS,
    DriverConfig,
    make_driver,
    resolve_driver,
)
from statectl.run.devices.motor import SimMotor
from statectl.run.devices.protocol import DeviceDriver, Report
from statectl.run.devices.stepper import SimStepper
from statectl.run.devices.twin import SimTwin, TwinNote
from statectl.run.runtime.records import ApiCall

__all__ = [
    "DRIVERS",
    "ApiCall",
    "DeviceDriver",
    "Driver",
    "DriverConfig",
    "Report",
    "SimMotor",
    "SimStepper",
    "SimTwin",
    "TwinNote",
    "connect",
    "make_driver",
    "requested_target",
    "resolve_driver",
]
