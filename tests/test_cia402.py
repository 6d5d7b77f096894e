"""The CiA 402 driver over CANopen, against the simulated drive on python-can's virtual bus."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("canopen")
import can

from statectl.channels.cli.demo import motor_chart
from statectl.channels.runconfig import load_driver_config
from statectl.kernel.errors import DiagnosticError, StatectlError
from statectl.kernel.model import Chart
from statectl.run.devices import connect
from statectl.run.devices.cia402 import Cia402Driver, Cia402SimDriver
from statectl.run.devices.cia402.profile import (
    PowerState,
    decode,
    drive_step,
    next_command,
    statusword,
)
from statectl.run.runtime import EventReceived, Record, Subject, WallClock

P = PowerState

# -- the profile as data ---------------------------------------------------------------------

#: (statusword, the state the standard's masks name)
STATUSWORDS = [
    (0x0000, P.NOT_READY),
    (0x0250, P.SWITCH_ON_DISABLED),  # bit 4 voltage, bit 9 remote: ignored by the mask
    (0x0231, P.READY),
    (0x0233, P.SWITCHED_ON),
    (0x1637, P.OPERATION_ENABLED),  # bits 10, 12 of profile position: ignored
    (0x0217, P.QUICK_STOP),
    (0x021F, P.FAULT_REACTION),
    (0x0218, P.FAULT),
]


@pytest.mark.parametrize(("word", "state"), STATUSWORDS)
def test_statusword_decodes_to_the_standards_state(word: int, state: PowerState) -> None:
    """A statusword names the power state its bits 0-3, 5, 6 show."""
    assert decode(word) is state
    assert decode(statusword(state)) is state


#: (state, controlword, previous controlword, the state the drive goes to)
STEPS = [
    (P.SWITCH_ON_DISABLED, 0x06, 0x00, P.READY),  # 2
    (P.READY, 0x07, 0x06, P.SWITCHED_ON),  # 3
    (P.SWITCHED_ON, 0x0F, 0x07, P.OPERATION_ENABLED),  # 4
    (P.OPERATION_ENABLED, 0x07, 0x0F, P.SWITCHED_ON),  # 5
    (P.SWITCHED_ON, 0x06, 0x07, P.READY),  # 6
    (P.READY, 0x00, 0x06, P.SWITCH_ON_DISABLED),  # 7
    (P.OPERATION_ENABLED, 0x06, 0x0F, P.READY),  # 8
    (P.OPERATION_ENABLED, 0x00, 0x0F, P.SWITCH_ON_DISABLED),  # 9
    (P.OPERATION_ENABLED, 0x02, 0x0F, P.QUICK_STOP),  # 11
    (P.QUICK_STOP, 0x00, 0x02, P.SWITCH_ON_DISABLED),  # 12
    (P.QUICK_STOP, 0x06, 0x02, P.QUICK_STOP),  # shutdown does not leave Quick stop
    (P.QUICK_STOP, 0x0F, 0x02, P.OPERATION_ENABLED),  # 16
    (P.FAULT, 0x80, 0x00, P.SWITCH_ON_DISABLED),  # 15: bit 7 rises
    (P.FAULT, 0x80, 0x80, P.FAULT),  # bit 7 held high: no edge, no reset
    (P.FAULT, 0x0F, 0x00, P.FAULT),  # nothing but a reset leaves Fault
    (P.SWITCH_ON_DISABLED, 0x0F, 0x00, P.SWITCH_ON_DISABLED),  # no skipping ahead
]


@pytest.mark.parametrize(("state", "cw", "before", "after"), STEPS)
def test_drive_takes_the_standards_transition(
    state: PowerState, cw: int, before: int, after: PowerState
) -> None:
    """The simulated drive's power state machine follows the transitions of CiA 402."""
    assert drive_step(state, cw, before) is after


def test_walk_from_any_state_reaches_operation_enabled() -> None:
    """next_command and drive_step together reach Operation enabled from every state a
    controlword can leave, by the enable sequence 0x06, 0x07, 0x0F after the states before."""
    for start in (P.SWITCH_ON_DISABLED, P.READY, P.SWITCHED_ON, P.QUICK_STOP, P.FAULT):
        state, cw, sent = start, 0x0F, []
        for _ in range(8):
            command = next_command(state, cw)
            if command is None:
                break
            sent.append(command)
            state, cw = drive_step(state, command, cw), command
        assert state is P.OPERATION_ENABLED, (start, sent)
        assert sent[-3:] == [0x06, 0x07, 0x0F] or start in (P.READY, P.SWITCHED_ON), sent


