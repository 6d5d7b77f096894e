"""A simulated CiA 402 drive that speaks real CANopen, so the real driver can be tested.

Rules:
1. The drive is a ``canopen`` local node on any python-can bus (the ``virtual``
   interface in tests and the demo) serving the packaged EDS: NMT with a
   heartbeat, an SDO server, RPDO1 (controlword, target position) and TPDO1
   (statusword, position actual value, sent on change and every event timer),
   EMCY on a fault.
2. It runs the power state machine of :mod:`statectl.run.devices.cia402.profile`
   and PDOs only in NMT Operational, in the mode 0x6060 selects (0x6061 shows it,
   unless :meth:`SimDrive.hold_mode` keeps the old one):
   - profile position (1): a rising bit 4 latches the target (bit 12
     acknowledges it, bit 10 clears) and the position moves at ``speed``
     counts/s until bit 10 sets again;
   - profile velocity (3): the velocity ramps to 0x60FF at ``acceleration``
     counts/s², bit 10 set once it is there;
   - homing (6): a rising bit 4 runs the 0x6098 method: 35 and 37 take the
     position as home at once, the others search the home switch (at position
     0) at the 0x6099:1 speed; bits 12 and 10 then say homing attained. A method
     the standard does not define sets bit 13 (homing error).
3. Faults a bus has are made on purpose: :meth:`SimDrive.fault` (EMCY, Fault
   reaction active for ``fault_reaction`` s, then Fault), :meth:`SimDrive.silence`
   (no heartbeat, no PDO, no SDO answer), :meth:`SimDrive.freeze` (heartbeat
   on, no more TPDOs: a stale value).
4. Its loop is a daemon thread of its own; :meth:`SimDrive.stop` ends it and
   leaves the bus.
"""

from __future__ import annotations

import contextlib
import struct
import threading
import time
from importlib.resources import as_file, files
from pathlib import Path
from typing import Any

import can
import canopen

from statectl.run.devices.cia402.profile import (
    HOMING,
    HOMING_METHODS,
    PROFILE_POSITION,
    PROFILE_VELOCITY,
    SW_HOMING_ATTAINED,
    SW_HOMING_ERROR,
    SW_SETPOINT_ACK,
    SW_TARGET_REACHED,
    PowerState,
    drive_step,
    statusword,
)

__all__ = ["SimDrive", "packaged_eds"]

_RPDO = struct.Struct("<Hi")  # controlword, target position (RPDO1 of the EDS)
_TPDO = struct.Struct("<Hi")  # statusword, position actual value (TPDO1)


def packaged_eds() -> Path:
    """The EDS shipped in the package (``statectl/data/cia402.eds``)."""
    with as_file(files("statectl") / "data" / "cia402.eds") as path:
        return Path(path)


