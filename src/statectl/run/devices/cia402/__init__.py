"""CiA 402 drives over CANopen: the profile as data, the driver, a simulated drive.

``canopen`` and ``python-can`` (the ``canopen`` extra) are imported when a driver
opens its bus, so this package loads without them.
"""

from statectl.run.devices.cia402.driver import Cia402Driver, Cia402SimDriver
from statectl.run.devices.cia402.profile import PowerState, decode, next_command

__all__ = ["Cia402Driver", "Cia402SimDriver", "PowerState", "decode", "next_command"]
