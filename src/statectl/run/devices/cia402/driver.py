"""Cia402Driver: the paper's Motor observer calls on a real CiA 402 drive over CANopen.

Rules:
1. ``bind`` opens the bus (python-can ``interface``/``channel``), reads the
   drive's object dictionary from the EDS, checks the device type by SDO
   (profile 402), sets profile position mode (0x6060 = 1), takes the PDO
   mapping from the EDS and starts the node (NMT Operational). A drive that
   does not answer then is a :class:`~statectl.kernel.errors.StatectlError` saying so.
2. ``Movement()``/``Initialization()``/``Error()`` walk the power state machine
   by controlword on RPDO1, one transition per statusword seen on TPDO1
   (:func:`~statectl.run.devices.cia402.profile.next_command`: 0x06, 0x07, 0x0F;
   from Fault 0x80 on bit 7's rising edge), then hand the target over with the
   set-point handshake (bit 4 up, bit 12 acknowledges, bit 4 down). Bit 10
   (target reached) with the position in the window reports the completion.
3. Faults become one detail each that :meth:`poll_fault` returns (so the
   monitored state raises its fault event) and one log line on the
   ``statectl.run.devices.cia402`` logger: an EMCY, a statusword in Fault, no
   heartbeat for ``heartbeat_timeout`` s, no TPDO for ``stale_after`` s, a frame
   the bus refuses (bus-off, a closed bus). None of them is a traceback.
4. Bus time is wall time (the bus runs on it); the Subject's clock times only
   the API log.
5. Positions in the model are units; the drive counts ``scale`` counts per unit.
"""

from __future__ import annotations

import logging
import struct
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from statectl.kernel.errors import StatectlError
from statectl.run.devices.base import Driver, requested_target
from statectl.run.devices.cia402.profile import (
    CW_ENABLE_OPERATION,
    CW_NEW_SETPOINT,
    SW_FAULT,
    SW_SETPOINT_ACK,
    SW_TARGET_REACHED,
    PowerState,
    decode,
    next_command,
)
from statectl.run.devices.protocol import Report
from statectl.run.runtime.clock import Clock

if TYPE_CHECKING:
    import canopen

__all__ = ["LOG", "Cia402Driver"]

LOG = logging.getLogger("statectl.run.devices.cia402")
_RPDO = struct.Struct("<Hi")
PROFILE_POSITION = 1


