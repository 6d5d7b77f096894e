"""The CiA 402 power state machine as data: statusword masks, controlword commands, transitions.

Rules:
1. :func:`decode` names the power state a statusword shows, by the standard's
   masks (bits 0-3, 5 and 6); no I/O, so the driver and the simulated drive
   share one reading of the profile.
2. :func:`next_command` is the controlword that takes a drive one transition
   nearer Operation enabled (2, 3, 4; 15 from Fault; 12 out of Quick stop
   active), or ``None`` where the drive must move by itself.
3. :func:`drive_step` is the drive's side: the state a controlword takes a
   drive to from a state (transitions 2-12 and 15); the simulated drive runs it.
4. Modes of operation (0x6060, shown in 0x6061): the operating-mode bits of the
   controlword and statusword mean different things per mode; :data:`MODES`
   names the three statectl drives, the bit constants say which mode they are of.
"""

from __future__ import annotations

from enum import Enum

__all__ = [
    "CW_DISABLE_VOLTAGE",
    "CW_ENABLE_OPERATION",
    "CW_FAULT_RESET",
    "CW_HOMING_START",
    "CW_NEW_SETPOINT",
    "CW_QUICK_STOP",
    "CW_SHUTDOWN",
    "CW_SWITCH_ON",
    "HOMING",
    "MODES",
    "PROFILE_POSITION",
    "PROFILE_VELOCITY",
    "SW_FAULT",
    "SW_HOMING_ATTAINED",
    "SW_HOMING_ERROR",
    "SW_SETPOINT_ACK",
    "SW_TARGET_REACHED",
    "SW_WARNING",
    "PowerState",
    "decode",
    "drive_step",
    "next_command",
    "statusword",
]


class PowerState(Enum):
    """The eight states of the CiA 402 drive power state machine."""

    NOT_READY = "Not ready to switch on"
    SWITCH_ON_DISABLED = "Switch on disabled"
    READY = "Ready to switch on"
    SWITCHED_ON = "Switched on"
    OPERATION_ENABLED = "Operation enabled"
    QUICK_STOP = "Quick stop active"
    FAULT_REACTION = "Fault reaction active"
    FAULT = "Fault"


#: (mask, value, state): the first row whose ``statusword & mask == value`` names the state.
STATUS_MASKS: tuple[tuple[int, int, PowerState], ...] = (
    (0x4F, 0x00, PowerState.NOT_READY),
    (0x4F, 0x40, PowerState.SWITCH_ON_DISABLED),
    (0x6F, 0x21, PowerState.READY),
    (0x6F, 0x23, PowerState.SWITCHED_ON),
    (0x6F, 0x27, PowerState.OPERATION_ENABLED),
    (0x6F, 0x07, PowerState.QUICK_STOP),
    (0x4F, 0x0F, PowerState.FAULT_REACTION),
    (0x4F, 0x08, PowerState.FAULT),
)

#: The statusword bits 0-6 a drive shows in each state (bit 4 voltage enabled set when on).
STATUS_BITS: dict[PowerState, int] = {
    PowerState.NOT_READY: 0x00,
    PowerState.SWITCH_ON_DISABLED: 0x40,
    PowerState.READY: 0x21,
    PowerState.SWITCHED_ON: 0x33,
    PowerState.OPERATION_ENABLED: 0x37,
    PowerState.QUICK_STOP: 0x17,
    PowerState.FAULT_REACTION: 0x1F,
    PowerState.FAULT: 0x08,
}

CW_SHUTDOWN = 0x06  # transitions 2, 6, 8
CW_SWITCH_ON = 0x07  # transition 3 (and 5: disable operation)
CW_ENABLE_OPERATION = 0x0F  # transition 4 (and 16 from Quick stop active)
CW_DISABLE_VOLTAGE = 0x00  # transitions 7, 9, 10, 12
CW_QUICK_STOP = 0x02  # transitions 7, 10, 11
CW_FAULT_RESET = 0x80  # transition 15, on bit 7's rising edge
CW_NEW_SETPOINT = 0x30  # profile position: bit 4 new set-point, bit 5 change immediately
CW_HOMING_START = 0x10  # homing: bit 4 rising starts the homing operation

