"""The Modbus driver: coils, discrete inputs and registers on Modbus TCP or RTU.

``pymodbus`` (the ``modbus`` extra) is imported when a driver binds, so this
package loads without it. docs/drivers.md describes the options.
"""

from statectl.run.devices.modbus.driver import LOG, QUIET, ModbusIO, OutageFilter
from statectl.run.devices.modbus.options import Action, Register, modbus_option_problems

__all__ = [
    "LOG",
    "QUIET",
    "Action",
    "ModbusIO",
    "OutageFilter",
    "Register",
    "modbus_option_problems",
]