# -- the driver on the bus -------------------------------------------------------------------


class Sniffer:
    """Every frame on a virtual channel, as (id, data), from a bus of its own."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.frames: list[tuple[int, bytes]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.01)
            if msg is not None:
                self.frames.append((msg.arbitration_id, bytes(msg.data)))

    def controlwords(self, node: int = 1) -> list[int]:
        return [int.from_bytes(d[:2], "little") for i, d in self.frames if i == 0x200 + node]

    def statuswords(self, node: int = 1) -> list[int]:
        return [int.from_bytes(d[:2], "little") for i, d in self.frames if i == 0x180 + node]

    def sdo(self, node: int = 1) -> list[tuple[str, int, int, int]]:
        """The SDO requests to the node: (read|write, index, subindex, value written)."""
        found = []
        for i, d in list(self.frames):
            if i == 0x600 + node and len(d) == 8:
                kind = "read" if d[0] == 0x40 else "write" if d[0] & 0xE0 == 0x20 else "?"
                index, sub = int.from_bytes(d[1:3], "little"), d[3]
                found.append((kind, index, sub, int.from_bytes(d[4:8], "little", signed=True)))
        return found

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.bus.shutdown()


class Run:
    """The paper's Motor on a Cia402SimDriver, on a WallClock, records kept."""

    def __init__(self, chart: Chart | None = None, **options: Any) -> None:
        self.driver = Cia402SimDriver(**options)
        self.sniffer = Sniffer(self.driver.channel)
        self.clock = WallClock()
        self.subject = Subject(chart or motor_chart(), clock=self.clock)
        self.records: list[Record] = []
        self.subject.listen(self.records.append)
        connect(self.subject, self.driver, period=0.01)
        self.subject.start()

    def until(self, state: str, limit: float = 5.0) -> None:
        deadline = time.monotonic() + limit
        self.subject.run_until_idle()
        while self.subject.configuration != {state} or self.subject.queued:
            assert time.monotonic() < deadline, (state, self.subject.configuration, self.events)
            time.sleep(0.002)
            self.subject.run_until_idle()

    def leave(self, state: str, limit: float = 5.0) -> None:
        deadline = time.monotonic() + limit
        while state in self.subject.configuration:
            assert time.monotonic() < deadline, (state, self.events)
            time.sleep(0.002)
            self.subject.run_until_idle()

    def seen(self, event: str, limit: float = 5.0) -> list[Any]:
        """The data of each ``event`` the device took, once there is one."""
        deadline = time.monotonic() + limit
        while True:
            self.subject.run_until_idle()
            found = [d for e, d in self.events if e == event]
            if found:
                return found
            assert time.monotonic() < deadline, (event, self.events)
            time.sleep(0.002)

    @property
    def events(self) -> list[tuple[str, Any]]:
        return [(r.event, r.data) for r in self.records if isinstance(r, EventReceived)]

    def close(self) -> None:
        self.subject.close()
        self.driver.close()
        self.sniffer.close()
        self.clock.stop()


@pytest.fixture
def run() -> Iterator[Run]:
    r = Run()
    yield r
    r.close()


def test_movement_enables_by_the_standard_controlword_sequence(run: Run) -> None:
    """Movement() sends 0x06, 0x07, 0x0F on RPDO1, then the set-point handshake
    (bit 4 up, then down), and its completion carries the position the drive reached."""
    run.subject.post("Movement", {"amount": 0.5})
    run.until("Blocked")
    assert run.sniffer.controlwords()[:5] == [0x06, 0x07, 0x0F, 0x3F, 0x0F]
    assert ("Movement completion", {"position": 0.5}) in run.events
    assert run.driver.drive.position == 500