SW_FAULT = 0x0008
SW_WARNING = 0x0080
SW_TARGET_REACHED = 0x0400  # bit 10
SW_SETPOINT_ACK = 0x1000  # bit 12 in profile position mode
SW_HOMING_ATTAINED = 0x1000  # bit 12 in homing mode (with bit 10: homing done)
SW_HOMING_ERROR = 0x2000  # bit 13 in homing mode

#: Modes of operation (0x6060 / 0x6061) statectl's driver and simulated drive speak.
PROFILE_POSITION = 1
PROFILE_VELOCITY = 3  # bit 10 of the statusword: target velocity reached
HOMING = 6
MODES: dict[int, str] = {
    PROFILE_POSITION: "profile position",
    PROFILE_VELOCITY: "profile velocity",
    HOMING: "homing",
}
#: Homing methods the standard defines (0x6098); 0 is "no homing", 36 is reserved.
HOMING_METHODS = frozenset(range(1, 36)) | {37}


def decode(word: int) -> PowerState:
    """The power state a statusword shows (rule 1)."""
    for mask, value, state in STATUS_MASKS:
        if word & mask == value:
            return state
    return PowerState.NOT_READY


def statusword(state: PowerState, extra: int = 0) -> int:
    """The statusword a drive in ``state`` shows, with ``extra`` bits (10, 12, ...) added."""
    return STATUS_BITS[state] | extra


def next_command(state: PowerState, previous_cw: int) -> int | None:
    """The controlword one step nearer Operation enabled from ``state`` (rule 2).

    From Fault the reset needs bit 7 to rise: if the last controlword already had
    it set, the answer is the word with bit 7 clear first.
    """
    if state is PowerState.SWITCH_ON_DISABLED:
        return CW_SHUTDOWN
    if state is PowerState.READY:
        return CW_SWITCH_ON
    if state is PowerState.SWITCHED_ON:
        return CW_ENABLE_OPERATION
    if state is PowerState.QUICK_STOP:
        return CW_DISABLE_VOLTAGE
    if state is PowerState.FAULT:
        return CW_DISABLE_VOLTAGE if previous_cw & CW_FAULT_RESET else CW_FAULT_RESET
    return None  # Not ready, Fault reaction active: the drive moves on by itself


def _command(cw: int) -> str:
    """Which device control command a controlword is (the standard's bit patterns)."""
    if cw & 0x02 == 0:
        return "disable voltage"
    if cw & 0x06 == 0x02:
        return "quick stop"
    if cw & 0x07 == 0x06:
        return "shutdown"
    if cw & 0x0F == 0x07:
        return "switch on"  # also "disable operation" from Operation enabled
    return "enable operation"  # 0x0F pattern


def drive_step(state: PowerState, cw: int, previous_cw: int) -> PowerState:
    """The state a drive in ``state`` goes to when it receives ``cw`` (rule 3)."""
    if state is PowerState.FAULT:
        rising = cw & CW_FAULT_RESET and not previous_cw & CW_FAULT_RESET
        return PowerState.SWITCH_ON_DISABLED if rising else state
    if state in (PowerState.NOT_READY, PowerState.FAULT_REACTION):
        return state
    command = _command(cw)
    if command == "disable voltage":
        return PowerState.SWITCH_ON_DISABLED  # 7, 9, 10, 12
    if state is PowerState.SWITCH_ON_DISABLED:
        return PowerState.READY if command == "shutdown" else state  # 2
    if command == "quick stop":
        if state is PowerState.OPERATION_ENABLED:
            return PowerState.QUICK_STOP  # 11
        return PowerState.SWITCH_ON_DISABLED if state is not PowerState.QUICK_STOP else state
    if state is PowerState.QUICK_STOP:
        return PowerState.OPERATION_ENABLED if command == "enable operation" else state  # 16
    if command == "shutdown":
        return PowerState.READY  # 6, 8
    if command == "switch on":
        return PowerState.SWITCHED_ON  # 3, 5
    if state is PowerState.READY:
        return PowerState.OPERATION_ENABLED  # 3+4 at once, as the standard allows
    return PowerState.OPERATION_ENABLED  # 4