class Cia402Driver(Driver):
    """A CiA 402 drive in profile position mode, driven over CANopen (rules 1-5)."""

    realtime: ClassVar[bool] = True  # the bus runs in wall time (the demo's WallClock)
    methods: ClassVar[dict[str, str]] = {
        "Movement": "move_to",
        "Initialization": "return_to",
        "Error": "recover",
    }
    completions: ClassVar[dict[str, str]] = {
        "Movement": "Movement completion",
        "Initialization": "Initialization completion",
        "Error": "Error completion",
    }

    def __init__(
        self,
        *,
        interface: str = "virtual",
        channel: str = "statectl-cia402",
        node_id: int = 1,
        eds: str | None = None,
        bitrate: int | None = None,
        scale: float = 1000.0,
        window: int = 10,
        sdo_timeout: float = 0.5,
        heartbeat_timeout: float = 0.5,
        stale_after: float = 0.5,
    ) -> None:
        super().__init__()
        self.interface, self.channel, self.node_id = interface, channel, node_id
        self.eds = eds
        self.bitrate = bitrate
        self.scale, self.window = float(scale), window
        self.sdo_timeout = sdo_timeout
        self.heartbeat_timeout, self.stale_after = heartbeat_timeout, stale_after
        self.network: canopen.Network | None = None
        self.node: canopen.RemoteNode | None = None
        self.statusword = 0
        self.actual = 0  # counts
        self.previous = 0.0  # where the last movement started, in units
        self._cw = 0
        self._goal: int | None = None  # counts
        self._phase: str | None = None  # enable, setpoint, moving
        self._faults: list[str] = []
        self._last_heartbeat = 0.0
        self._last_status = 0.0
        self._silent_reported = False
        self._stale_reported = False
        self.sent: list[int] = []  # every controlword sent, in order (tests, the bench)

    # -- set-up ---------------------------------------------------------------------------------

    @property
    def where(self) -> str:
        return f"CiA 402 node {self.node_id} on {self.interface}:{self.channel}"

    def bind(self, report: Report, clock: Clock) -> None:
        super().bind(report, clock)
        if self.network is None:
            self.open()

    def open(self) -> None:
        """Rule 1: bus, object dictionary, SDO set-up, PDO mapping, NMT start."""
        try:
            import can
            import canopen
            from canopen.sdo.exceptions import SdoError
        except ImportError as exc:
            raise StatectlError(
                f"the cia402 driver needs the canopen extra ({exc}); "
                "pip install 'statectl[canopen]'"
            ) from None
        from statectl.run.devices.cia402.sim import packaged_eds

        eds = Path(self.eds) if self.eds else packaged_eds()
        if not eds.is_file():
            raise StatectlError(f"{self.where}: no EDS file {eds}; set options.eds to its path")
        network = canopen.Network()
        try:
            kwargs: dict[str, Any] = {"interface": self.interface, "channel": self.channel}
            if self.bitrate is not None:
                kwargs["bitrate"] = self.bitrate
            network.connect(**kwargs)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise StatectlError(f"{self.where}: cannot open the bus ({exc})") from None
        try:
            node = network.add_node(self.node_id, str(eds))
            node.sdo.RESPONSE_TIMEOUT = self.sdo_timeout
            node.sdo.MAX_RETRIES = 1  # one try: canopen counts the first as a retry
            device_type = int(node.sdo[0x1000].raw)
            if device_type & 0xFFFF != 402:
                raise StatectlError(
                    f"{self.where}: device type 0x{device_type:08X} is not a CiA 402 drive"
                )
            node.sdo[0x6060].raw = PROFILE_POSITION
            node.tpdo.read(from_od=True)  # type: ignore[no-untyped-call]
            node.rpdo.read(from_od=True)  # type: ignore[no-untyped-call]
        except SdoError as exc:
            network.disconnect()
            raise StatectlError(
                f"{self.where}: the drive does not answer SDO (timeout {self.sdo_timeout} s: "
                f"{exc}); check node id, wiring and power"
            ) from None
        except Exception as exc:  # a bad EDS is any error the parser raises
            network.disconnect()
            if isinstance(exc, StatectlError):
                raise
            raise StatectlError(f"{self.where}: cannot use EDS {eds} ({exc})") from None
        self.network, self.node = network, node
        node.tpdo[1].add_callback(self._on_tpdo)
        node.emcy.add_callback(self._on_emcy)
        network.subscribe(0x700 + self.node_id, self._on_heartbeat)
        now = time.monotonic()
        self._last_heartbeat = self._last_status = now
        node.nmt.state = "OPERATIONAL"

    def close(self) -> None:
        """Leave the bus (idempotent)."""
        with self._lock:
            network, self.network = self.network, None
        if network is not None:
            network.disconnect()

    # -- the observer calls ---------------------------------------------------------------------

    def arguments(self, method: str, data: Any) -> tuple[Any, ...]:
        if method == "Movement":
            return (requested_target(self.actual / self.scale, data),)
        return (self.previous,)

    def move_to(self, target: float) -> None:
        with self._lock:
            self.log_call("move_to", float(target))
            self.previous = self.actual / self.scale
            self._start(target)

    def return_to(self, position: float) -> None:
        with self._lock:
            self.log_call("return_to", float(position))
            self._start(position)

    def recover(self, position: float) -> None:
        """Error(): reset the fault (bit 7 rising), enable again, go back to ``position``."""
        with self._lock:
            self.log_call("recover", float(position))
            self._start(position)

    def _start(self, target: float) -> None:
        self._goal = round(target * self.scale)
        self._phase = "enable"
        self._faults.clear()  # logged already; a new command starts a new episode
        if self.method == "Movement" and decode(self.statusword) is PowerState.FAULT:
            self._bus_fault(f"{self.where}: drive in Fault at Movement(); Error() resets it")
        self._step(self.statusword)

    # -- the bus side ---------------------------------------------------------------------------

    def _send(self, cw: int, target: int | None = None) -> None:
        node, network = self.node, self.network
        if node is None or network is None:
            self._bus_fault(f"{self.where}: the bus is closed; cannot send controlword 0x{cw:02X}")
            return
        goal = target if target is not None else (self._goal or 0)
        try:
            rpdo = node.rpdo[1]
            network.send_message(rpdo.cob_id, _RPDO.pack(cw, goal))
        except Exception as exc:  # python-can raises CanError; a dead socket OSError
            self._bus_fault(f"{self.where}: the bus refused controlword 0x{cw:02X} ({exc})")
            return
        self._cw = cw
        self.sent.append(cw)

    def _step(self, word: int) -> None:
        """One statusword seen: the next controlword of the walk (rule 2)."""
        phase = self._phase
        if phase is None:
            return
        state = decode(word)
        if state is PowerState.FAULT and self.method == "Movement":
            return  # the fault is reported; Error() resets it
        if state is not PowerState.OPERATION_ENABLED:
            command = next_command(state, self._cw)
            if command is not None and command != self._cw:
                self._send(command)
            return
        if phase == "enable":
            self._phase = "setpoint"
            self._send(CW_ENABLE_OPERATION | CW_NEW_SETPOINT, self._goal)
        elif phase == "setpoint" and word & SW_SETPOINT_ACK:
            self._phase = "moving"
            self._send(CW_ENABLE_OPERATION, self._goal)
        elif (
            phase == "moving"
            and not word & SW_SETPOINT_ACK
            and word & SW_TARGET_REACHED
            and self._goal is not None
            and abs(self.actual - self._goal) <= self.window
        ):
            self._phase = None
            method = self.method or "Movement"
            self.complete(method, {"position": self.actual / self.scale})

    def _on_tpdo(self, pdo: Any) -> None:
        data = bytes(pdo.data)
        if len(data) < _RPDO.size:
            return
        word, actual = _RPDO.unpack_from(data)
        with self._lock:
            self._last_status = time.monotonic()
            self._stale_reported = False
            fault_now = word & SW_FAULT and not self.statusword & SW_FAULT
            self.statusword, self.actual = word, actual
            if fault_now and decode(word) is PowerState.FAULT:
                self._bus_fault(f"{self.where}: drive in Fault (statusword 0x{word:04X})")
            self._step(word)

    def _on_emcy(self, entry: Any) -> None:
        code = int(entry.code)
        if code == 0:
            LOG.info("%s: EMCY error reset", self.where)
            return
        self._bus_fault(f"{self.where}: EMCY 0x{code:04X} ({entry.get_desc() or 'no description'})")

    def _on_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._lock:
            self._last_heartbeat = time.monotonic()
            self._silent_reported = False

    def _bus_fault(self, detail: str) -> None:
        with self._lock:
            if detail in self._faults:
                return
            LOG.warning("%s", detail)
            if not self._faults:  # one fault per episode: an EMCY and its Fault are one
                self._faults.append(detail)

    # -- faults ---------------------------------------------------------------------------------

    def poll_fault(self) -> str | None:
        """An injected fault, then bus faults in the order seen, then silence (rule 3)."""
        injected = super().poll_fault()
        if injected is not None:
            return injected
        with self._lock:
            if self._faults:
                return self._faults.pop(0)
            if self.network is None:
                return None
            now = time.monotonic()
            quiet = now - self._last_heartbeat
            if quiet > self.heartbeat_timeout and not self._silent_reported:
                self._silent_reported = True
                detail = (
                    f"{self.where}: no heartbeat for {quiet:.2f} s; the drive stopped answering"
                )
                LOG.warning("%s", detail)
                return detail
            stale = now - self._last_status
            if stale > self.stale_after and not self._stale_reported:
                self._stale_reported = True
                detail = f"{self.where}: statusword stale, no TPDO for {stale:.2f} s"
                LOG.warning("%s", detail)
                return detail
        return None