def test_fault_reset_is_a_rising_edge_of_bit_7(run: Run) -> None:
    """An EMCY during Moving raises Error; Error() resets the fault by bit 7's rising edge
    (a word with bit 7 clear, then one with it set) and enables again by 0x06, 0x07, 0x0F."""
    run.subject.post("Movement", {"amount": 1})
    run.subject.run_until_idle()
    deadline = time.monotonic() + 5
    while run.driver.drive.state is not PowerState.OPERATION_ENABLED:
        assert time.monotonic() < deadline
        time.sleep(0.002)
    run.driver.drive.fault(0x7300, "enc")
    run.until("Blocked")
    words = run.sniffer.controlwords()
    reset = next(i for i, w in enumerate(words) if w & 0x80)
    assert reset > 0 and not words[reset - 1] & 0x80
    assert words[reset + 1 : reset + 4] == [0x06, 0x07, 0x0F]
    names = [e for e, _ in run.events]
    assert names[-2:] == ["Error", "Error completion"]
    assert run.driver.drive.state is PowerState.OPERATION_ENABLED


def _emcy(r: Run) -> None:
    r.driver.drive.fault(0x2310, "I")


def _silence(r: Run) -> None:
    r.driver.drive.silence()


def _stale(r: Run) -> None:
    r.driver.drive.freeze()


def _bus_off(r: Run) -> None:
    """The virtual bus cannot go bus-off; a bus that refuses every frame is the same to us."""
    network = r.driver.network
    assert network is not None and network.bus is not None

    def refuse(msg: can.Message, timeout: float | None = None) -> None:
        raise can.CanOperationError("bus-off (simulated)")

    network.bus.send = refuse  # type: ignore[method-assign]
    r.driver.recover(0.0)  # the next frame the driver sends meets the dead bus


#: (what goes wrong during Moving, what the Error's detail and the log line say)
FAULTS: list[tuple[str, Callable[[Run], None], str]] = [
    ("emcy", _emcy, "EMCY 0x2310"),
    ("drive stops answering", _silence, "no heartbeat"),
    ("stale statusword", _stale, "no TPDO"),
    ("bus-off", _bus_off, "bus refused controlword"),
]


@pytest.mark.parametrize(("case", "make", "said"), FAULTS, ids=[f[0] for f in FAULTS])
def test_bus_fault_during_moving_raises_the_states_fault_event(
    case: str, make: Callable[[Run], None], said: str, caplog: pytest.LogCaptureFixture
) -> None:
    """A fault a real bus has, during Moving, becomes the Moving monitor's Error with a
    detail saying what happened, and one warning on the driver's logger."""
    r = Run(heartbeat_timeout=0.2, stale_after=0.2, speed=200.0)  # a slow move: time to fail
    try:
        with caplog.at_level(logging.WARNING, logger="statectl.run.devices.cia402"):
            r.subject.post("Movement", {"amount": 5})
            r.subject.run_until_idle()
            time.sleep(0.05)
            make(r)
            r.leave("Moving")
        errors = [d for e, d in r.events if e == "Error"]
        assert errors and said in errors[0]["detail"], r.events
        assert any(said in m for m in caplog.messages), caplog.messages
    finally:
        r.close()


def test_a_drive_that_does_not_answer_sdo_is_a_clear_error() -> None:
    """Opening a node nobody answers for is a StatectlError naming the node and the SDO
    timeout, not a traceback from the bus library."""
    driver = Cia402Driver(channel="statectl-test-empty", node_id=9, sdo_timeout=0.1)
    with pytest.raises(StatectlError, match=r"node 9 .* does not answer SDO"):
        driver.bind(lambda e, d: None, WallClock())
    assert driver.network is None


def test_an_unknown_interface_is_a_clear_error() -> None:
    """A bus interface python-can does not have is a StatectlError saying the bus cannot open."""
    driver = Cia402Driver(interface="no-such-interface", channel="x")
    with pytest.raises(StatectlError, match="cannot open the bus"):
        driver.bind(lambda e, d: None, WallClock())


# -- configuration ---------------------------------------------------------------------------


def test_socketcan_is_a_config_change_only(tmp_path: Path) -> None:
    """A real drive on SocketCAN is the same driver with other options; they load as given."""
    path = tmp_path / "run.yaml"
    path.write_text(
        "devices:\n"
        "  Motor:\n"
        "    driver: cia402\n"
        "    options: {interface: socketcan, channel: can0, node_id: 3, scale: 4096}\n"
    )
    config = load_driver_config(path)
    assert config["Motor"] == (
        "cia402",
        {"interface": "socketcan", "channel": "can0", "node_id": 3, "scale": 4096},
    )