class SimDrive:
    """A CiA 402 servo drive on a CAN bus, simulated (rules 1-4)."""

    def __init__(
        self,
        *,
        interface: str = "virtual",
        channel: str = "statectl-cia402",
        node_id: int = 1,
        eds: str | Path | None = None,
        speed: float = 20000.0,
        heartbeat_ms: int = 100,
        event_timer: float = 0.02,
        tick: float = 0.002,
        fault_reaction: float = 0.05,
        acceleration: float = 200000.0,
    ) -> None:
        self.node_id = node_id
        self.speed = float(speed)
        self.fault_reaction = fault_reaction  # s in Fault reaction active before Fault
        self.acceleration = float(acceleration)
        self.mode = PROFILE_POSITION  # 0x6060 as written
        self.mode_display = PROFILE_POSITION  # 0x6061
        self.velocity = 0.0  # counts/s
        self.target_velocity = 0  # 0x60FF
        self.homing_method = 35  # 0x6098
        self.homing_speeds = [1000, 100]  # 0x6099:1, :2
        self._homing = False
        self._hold_mode = False
        self._reaction_until = 0.0
        self.event_timer = event_timer
        self.tick = tick
        self.heartbeat_ms = heartbeat_ms
        self.state = PowerState.SWITCH_ON_DISABLED
        self.position = 0.0
        self.target = 0
        self.error_code = 0
        self._cw = 0
        self._bits = SW_TARGET_REACHED
        self._silent = False
        self._frozen = False
        self._last_sent: tuple[int, int] | None = None
        self._last_time = 0.0
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self.network = canopen.Network()
        self.network.connect(interface=interface, channel=channel, receive_own_messages=False)
        self.node = canopen.LocalNode(node_id, str(eds or packaged_eds()))
        self.network.add_node(self.node)
        self.node.add_read_callback(self._on_read)  # type: ignore[no-untyped-call]
        self.node.add_write_callback(self._on_write)  # type: ignore[no-untyped-call]
        self.network.subscribe(0x200 + node_id, self._on_rpdo)
        self.node.nmt.state = "PRE-OPERATIONAL"
        self.node.nmt.start_heartbeat(heartbeat_ms)
        self._thread = threading.Thread(target=self._run, name="cia402-sim", daemon=True)
        self._thread.start()

    # -- faults made on purpose ----------------------------------------------------------------

    def fault(self, code: int = 0x7300, detail: str = "") -> None:
        """Fault the drive: EMCY ``code`` on the bus with ``detail`` as its five
        manufacturer-specific bytes, Fault reaction active, then Fault (rule 3)."""
        with self._lock:
            self.error_code = code
            self.state = PowerState.FAULT_REACTION
            self._reaction_until = time.monotonic() + self.fault_reaction
            self.velocity = 0.0
            self._homing = False
            self.node.emcy.send(code, 0x01, detail.encode("ascii", "replace")[:5])
            self._send_status(force=True)

    def hold_mode(self) -> None:
        """Take writes of 0x6060 but keep showing the old mode in 0x6061 (a busy drive)."""
        with self._lock:
            self._hold_mode = True

    def silence(self) -> None:
        """Stop answering: no heartbeat, no TPDO, no SDO response (a drive gone away)."""
        with self._lock:
            self._silent = True
            self.node.nmt.stop_heartbeat()  # type: ignore[no-untyped-call]
            self.network.unsubscribe(self.node.sdo.rx_cobid, self.node.sdo.on_request)

    def freeze(self) -> None:
        """Keep the heartbeat but send no more TPDOs: the driver's values go stale."""
        with self._lock:
            self._frozen = True

    def stop(self) -> None:
        """End the loop and leave the bus."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        try:
            self.node.nmt.stop_heartbeat()  # type: ignore[no-untyped-call]
        finally:
            self.network.disconnect()

    # -- the drive ------------------------------------------------------------------------------

    @property
    def statusword(self) -> int:
        return statusword(self.state, self._bits)

    def _on_read(self, *, index: int, subindex: int, od: Any) -> int | None:
        if index == 0x6041:
            return self.statusword
        if index == 0x6064:
            return int(self.position)
        if index == 0x603F:
            return self.error_code
        if index == 0x6061:
            return self.mode_display
        if index == 0x606C:
            return int(self.velocity)
        return None

    def _on_write(self, *, index: int, subindex: int, od: Any, data: bytes) -> None:
        """SDO writes: the mode (rule 2), the target velocity, the homing settings."""
        value = od.decode_raw(data)
        with self._lock:
            if index == 0x6060:
                self._set_mode(int(value))
            elif index == 0x60FF:
                if value != self.target_velocity:
                    self._bits &= ~SW_TARGET_REACHED
                self.target_velocity = int(value)
            elif index == 0x6098:
                self.homing_method = int(value)
            elif index == 0x6099 and subindex in (1, 2):
                self.homing_speeds[subindex - 1] = int(value)
            self._send_status(force=True)

    def _set_mode(self, mode: int) -> None:
        self.mode = mode
        if not self._hold_mode:
            self.mode_display = mode
        self._homing = False
        self.velocity = 0.0
        self.target = int(self.position)
        self._bits = SW_TARGET_REACHED if mode == PROFILE_POSITION else 0

    def _on_rpdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self._silent or self.node.nmt.state != "OPERATIONAL" or len(data) < _RPDO.size:
            return
        cw, target = _RPDO.unpack_from(bytes(data))
        with self._lock:
            before = self.state
            self.state = drive_step(self.state, cw, self._cw)
            if before is PowerState.FAULT and self.state is not PowerState.FAULT:
                self.error_code = 0
                self.node.emcy.send(0x0000, 0x00)  # error reset: the fault is gone
            enabled = self.state is PowerState.OPERATION_ENABLED
            rising = enabled and cw & 0x10 and not self._cw & 0x10
            if self.mode_display == HOMING:
                if rising:
                    self._start_homing()
            elif rising:
                self.target = target  # new set-point: latch, acknowledge
                self._bits = (self._bits | SW_SETPOINT_ACK) & ~SW_TARGET_REACHED
            elif not cw & 0x10:
                self._bits &= ~SW_SETPOINT_ACK
            self._cw = cw
            self._send_status()

    def _start_homing(self) -> None:
        """Bit 4 rose in homing mode (rule 2): start the method, or say homing error."""
        self._bits &= ~(SW_HOMING_ATTAINED | SW_TARGET_REACHED | SW_HOMING_ERROR)
        if self.homing_method not in HOMING_METHODS:
            self._bits |= SW_HOMING_ERROR | SW_TARGET_REACHED
            return
        self._homing = True

    def _send_status(self, force: bool = False) -> None:
        if self._silent or self._frozen:
            return
        word = (self.statusword, int(self.position))
        now = time.monotonic()
        if force or word != self._last_sent or now - self._last_time >= self.event_timer:
            self._last_sent, self._last_time = word, now
            self.network.send_message(0x180 + self.node_id, _TPDO.pack(*word))

    def _run(self) -> None:
        last = time.monotonic()
        while not self._stop.wait(self.tick):
            now = time.monotonic()
            dt, last = now - last, now
            with self._lock:
                if self.state is PowerState.FAULT_REACTION and now >= self._reaction_until:
                    self.state = PowerState.FAULT  # the reaction (braking) is over
                if self.state is PowerState.OPERATION_ENABLED:
                    self._move(dt)
                if self.node.nmt.state == "OPERATIONAL":
                    with contextlib.suppress(can.CanError):  # a bus gone: the driver sees it
                        self._send_status()

    def _move(self, dt: float) -> None:
        """One tick of the mode's motion in Operation enabled (rule 2)."""
        if self.mode_display == PROFILE_VELOCITY:
            error = self.target_velocity - self.velocity
            self.velocity += min(abs(error), self.acceleration * dt) * (1 if error > 0 else -1)
            self.position += self.velocity * dt
            if self.velocity == self.target_velocity:
                self._bits |= SW_TARGET_REACHED
            return
        if self.mode_display == HOMING:
            if not self._homing:
                return
            if self.homing_method in (35, 37):
                self.position = 0.0  # the current position is home
            step = min(abs(self.position), self.homing_speeds[0] * dt)
            self.position += -step if self.position > 0 else step
            if self.position == 0.0:
                self._homing = False
                self._bits |= SW_HOMING_ATTAINED | SW_TARGET_REACHED
            return
        if self.mode_display == PROFILE_POSITION:
            error = self.target - self.position
            step = min(abs(error), self.speed * dt)
            self.position += step if error > 0 else -step
            if self.position == self.target:
                self._bits |= SW_TARGET_REACHED