class Cia402SimDriver(Cia402Driver):
    """The CiA 402 driver with its own simulated drive on a private virtual bus.

    ``inject_fault`` makes the simulated drive fault (EMCY 0x7300, then Fault), so
    a fault reaches the model by the same frames a real drive sends.
    """

    _count: ClassVar[int] = 0

    def __init__(
        self,
        *,
        node_id: int = 1,
        speed: float = 20000.0,
        scale: float = 1000.0,
        heartbeat_timeout: float = 0.5,
        stale_after: float = 0.5,
    ) -> None:
        Cia402SimDriver._count += 1
        channel = f"statectl-cia402-sim-{Cia402SimDriver._count}"
        super().__init__(
            interface="virtual",
            channel=channel,
            node_id=node_id,
            scale=scale,
            heartbeat_timeout=heartbeat_timeout,
            stale_after=stale_after,
        )
        self.speed = speed
        self.drive: Any = None  # the SimDrive, once open

    def open(self) -> None:
        from statectl.run.devices.cia402.sim import SimDrive

        self.drive = SimDrive(channel=self.channel, node_id=self.node_id, speed=self.speed)
        try:
            super().open()
        except StatectlError:
            self.drive.stop()
            raise

    def close(self) -> None:
        super().close()
        if self.drive is not None:
            self.drive.stop()
            self.drive = None

    def inject_fault(self, detail: str, after: float | None = None) -> None:
        """Fault the simulated drive ``after`` seconds from now (EMCY, then Fault)."""
        drive = self.drive
        if drive is None:
            raise StatectlError("Cia402SimDriver is not open; bind() it first")
        self.clock.call_later(after or 0.0, lambda: drive.fault(0x7300, detail))