def test_bad_cia402_options_are_d511_all_at_once(tmp_path: Path) -> None:
    """Every bad option value of a bus driver is one D511 with the file's line."""
    path = tmp_path / "run.yaml"
    path.write_text(
        "devices:\n"
        "  Motor:\n"
        "    driver: cia402\n"
        "    options: {node_id: 200, eds: missing.eds, scale: 0}\n"
    )
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    diags = info.value.diagnostics
    assert [d.code for d in diags] == ["D511"] * 3
    assert all(d.where.line == 4 for d in diags)
    assert {m.split(": ")[1].split(" ")[0] for m in (d.message for d in diags)} == {
        "node_id",
        "eds",
        "scale",
    }


@pytest.mark.parametrize(
    ("driver", "option"),
    [
        ("cia402", "scale"),
        ("cia402-sim", "speed"),
        ("cia402", "sdo_timeout"),
        ("cia402", "stale_after"),
    ],
)
def test_an_infinite_cia402_number_is_d511(tmp_path: Path, driver: str, option: str) -> None:
    """.inf is no scale or timeout: D511 at the options' line (a scale of .inf used to
    load and end the first Movement in an OverflowError traceback)."""
    path = tmp_path / "run.yaml"
    path.write_text(f"devices:\n  Motor:\n    driver: {driver}\n    options: {{{option}: .inf}}\n")
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    found = [(d.code, d.where.line, option in d.message) for d in info.value.diagnostics]
    assert found == [("D511", 4, True)]


def test_demo_runs_the_motor_scenario_on_the_simulated_drive() -> None:
    """`statectl demo --driver cia402-sim` ends Blocked, its fault an EMCY from the drive."""
    import io
    import re

    from statectl.channels.cli.demo import run_demo

    out = io.StringIO()
    subject = run_demo(out, driver="cia402-sim")
    text = out.getvalue()
    assert subject.configuration == {"Blocked"}
    assert "EMCY 0x7300" in text and "Error completion" in text
    assert len(re.findall(r"event\s+Movement completion", text)) == 1  # the faulted one never


def test_the_socketcan_example_config_loads() -> None:
    """examples/motor/cia402-socketcan.yaml is a valid run config for the cia402 driver."""
    root = Path(__file__).parent.parent
    name, options = load_driver_config(root / "examples" / "motor" / "cia402-socketcan.yaml")[
        "Motor"
    ]
    assert (name, options["interface"], options["channel"]) == ("cia402", "socketcan", "can0")


@pytest.mark.parametrize(("realtime", "code", "moved"), [(False, 2, False), (True, 0, True)])
def test_a_bus_driver_runs_on_wall_time_only(realtime: bool, code: int, moved: bool) -> None:
    """A batch run of a bus driver on simulated time is a usage error naming --realtime (it
    used to end at once with the Motor still Moving, exit 0); with --realtime the typed
    Movement runs."""
    import io

    from statectl.channels.cli.run import run

    motor = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
    out, err = io.StringIO(), io.StringIO()
    lines = io.StringIO("Movement {amount: 1}\n")
    got = run(str(motor), driver="cia402-sim", realtime=realtime, events=lines, out=out, err=err)
    assert (got, "--realtime" in err.getvalue()) == (code, not realtime), err.getvalue()
    assert ("Cia402SimDriver.move_to(1.0)" in out.getvalue()) == moved


# -- Fault reaction active, EMCY bytes, modes (issue 31) -------------------------------------

AXIS = Path(__file__).parent.parent / "examples" / "motor" / "axis-cia402.yaml"


def axis_chart() -> Chart:
    from statectl.front.builder.build import load_chart

    return load_chart(AXIS)


def _wait(what: Callable[[], Any], limit: float = 5.0) -> Any:
    deadline = time.monotonic() + limit
    while not (got := what()):
        assert time.monotonic() < deadline
        time.sleep(0.002)
    return got


