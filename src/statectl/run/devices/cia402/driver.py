"""Cia402Driver: the paper's Motor observer calls on a real CiA 402 drive over CANopen.

Rules:
1. ``bind`` opens the bus (python-can ``interface``/``channel``), reads the
   drive's object dictionary from the EDS, checks the device type by SDO
   (profile 402), sets profile position mode (0x6060 = 1) and reads 0x6061
   until it shows it, takes the PDO mapping from the EDS and starts the node
   (NMT Operational). A drive that does not answer then is a
   :class:`~statectl.kernel.errors.StatectlError` saying so.
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
6. Each call runs in one mode of operation: ``Movement``/``Initialization``/
   ``Error`` in profile position, ``Homing()`` in homing (0x6098 method, 0x6099
   speeds; bit 4 starts it, bits 12 + 10 say attained, bit 13 a homing error),
   ``Velocity()`` in profile velocity (0x60FF; bit 10 says reached). A call in
   another mode than the drive's first writes 0x6060 and its parameters by SDO
   on a thread of its own (an SDO answer must never wait for the driver's lock)
   and reads 0x6061 back; a mode not shown within ``mode_timeout`` s is a fault.
7. A drive fault is one episode from the EMCY or the first Fault reaction
   active / Fault statusword until the drive leaves Fault: one detail for the
   model, whatever order the frames come in.
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from statectl.kernel.errors import MissingExtra, StatectlError
from statectl.run.devices.base import Driver, finite_number, requested_target
from statectl.run.devices.cia402.profile import (
    CW_ENABLE_OPERATION,
    CW_HOMING_START,
    CW_NEW_SETPOINT,
    HOMING,
    MODES,
    PROFILE_POSITION,
    PROFILE_VELOCITY,
    SW_HOMING_ATTAINED,
    SW_HOMING_ERROR,
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
_FAULTED = (PowerState.FAULT, PowerState.FAULT_REACTION)
#: The defaults the driver and its simulated variant share (one place: they cannot drift).
SCALE, HOMING_METHOD, HOMING_SPEEDS = 1000.0, 35, (1.0, 0.1)
HEARTBEAT_TIMEOUT = STALE_AFTER = MODE_TIMEOUT = 0.5  # seconds each
#: The calls that stop at a drive in Fault (Error() is the one that resets it).
_STOP_AT_FAULT = frozenset({"Movement", "Homing", "Velocity"})


class Cia402Driver(Driver):
    """A CiA 402 drive over CANopen: profile position, homing, profile velocity (rules 1-7)."""

    realtime: ClassVar[bool] = True  # the bus runs in wall time (the demo's WallClock)
    methods: ClassVar[dict[str, str]] = {
        "Movement": "move_to",
        "Initialization": "return_to",
        "Error": "recover",
        "Homing": "home",
        "Velocity": "run_at",
    }
    completions: ClassVar[dict[str, str]] = {
        "Movement": "Movement completion",
        "Initialization": "Initialization completion",
        "Error": "Error completion",
        "Homing": "Homing completion",
        "Velocity": "Velocity completion",
    }

    def __init__(
        self,
        *,
        interface: str = "virtual",
        channel: str = "statectl-cia402",
        node_id: int = 1,
        eds: str | None = None,
        bitrate: int | None = None,
        scale: float = SCALE,
        window: int = 10,
        sdo_timeout: float = 0.5,
        heartbeat_timeout: float = HEARTBEAT_TIMEOUT,
        stale_after: float = STALE_AFTER,
        mode_timeout: float = MODE_TIMEOUT,
        homing_method: int = HOMING_METHOD,
        homing_speeds: Sequence[float] = HOMING_SPEEDS,
    ) -> None:
        super().__init__()
        self.interface, self.channel, self.node_id = interface, channel, node_id
        self.mode_timeout = mode_timeout
        self.homing_method = homing_method
        self.homing_speeds = (float(homing_speeds[0]), float(homing_speeds[1]))  # units/s
        self.mode = 0  # the mode 0x6061 confirmed (rule 6)
        self._generation = 0  # counts commands: a late SDO set-up of an old one is dropped
        self._serving = "Movement"  # the observer method the current command serves
        self._velocity = 0  # counts/s asked of the drive in profile velocity
        self._episode = False  # a drive fault reported, the drive not out of Fault (rule 7)
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
        except ImportError:
            raise MissingExtra("the cia402 driver", "canopen", "canopen") from None
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
            shown = self._await_mode(node, PROFILE_POSITION)
            if shown != PROFILE_POSITION:
                raise StatectlError(
                    f"{self.where}: the drive does not show profile position mode: 0x6061 "
                    f"reads {shown} {self.mode_timeout} s after 0x6060 = 1 was written"
                )
            self.mode = PROFILE_POSITION
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
        if method == "Homing":
            return (_homing_method(data, self.homing_method),)
        if method == "Velocity":
            return (_velocity(data),)
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

    def home(self, method: int) -> None:
        """Homing(): homing mode, 0x6098 = ``method``, 0x6099 speeds, then bit 4 (rule 6)."""
        with self._lock:
            self.log_call("home", method)
            speeds = [round(v * self.scale) for v in self.homing_speeds]
            writes = [(0x6098, 0, method), (0x6099, 1, speeds[0]), (0x6099, 2, speeds[1])]
            self._start(None, HOMING, writes)

    def run_at(self, velocity: float) -> None:
        """Velocity(): profile velocity mode, 0x60FF = ``velocity`` (units/s) (rule 6)."""
        with self._lock:
            self.log_call("run_at", float(velocity))
            self._velocity = round(velocity * self.scale)
            self._start(None, PROFILE_VELOCITY, [(0x60FF, 0, self._velocity)])

    def _start(
        self,
        target: float | None,
        mode: int = PROFILE_POSITION,
        writes: Sequence[tuple[int, int, int]] = (),
    ) -> None:
        self._goal = self.actual if target is None else round(target * self.scale)
        self._serving = self.method or "Movement"
        self._generation += 1
        self._faults.clear()  # logged already; a new command starts a new episode
        if self._serving in _STOP_AT_FAULT and decode(self.statusword) in _FAULTED:
            self._bus_fault(f"{self.where}: drive in Fault at {self._serving}(); Error() resets it")
        if mode == self.mode and not writes:
            self._phase = "enable"
            self._step(self.statusword)
            return
        self._phase = "prepare"  # rule 6: the SDO set-up runs without the lock
        threading.Thread(
            target=self._prepare,
            args=(self._generation, mode, tuple(writes)),
            name="cia402-sdo",
            daemon=True,
        ).start()

    def _await_mode(self, node: Any, mode: int) -> int:
        """Read 0x6061 until it shows ``mode`` or ``mode_timeout`` passes; what it shows."""
        deadline = time.monotonic() + self.mode_timeout
        while True:
            shown = int(node.sdo[0x6061].raw)
            if shown == mode or time.monotonic() >= deadline:
                return shown
            time.sleep(0.005)

    def _prepare(self, generation: int, mode: int, writes: Sequence[tuple[int, int, int]]) -> None:
        """Rule 6: write the mode and read it back, write its parameters, then enable."""
        node, name = self.node, MODES.get(mode, str(mode))
        if node is None:
            return
        try:
            shown = mode
            if mode != self.mode:
                node.sdo[0x6060].raw = mode
                shown = self._await_mode(node, mode)
            if shown == mode:
                for index, sub, value in writes:
                    (node.sdo[index][sub] if sub else node.sdo[index]).raw = value
        except Exception as exc:  # an SDO abort or timeout, a bus that refuses the frame
            self._prepared(generation, f"SDO set-up of {name} mode failed ({exc})")
            return
        if shown != mode:
            self._prepared(
                generation,
                f"{name} mode (0x6060 = {mode}) not confirmed: 0x6061 still reads {shown} "
                f"after {self.mode_timeout} s",
            )
            return
        self.mode = mode
        self._prepared(generation, None)

    def _prepared(self, generation: int, failure: str | None) -> None:
        with self._lock:
            if generation != self._generation:
                return  # a newer command took over
            if failure is not None:
                self._phase = None
                self._bus_fault(f"{self.where}: {failure}")
                return
            self._phase = "enable"
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
        if phase is None or phase == "prepare":
            return
        state = decode(word)
        if state in _FAULTED and self._serving in _STOP_AT_FAULT:
            return  # the fault is reported; Error() resets it
        if state is not PowerState.OPERATION_ENABLED:
            command = next_command(state, self._cw)
            if command is not None and command != self._cw:
                self._send(command)
            return
        if self.mode == HOMING:
            self._step_homing(phase, word)
        elif self.mode == PROFILE_VELOCITY:
            if word & SW_TARGET_REACHED:  # in profile velocity: the velocity is reached
                self._phase = None
                self.complete(self._serving, {"velocity": self._velocity / self.scale})
        elif phase == "enable":
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
            self.complete(self._serving, {"position": self.actual / self.scale})

    def _step_homing(self, phase: str, word: int) -> None:
        """Rule 6 in homing mode: bit 4 up, then bits 12 + 10 (attained); a bit 12 still
        set from an earlier homing must clear first, so it is not taken for this one."""
        if phase == "enable":
            self._phase = "homing-start" if word & SW_HOMING_ATTAINED else "homing"
            self._send(CW_ENABLE_OPERATION | CW_HOMING_START)
        elif word & SW_HOMING_ERROR:
            self._phase = None
            self._send(CW_ENABLE_OPERATION)
            self._bus_fault(f"{self.where}: homing error (statusword 0x{word:04X} bit 13)")
        elif phase == "homing-start" and not word & SW_HOMING_ATTAINED:
            self._phase = "homing"
        elif phase == "homing" and word & SW_HOMING_ATTAINED and word & SW_TARGET_REACHED:
            self._phase = None
            self._send(CW_ENABLE_OPERATION)
            self.complete(self._serving, {"position": self.actual / self.scale})

    def _on_tpdo(self, pdo: Any) -> None:
        data = bytes(pdo.data)
        if len(data) < _RPDO.size:
            return
        word, actual = _RPDO.unpack_from(data)
        with self._lock:
            self._last_status = time.monotonic()
            self._stale_reported = False
            self.statusword, self.actual = word, actual
            state = decode(word)
            if state in _FAULTED:  # rule 7: Fault reaction active or Fault, one episode
                name = "Fault" if state is PowerState.FAULT else "Fault reaction active"
                self._bus_fault(f"{self.where}: drive in {name} (statusword 0x{word:04X})", True)
            else:
                self._episode = False
            self._step(word)

    def _on_emcy(self, entry: Any) -> None:
        code = int(entry.code)
        if code == 0:
            LOG.info("%s: EMCY error reset", self.where)
            return
        maker = bytes(entry.data).hex(" ").upper() or "none"
        self._bus_fault(
            f"{self.where}: EMCY 0x{code:04X} ({entry.get_desc() or 'no description'}), "
            f"error register 0x{int(entry.register):02X}, manufacturer bytes {maker}",
            True,
        )

    def _on_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._lock:
            self._last_heartbeat = time.monotonic()
            self._silent_reported = False

    def _bus_fault(self, detail: str, drive: bool = False) -> None:
        """One fault detail for the model; ``drive``: of the drive's fault episode (rule 7)."""
        with self._lock:
            if detail in self._faults or (drive and self._episode):
                return
            LOG.warning("%s", detail)
            self._episode = self._episode or drive
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