def test_the_drive_passes_through_fault_reaction_active_before_fault() -> None:
    """A fault puts the simulated drive in Fault reaction active (statusword 0x..1F) for
    ``fault_reaction`` s, then Fault (0x..08): the frames show both, in that order; the
    driver raises one Error for the episode and Error() resets it as before."""
    r = Run(fault_reaction=0.1, speed=200.0)
    try:
        r.subject.post("Movement", {"amount": 5})
        r.subject.run_until_idle()
        _wait(lambda: r.driver.drive.state is PowerState.OPERATION_ENABLED)
        r.driver.drive.fault(0x7300, "enc")
        r.until("Blocked")
        states = [decode(w) for w in r.sniffer.statuswords()]
        reaction = states.index(P.FAULT_REACTION)
        assert P.FAULT in states[reaction:] and P.FAULT not in states[:reaction]
        assert [e for e, _ in r.events].count("Error") == 1, r.events
        assert r.events[-1][0] == "Error completion"
    finally:
        r.close()


def test_an_emcy_keeps_its_manufacturer_bytes_in_the_detail() -> None:
    """The Error an EMCY raises says its code, error register and the five
    manufacturer-specific bytes in hex (they used to be dropped)."""
    r = Run(speed=200.0)
    try:
        r.subject.post("Movement", {"amount": 5})
        r.subject.run_until_idle()
        _wait(lambda: r.driver.drive.state is PowerState.OPERATION_ENABLED)
        r.driver.drive.fault(0x2310, "Iq!")
        r.leave("Moving")
        detail = next(d for e, d in r.events if e == "Error")["detail"]
        assert "EMCY 0x2310" in detail and "error register 0x01" in detail
        assert "manufacturer bytes 49 71 21 00 00" in detail
    finally:
        r.close()


def test_homing_runs_the_drives_homing_mode_and_completes_when_attained() -> None:
    """Homing() writes 0x6060 = 6 and reads 0x6061 back, writes the method (0x6098) and
    the speeds (0x6099:1, :2, in counts/s), starts homing by controlword bit 4 once
    enabled, and reports Homing completion when bits 12 and 10 say homing attained."""
    r = Run(axis_chart(), homing_method=17, homing_speeds=[5.0, 0.5], scale=1000.0)
    try:
        r.driver.drive.position = 400.0  # the home switch is at 0
        r.subject.post("Homing")
        r.until("Ready")
        sdo = r.sniffer.sdo()
        mode = sdo.index(("write", 0x6060, 0, 6))
        assert ("read", 0x6061, 0, 0) in sdo[mode:]
        assert [s for s in sdo if s[0] == "write" and s[1] in (0x6098, 0x6099)] == [
            ("write", 0x6098, 0, 17),
            ("write", 0x6099, 1, 5000),
            ("write", 0x6099, 2, 500),
        ]
        assert 0x1F in r.sniffer.controlwords()  # enable operation + bit 4: start homing
        assert ("Homing completion", {"position": 0.0}) in r.events
        assert r.driver.drive.position == 0.0
    finally:
        r.close()


def test_a_homing_error_is_the_states_fault_event() -> None:
    """A method the drive does not have (36 is reserved; the event's data overrides the
    option) makes it set statusword bit 13; the driver reports it as a homing error,
    which Homing's monitor raises as Error."""
    r = Run(axis_chart(), homing_method=35)
    try:
        r.subject.post("Homing", {"method": 36})
        errors = r.seen("Error")
        assert "homing error" in errors[0]["detail"], r.events
        assert "Homing completion" not in [e for e, _ in r.events]
        assert ("write", 0x6098, 0, 36) in r.sniffer.sdo()
    finally:
        r.close()


def test_a_mode_the_drive_does_not_show_is_the_states_fault_event() -> None:
    """If 0x6061 does not show the mode written to 0x6060 within mode_timeout, the call
    does not go on (no homing start) and Homing's monitor raises Error saying so."""
    r = Run(axis_chart(), mode_timeout=0.1)
    try:
        r.driver.drive.hold_mode()
        r.subject.post("Homing")
        errors = r.seen("Error")
        assert "homing mode (0x6060 = 6) not confirmed" in errors[0]["detail"]
        assert "0x6061 still reads 1" in errors[0]["detail"]
        assert 0x1F not in r.sniffer.controlwords()
    finally:
        r.close()


def test_velocity_runs_profile_velocity_and_completes_when_reached() -> None:
    """Velocity({velocity: 2}) switches to profile velocity (0x6060 = 3), writes 0x60FF =
    2000 counts/s and reports Velocity completion once statusword bit 10 says the velocity
    is reached; a Movement afterwards goes back to profile position and completes."""
    r = Run(axis_chart(), acceleration=50000.0)
    try:
        r.subject.post("Homing")
        r.until("Ready")
        r.subject.post("Velocity", {"velocity": 2.0})
        r.until("Ready")
        assert ("Velocity completion", {"velocity": 2.0}) in r.events
        assert ("write", 0x6060, 0, 3) in r.sniffer.sdo()
        assert ("write", 0x60FF, 0, 2000) in r.sniffer.sdo()
        assert (r.driver.drive.mode_display, r.driver.drive.velocity) == (3, 2000.0)
        r.subject.post("Movement", {"amount": 0.5})
        r.until("Ready")
        assert r.events[-1][0] == "Movement completion"
        assert r.sniffer.sdo().count(("write", 0x6060, 0, 1)) == 2  # at start-up, and now
    finally:
        r.close()


def test_the_axis_socketcan_config_loads_with_its_homing_options() -> None:
    """examples/motor/axis-cia402-socketcan.yaml: the same cia402 driver, by configuration
    only, with the homing method and speeds and the mode timeout."""
    from statectl.run.devices import make_driver

    root = Path(__file__).parent.parent
    name, options = load_driver_config(root / "examples" / "motor" / "axis-cia402-socketcan.yaml")[
        "Axis"
    ]
    assert (name, options["interface"], options["homing_method"]) == ("cia402", "socketcan", 17)
    driver = make_driver(name, options, chart=axis_chart())
    assert isinstance(driver, Cia402Driver) and driver.homing_speeds == (2.0, 0.2)
    assert {"Homing", "Velocity"} <= driver.serves()


@pytest.mark.parametrize(
    ("options", "says"),
    [
        ("{homing_method: 300}", "homing_method must be"),
        ("{homing_speeds: [1]}", "homing_speeds must be two speeds"),
        ("{homing_speeds: [1, -1]}", "homing_speeds must be two speeds"),
        ("{mode_timeout: 0}", "mode_timeout must be a number > 0"),
    ],
)
def test_bad_mode_options_are_d511(tmp_path: Path, options: str, says: str) -> None:
    """A homing method outside 0x6098's range, speeds that are not two numbers > 0 and a
    mode timeout of 0 are each one D511 at the options' line."""
    path = tmp_path / "run.yaml"
    path.write_text(f"devices:\n  Axis:\n    driver: cia402\n    options: {options}\n")
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    found = [(d.code, d.where.line, says in d.message) for d in info.value.diagnostics]
    assert found == [("D511", 4, True)], [d.message for d in info.value.diagnostics]


def test_a_fault_reaction_time_is_a_sim_option(tmp_path: Path) -> None:
    """cia402-sim takes fault_reaction (s >= 0); a negative one is D511."""
    path = tmp_path / "run.yaml"
    path.write_text(
        "devices:\n  Axis:\n    driver: cia402-sim\n    options: {fault_reaction: -1}\n"
    )
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    assert ["fault_reaction must be seconds >= 0" in d.message for d in info.value.diagnostics] == [
        True
    ]


def test_a_drive_that_does_not_show_profile_position_at_start_is_a_clear_error() -> None:
    """At start-up 0x6060 = 1 is read back from 0x6061: a drive that keeps showing
    another mode is a StatectlError saying what 0x6061 reads, not a run that starts."""
    from statectl.run.devices.cia402.sim import SimDrive

    drive = SimDrive(channel="statectl-test-mode", node_id=5)
    try:
        drive.hold_mode()
        drive.mode_display = 0  # no mode
        driver = Cia402Driver(channel="statectl-test-mode", node_id=5, mode_timeout=0.1)
        with pytest.raises(StatectlError, match=r"node 5 .*0x6061 reads 0 0.1 s after 0x6060 = 1"):
            driver.bind(lambda e, d: None, WallClock())
        assert driver.network is None
    finally:
        drive.stop()