def _homing_method(data: Any, default: int) -> int:
    """Homing()'s method: ``{method: n}`` in the event's data, else the option."""
    method = data.get("method", default) if isinstance(data, dict) else default
    if not (type(method) is int and -128 <= method <= 127):
        raise StatectlError(f"a homing method is a number -128..127 (0x6098; got {method!r})")
    return method


def _velocity(data: Any) -> float:
    """Velocity()'s target: ``{velocity: v}`` in units/s, a finite number."""
    v = data.get("velocity") if isinstance(data, dict) else None
    if v is None or not finite_number(v):
        raise StatectlError(
            f"Velocity needs a finite number: event data {{velocity: <units/s>}} (got {data!r})"
        )
    return float(v)


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
        scale: float = SCALE,
        heartbeat_timeout: float = HEARTBEAT_TIMEOUT,
        stale_after: float = STALE_AFTER,
        mode_timeout: float = MODE_TIMEOUT,
        homing_method: int = HOMING_METHOD,
        homing_speeds: Sequence[float] = HOMING_SPEEDS,
        fault_reaction: float = 0.05,
        acceleration: float = 200000.0,
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
            mode_timeout=mode_timeout,
            homing_method=homing_method,
            homing_speeds=homing_speeds,
        )
        self.speed = speed
        self.fault_reaction, self.acceleration = fault_reaction, acceleration
        self.drive: Any = None  # the SimDrive, once open

    def open(self) -> None:
        from statectl.run.devices.cia402.sim import SimDrive

        self.drive = SimDrive(
            channel=self.channel,
            node_id=self.node_id,
            speed=self.speed,
            fault_reaction=self.fault_reaction,
            acceleration=self.acceleration,
        )
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
