"""The Modbus TCP driver against a pymodbus server the test starts on 127.0.0.1."""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("pymodbus")
from pymodbus.datastore import (
    ModbusDeviceContext,
    ModbusSequentialDataBlock,
    ModbusServerContext,
)
from pymodbus.server import ModbusTcpServer

from statectl.channels.runconfig import load_driver_config
from statectl.front.observers import Notification
from statectl.kernel.errors import DiagnosticError
from statectl.run.devices.modbus import ModbusIO
from statectl.run.runtime import WallClock

ROOT = Path(__file__).parent.parent
COILS = {"close_valve": 0, "open_valve": 1}
INPUTS = {f"in{i}": i for i in range(64)} | {"closed": 0, "opened": 1}
ACTIONS = {
    "Grip": {"set": {"close_valve": True, "open_valve": False}, "until": {"closed": True},
             "done": "Grip completion"},
    "Release": {"set": {"close_valve": False, "open_valve": True}, "until": {"opened": True},
                "done": "Release completion"},
}  # fmt: skip


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """A pymodbus TCP server on its own loop thread, on a free loopback port.

    ``delay`` makes every answer late (a stale value on a live link).
    """

    def __init__(self, port: int | None = None) -> None:
        self.port = port or free_port()
        self.delay = 0.0
        device = ModbusDeviceContext(
            di=ModbusSequentialDataBlock(1, [False] * 80),
            co=ModbusSequentialDataBlock(1, [False] * 16),
            hr=ModbusSequentialDataBlock(1, [0] * 64),
            ir=ModbusSequentialDataBlock(1, [0] * 64),
        )
        self.context = ModbusServerContext(devices=device, single=True)
        get = device.async_getValues

        async def late_get(*args: Any, **kwargs: Any) -> Any:
            if self.delay:
                await asyncio.sleep(self.delay)
            return await get(*args, **kwargs)

        device.async_getValues = late_get  # type: ignore[method-assign]
        self.loop = asyncio.new_event_loop()
        self.server: ModbusTcpServer | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        self._started()

    def _started(self) -> None:
        deadline = time.monotonic() + 5
        while True:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "the Modbus server did not start"
                time.sleep(0.01)

    def _run(self) -> None:
        async def serve() -> None:
            self.server = ModbusTcpServer(self.context, address=("127.0.0.1", self.port))
            await self.server.serve_forever()

        asyncio.set_event_loop(self.loop)
        self.loop.run_until_complete(serve())
        self.loop.close()

    def _on_loop(self, coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(5)

    def coil(self, address: int) -> bool:
        return bool(self.context[0].getValues(1, address, 1)[0])

    def set_input(self, address: int, value: bool) -> None:
        self.context[0].setValues(2, address, [value])

    def set_registers(self, table: int, address: int, words: list[int]) -> None:
        """Words into input (4) or holding (3) registers from ``address`` on."""
        self.context[0].setValues(table, address, words)

    def holding(self, address: int, count: int) -> list[int]:
        return [int(w) for w in self.context[0].getValues(3, address, count)]

    def stop(self) -> None:
        if self.thread.is_alive() and self.server is not None:
            self._on_loop(self.server.shutdown())
            self.thread.join(5)


class Gripper:
    """A ModbusIO gripper bound to a recording report on a WallClock."""

    def __init__(self, port: int, **options: Any) -> None:
        self.events: list[tuple[str, Any]] = []
        self.clock = WallClock()
        options = {"coils": COILS, "inputs": INPUTS, "actions": ACTIONS} | options
        self.driver = ModbusIO(port=port, timeout=0.3, **options)
        self.driver.bind(lambda e, d: self.events.append((e, d)), self.clock)

    def call(self, method: str) -> None:
        self.driver.update(Notification("Gripper", 0, method, method, method))

    def wait(self, what: Callable[[], Any], limit: float = 5.0) -> Any:
        deadline = time.monotonic() + limit
        while not (result := what()):
            assert time.monotonic() < deadline, (self.events, self.driver.values)
            time.sleep(0.005)
        return result

    def close(self) -> None:
        self.driver.close()
        self.clock.stop()


@pytest.fixture
def server() -> Iterator[Server]:
    s = Server()
    yield s
    s.stop()


def test_grip_writes_the_valves_and_completes_on_the_sensor(server: Server) -> None:
    """Grip() sets the named coils; its completion comes once the named input reads true."""
    g = Gripper(server.port)
    try:
        g.call("Grip")
        g.wait(lambda: server.coil(0))
        assert (server.coil(0), server.coil(1)) == (True, False)
        time.sleep(0.05)
        assert g.events == []  # the sensor has not closed yet
        server.set_input(0, True)
        event, values = g.wait(lambda: g.events)[0]
        assert event == "Grip completion" and values["closed"] is True
        assert [str(c) for c in g.driver.api_log] == ["ModbusIO.Grip()"]  # as the tables name it
    finally:
        g.close()


def _refused(server: Server) -> int:
    server.stop()
    return server.port  # nobody listens there now


def _reset_later(server: Server) -> int:
    return server.port


#: (case, port to use, what to do once the gripper polls, what the fault says)
CASES: list[tuple[str, Callable[[Server], int], Callable[[Server], None], str]] = [
    ("connection refused", _refused, lambda s: None, "failed"),
    ("connection reset", _reset_later, lambda s: s.stop(), "failed"),
    ("stale value", _reset_later, lambda s: setattr(s, "delay", 0.25), "stale"),
]


@pytest.mark.parametrize(("case", "port", "then", "said"), CASES, ids=[c[0] for c in CASES])
def test_link_faults_are_one_fault_detail_and_a_log_line(
    server: Server,
    case: str,
    port: Callable[[Server], int],
    then: Callable[[Server], None],
    said: str,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A refused or reset connection and a stale input each become a poll_fault detail
    saying what happened and a warning on the driver's logger; nothing raises."""
    with caplog.at_level(logging.WARNING, logger="statectl.run.devices.modbus"):
        g = Gripper(port(server), stale_after=0.15)
        try:
            time.sleep(0.05)
            then(server)
            detail = g.wait(g.driver.poll_fault)
            assert said in detail and f"127.0.0.1:{server.port}" in detail
            assert any(said in m for m in caplog.messages), caplog.messages
        finally:
            g.close()
    server.delay = 0.0


def test_modbus_options_are_checked_when_the_config_loads(tmp_path: Path) -> None:
    """An action naming a coil the device lacks and a bad address are D511 with the line."""
    path = tmp_path / "run.yaml"
    path.write_text(
        "devices:\n"
        "  Gripper:\n"
        "    driver: modbus\n"
        "    options:\n"
        "      coils: {close_valve: -1}\n"
        "      actions: {Grip: {set: {nozzle: true}}}\n"
    )
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    messages = [d.message for d in info.value.diagnostics]
    assert [d.code for d in info.value.diagnostics] == ["D511", "D511"]
    assert "coils.close_valve: address" in messages[0]
    assert "'nozzle' is not one of the coils" in messages[1]


def test_the_example_gripper_runs_on_modbus_and_a_reset_link_is_its_slip(
    server: Server, tmp_path: Path
) -> None:
    """The pick-and-place Gripper, configured by its example run config (port changed),
    closes on Grip by the sensor, and a connection reset while Closed (monitored) is its
    declared fault event Slip."""
    from statectl.front.builder.build import load_chart
    from statectl.run.devices import connect, make_driver
    from statectl.run.runtime import EventReceived, Subject

    example = ROOT / "examples" / "pick-and-place"
    text = (example / "gripper-modbus.yaml").read_text().replace("5020", str(server.port))
    (tmp_path / "run.yaml").write_text(text)
    name, options = load_driver_config(tmp_path / "run.yaml")["Gripper"]
    chart = load_chart(example / "gripper.yaml")
    driver = make_driver(name, options, chart=chart)
    clock = WallClock()
    subject = Subject(chart, clock=clock)
    events: list[str] = []
    subject.listen(lambda r: events.append(r.event) if isinstance(r, EventReceived) else None)
    connect(subject, driver, period=0.01)
    subject.start()

    def until(state: str) -> None:
        deadline = time.monotonic() + 5
        subject.run_until_idle()
        while subject.configuration != {state}:
            assert time.monotonic() < deadline, (state, events)
            time.sleep(0.005)
            subject.run_until_idle()

    try:
        subject.post("Grip")
        until("Closing")
        server.set_input(0, True)  # the jaws close
        until("Closed")
        server.stop()
        until("Open")
        assert events == ["Grip", "Grip completion", "Slip"]
    finally:
        subject.close()
        getattr(driver, "close")()  # noqa: B009 - not on the DeviceDriver protocol
        clock.stop()


@pytest.mark.parametrize(
    ("options", "says"),
    [
        ("{host: 5}", "host must be"),
        ("{unit: x}", "unit must be a Modbus device id"),
        ("{unit: 300}", "unit must be a Modbus device id"),
        ("{period: .inf}", "period must be seconds > 0"),
        ("{timeout: .nan}", "timeout must be seconds > 0"),
    ],
)
def test_bad_modbus_link_options_are_d511(tmp_path: Path, options: str, says: str) -> None:
    """A host that is not a name, a unit id outside 0-255 or a period that is not a finite
    number of seconds is a D511 at the options' line (a host of 5 used to end in a
    TypeError traceback from the socket library at the first Grip)."""
    path = tmp_path / "run.yaml"
    path.write_text(f"devices:\n  Gripper:\n    driver: modbus\n    options: {options}\n")
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    found = [(d.code, d.where.line, says in d.message) for d in info.value.diagnostics]
    assert found == [("D511", 4, True)]


# -- registers, outages, RTU (issue 31) ------------------------------------------------------

from statectl.run.devices.modbus.options import Register  # noqa: E402
from statectl.run.devices.modbus.registers import decode_register, encode_register  # noqa: E402

#: (type, byte order, word order, scale, offset, words as read, the model's value)
REGISTERS = [
    ("uint16", "big", "big", 1, 0, [0xFFFE], 65534),
    ("int16", "big", "big", 1, 0, [0xFFFE], -2),
    ("int16", "little", "big", 1, 0, [0xFEFF], -2),
    ("int16", "big", "big", 0.1, -5, [250], 20.0),
    ("int32", "big", "big", 1, 0, [0x0001, 0x0002], 0x10002),
    ("int32", "big", "little", 1, 0, [0x0002, 0x0001], 0x10002),
    ("int32", "big", "big", 1, 0, [0xFFFF, 0xFFFF], -1),
    ("float32", "big", "big", 1, 0, [0x4049, 0x0FDB], 3.1415927410125732),  # ABCD
    ("float32", "big", "little", 1, 0, [0x0FDB, 0x4049], 3.1415927410125732),  # CDAB
    ("float32", "little", "big", 1, 0, [0x4940, 0xDB0F], 3.1415927410125732),  # BADC
    ("float32", "little", "little", 1, 0, [0xDB0F, 0x4940], 3.1415927410125732),  # DCBA
    ("float32", "big", "big", 2, 1, [0x3F80, 0x0000], 3.0),
]


@pytest.mark.parametrize(("kind", "byte", "word", "scale", "offset", "words", "value"), REGISTERS)
def test_register_words_become_the_models_number(
    kind: str, byte: str, word: str, scale: float, offset: float, words: list[int], value: float
) -> None:
    """A register's words, by its type, byte and word order, are raw * scale + offset;
    writing the value gives the same words back."""
    reg = Register("r", "input", 0, kind, scale, offset, byte, word)
    assert decode_register(reg, words) == pytest.approx(value)
    assert encode_register(reg, value) == words


def test_a_register_value_the_type_cannot_hold_is_refused() -> None:
    """Writing 70000 to an int16 register is a StatectlError saying what, not a struct.error."""
    from statectl.kernel.errors import StatectlError

    with pytest.raises(StatectlError, match=r"register r \(int16.* cannot hold 70000"):
        encode_register(Register("r", "holding", 0, "int16"), 70000)


def _float_words(value: float) -> list[int]:
    """``value`` as float32 words with the low word first (the clamp's pressure register)."""
    return encode_register(Register("p", "input", 0, "float32", word_order="little"), value)


class Clamp:
    """examples/modbus/clamp.yaml on a config of examples/modbus, on a WallClock."""

    def __init__(self, config: str, tmp_path: Path, swap: Callable[[str], str]) -> None:
        from statectl.front.builder.build import load_chart
        from statectl.run.devices import connect, make_driver
        from statectl.run.runtime import EventReceived, Subject

        example = ROOT / "examples" / "modbus"
        (tmp_path / "run.yaml").write_text(swap((example / config).read_text()))
        name, options = load_driver_config(tmp_path / "run.yaml")["Clamp"]
        chart = load_chart(example / "clamp.yaml")
        self.driver: Any = make_driver(name, options, chart=chart)
        self.clock = WallClock()
        self.subject = Subject(chart, clock=self.clock)
        self.events: list[tuple[str, Any]] = []
        self.subject.listen(
            lambda r: (
                self.events.append((r.event, r.data)) if isinstance(r, EventReceived) else None
            )
        )
        connect(self.subject, self.driver, period=0.01)
        self.subject.start()

    def until(self, state: str, limit: float = 5.0) -> None:
        deadline = time.monotonic() + limit
        self.subject.run_until_idle()
        while self.subject.configuration != {state}:
            assert time.monotonic() < deadline, (state, self.events)
            time.sleep(0.005)
            self.subject.run_until_idle()

    def close(self) -> None:
        self.subject.close()
        self.driver.close()
        self.clock.stop()


@pytest.mark.parametrize(("pressure", "state"), [(2.7, "Clamped"), (2.2, "Weak")])
def test_registers_are_event_data_that_guards_read(
    server: Server, tmp_path: Path, pressure: float, state: str
) -> None:
    """Clamp() writes the valve coil and the set-point holding register (3.0 bar at 0.1 per
    count: 30); its completion comes once the float32 pressure register reaches 2.0 and
    carries the pressure, which the completion rows' guards compare with min_pressure."""
    c = Clamp("clamp-tcp.yaml", tmp_path, lambda t: t.replace("5020", str(server.port)))
    try:
        c.subject.post("Clamp")
        c.until("Clamping")
        deadline = time.monotonic() + 5
        while not (server.coil(0) and server.holding(10, 1) == [30]):
            assert time.monotonic() < deadline, (server.coil(0), server.holding(10, 1))
            time.sleep(0.005)
        server.set_registers(4, 0, _float_words(pressure))
        c.until(state)
        data = dict(c.events)["Clamp completion"]
        assert list(data) == ["pressure"] and data["pressure"] == pytest.approx(pressure)
    finally:
        c.close()


def test_a_write_in_an_outage_is_retried_then_raises_the_states_fault_event(
    server: Server, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """With the server down, Clamping's declared fault event (Stuck) is raised once for
    the outage (its monitor or the given-up write, whichever comes first), Clamp()'s
    valve write is tried 1 + retries times and given up; the dropped action never
    completes from the inputs alone once the server is back, and the driver says the
    device was left part-way."""
    server.stop()
    swap = lambda t: t.replace("5020", str(server.port)).replace("retries: 3", "retries: 2")  # noqa: E731
    with caplog.at_level(logging.WARNING, logger="statectl.run.devices.modbus"):
        c = Clamp("clamp-tcp.yaml", tmp_path, swap)
        back: Server | None = None
        try:
            c.subject.post("Clamp")
            c.until("Releasing")  # Stuck: Clamping -> Releasing
            assert [e for e, _ in c.events].count("Stuck") == 1, c.events  # once an outage
            deadline = time.monotonic() + 5
            while len(c.driver.failed_writes) < 2:  # Clamp's valve, then Release's
                assert time.monotonic() < deadline, c.driver.failed_writes
                time.sleep(0.005)
            assert "Clamp() write failed" in c.driver.failed_writes[0]
            assert "write_coil(0)" in c.driver.failed_writes[0]
            assert "tried 3 times" in c.driver.failed_writes[0]
            assert [e for e, _ in c.events].count("Stuck") == 1, c.events
            back = Server(server.port)
            back.set_registers(4, 0, _float_words(2.7))  # high enough for Clamp's until
            deadline = time.monotonic() + 5
            while not c.driver.values:
                assert time.monotonic() < deadline
                time.sleep(0.005)
            assert "Clamp completion" not in [e for e, _ in c.events]
            assert "Clamp() write failed" in (c.driver.unfinished() or "")
            assert any("answering again" in m for m in caplog.messages), caplog.messages
        finally:
            c.close()
            if back is not None:
                back.stop()


def test_a_write_given_up_raises_the_actions_fault_event(server: Server) -> None:
    """In a state no monitor watches, a coil write that fails 1 + retries times raises
    the action's fault event with what failed, and the action never completes: the
    input that reads true later is no completion (it used to be reported as one)."""
    port = server.port
    server.stop()
    actions = {"Grip": {**ACTIONS["Grip"], "fault": "Jam"}}
    g = Gripper(port, actions=actions, retries=2, retry_delay=0.01)
    back: Server | None = None
    try:
        g.call("Grip")
        event, data = g.wait(lambda: g.events)[0]
        assert event == "Jam" and "Grip() write failed" in data["detail"]
        assert "write_coil(0) failed" in data["detail"] and "tried 3 times" in data["detail"]
        back = Server(port)
        back.set_input(0, True)
        g.wait(lambda: g.driver.values.get("closed"))
        assert g.events == [(event, data)]
    finally:
        g.close()
        if back is not None:
            back.stop()


def test_the_fault_event_of_a_write_is_the_one_its_state_declares() -> None:
    """Without an action's ``fault``, a given-up write raises the fault event declared for
    the state the method's command enters: Clamp() enters Clamping, which declares Stuck;
    Release() enters Releasing, which declares none."""
    from statectl.front.builder.build import load_chart
    from statectl.run.devices.modbus.driver import fault_event_for

    chart = load_chart(ROOT / "examples" / "modbus" / "clamp.yaml")
    assert (fault_event_for(chart, "Clamp"), fault_event_for(chart, "Release")) == ("Stuck", None)


def test_a_write_is_retried_until_the_server_answers_within_the_bound(server: Server) -> None:
    """A write that fails while the server restarts lands on a later try: the action
    completes and no fault is raised."""
    port = server.port
    server.stop()
    g = Gripper(port, retries=100, retry_delay=0.02)
    back: Server | None = None
    try:
        g.call("Grip")
        deadline = time.monotonic() + 5
        while not g.driver.outages:
            assert time.monotonic() < deadline
            time.sleep(0.005)
        back = Server(port)
        g.wait(lambda: back is not None and back.coil(0))
        back.set_input(0, True)
        event, _ = g.wait(lambda: g.events)[0]
        assert event == "Grip completion" and g.driver.failed_writes == []
    finally:
        g.close()
        if back is not None:
            back.stop()


def test_pymodbus_says_one_line_per_outage_and_statectl_warns_of_both_ends(
    server: Server, caplog: pytest.LogCaptureFixture
) -> None:
    """During an outage pymodbus's own "Connection to ... failed" passes once (it used to
    come ~80 times a second); statectl warns when the link goes and when it comes back,
    and a second outage is one more pymodbus line."""
    from statectl.run.devices.modbus import QUIET

    port = server.port
    with caplog.at_level(logging.WARNING):
        g = Gripper(port)
        servers: list[Server] = []
        try:
            g.wait(lambda: g.driver.reads)
            for n in (1, 2):
                (servers[-1] if servers else server).stop()
                dropped = QUIET.dropped + 10  # ten failed polls more
                g.wait(lambda d=dropped: QUIET.dropped >= d)
                servers.append(Server(port))
                g.wait(lambda n=n: sum("answering again" in m for m in caplog.messages) == n)
                ours = [r.getMessage() for r in caplog.records if r.name.startswith("pymodbus")]
                assert len(ours) == n, ours
        finally:
            g.close()
            for s in servers:
                s.stop()
    mine = [r for r in caplog.records if r.name == "statectl.run.devices.modbus"]
    assert [r.levelno for r in mine] == [logging.WARNING] * 4, [r.getMessage() for r in mine]
    assert ["answering again" in r.getMessage() for r in mine] == [False, True, False, True]


def test_a_live_run_left_part_way_by_an_outage_exits_1_and_says_so(tmp_path: Path) -> None:
    """`statectl run gripper.yaml --config ... --realtime` with the server down: Grip's
    valve write is given up (Closing declares no fault event), the run ends with its
    final-state line, says the Gripper was left part-way, and exits 1 (it used to exit 0
    with no final-state line)."""
    import io

    from statectl.channels.cli.run import run

    example = ROOT / "examples" / "pick-and-place"
    text = (example / "gripper-modbus.yaml").read_text().replace("5020", str(free_port()))
    (tmp_path / "run.yaml").write_text(text + "      retries: 1\n      retry_delay: 0.01\n")
    out, err = io.StringIO(), io.StringIO()
    got = run(
        str(example / "gripper.yaml"),
        config=str(tmp_path / "run.yaml"),
        realtime=True,
        events=io.StringIO("Grip\n+1.5\n"),
        out=out,
        err=err,
    )
    assert got == 1, (out.getvalue(), err.getvalue())
    assert "final state Closing" in out.getvalue()
    said = err.getvalue()
    assert "Gripper was left part-way by a bus outage" in said and "tried 2 times" in said
    assert "1 device(s) left part-way" in said


@pytest.mark.parametrize(
    ("options", "says"),
    [
        ("{registers: {p: {table: coil, address: 0}}}", "registers.p.table must be holding"),
        ("{registers: {p: {table: input, address: 0, type: float64}}}", "registers.p.type"),
        ("{registers: {p: {table: input, address: 0, word_order: middle}}}", "word_order"),
        ("{registers: {p: {table: input, address: 0, scale: 0}}}", "scale must not be 0"),
        ("{registers: {a: {table: input, address: 0}, b: {table: input, address: 200}}}",
         "span 201 addresses"),
        ("{transport: rtu}", "serial must be the serial port"),
        ("{transport: udp}", "transport must be tcp or rtu"),
        ("{transport: rtu, serial: /dev/x, parity: X}", "parity must be N, E or O"),
        ("{retries: -1}", "retries must be"),
        ("{retry_delay: 0}", "retry_delay must be seconds > 0"),
        ("{actions: {Grip: {until: {nozzle: true}}}}", "'nozzle' is not one of the inputs"),
        ("{registers: {p: {table: input, address: 0}}, actions: {Grip: {until: {p: 3}}}}",
         "until.p must be {at_least"),
        ("{registers: {p: {table: input, address: 0}}, actions: {Grip: {set: {p: 3}}}}",
         "'p' is not one of the coils or holding registers"),
        ("{actions: {Grip: {data: [nope]}}}", "data: 'nope' is not one of the inputs"),
        ("{actions: {Grip: {fault: 3}}}", "Grip.fault must be an event name"),
    ],
)  # fmt: skip
def test_bad_register_link_and_action_options_are_d511(
    tmp_path: Path, options: str, says: str
) -> None:
    """Each bad register, transport, retry or action option is one D511 at the options'
    line, saying what is wrong (none of these options existed before)."""
    path = tmp_path / "run.yaml"
    path.write_text(f"devices:\n  Gripper:\n    driver: modbus\n    options: {options}\n")
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    found = [(d.code, d.where.line, says in d.message) for d in info.value.diagnostics]
    assert found == [("D511", 4, True)], [d.message for d in info.value.diagnostics]


@pytest.mark.parametrize("config", ["clamp-tcp.yaml", "clamp-rtu.yaml"])
def test_the_modbus_example_configs_load(config: str) -> None:
    """examples/modbus's run configs are valid for the modbus driver and its clamp."""
    name, options = load_driver_config(ROOT / "examples" / "modbus" / config)["Clamp"]
    assert (name, options["transport"]) == ("modbus", config[6:9])


class SerialLine:
    """Two pseudo-terminals joined by a relay thread, as ``socat`` joins them: the driver
    opens one end, a pymodbus RTU server the other (a null-modem cable, in a process)."""

    def __init__(self) -> None:
        import os
        import tty

        self.masters: list[int] = []
        self.slaves: list[int] = []
        self.paths: list[str] = []
        for _ in range(2):
            master, slave = os.openpty()
            tty.setraw(slave)
            self.masters.append(master)
            self.slaves.append(slave)
            self.paths.append(os.ttyname(slave))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._relay, daemon=True)
        self._thread.start()

    def _relay(self) -> None:
        import os
        import select

        a, b = self.masters
        while not self._stop.is_set():
            ready, _, _ = select.select([a, b], [], [], 0.02)
            for fd in ready:
                try:
                    data = os.read(fd, 1024)
                except OSError:
                    continue
                os.write(b if fd == a else a, data)

    def close(self) -> None:
        import os

        self._stop.set()
        self._thread.join(2)
        for fd in self.masters + self.slaves:
            os.close(fd)


class RtuServer(Server):
    """The test's server on a serial line (RTU framing) instead of TCP."""

    def __init__(self, path: str) -> None:
        self.path = path
        super().__init__(port=1)

    def _run(self) -> None:
        from pymodbus import FramerType
        from pymodbus.server import ModbusSerialServer

        async def serve() -> None:
            self.server = ModbusSerialServer(  # type: ignore[assignment]
                self.context, framer=FramerType.RTU, port=self.path, baudrate=115200
            )
            await self.server.serve_forever()  # type: ignore[union-attr]

        asyncio.set_event_loop(self.loop)
        self.loop.run_until_complete(serve())
        self.loop.close()

    def _started(self) -> None:
        time.sleep(0)  # the serial server opens its port on the loop; the client retries


def test_the_clamp_runs_on_modbus_rtu_over_a_serial_line(tmp_path: Path) -> None:
    """examples/modbus/clamp-rtu.yaml, its serial port changed to a pseudo-terminal whose
    other end a pymodbus RTU server holds: Clamp() writes the valve and the set-point and
    completes on the float32 pressure, as on TCP."""
    line = SerialLine()
    server = RtuServer(line.paths[1])
    swap = lambda t: t.replace("/dev/ttyUSB0", line.paths[0]).replace(  # noqa: E731
        "baudrate: 19200\n      parity: E", "baudrate: 115200\n      parity: N"
    )
    c = Clamp("clamp-rtu.yaml", tmp_path, swap)
    try:
        assert c.driver.where == f"Modbus RTU {line.paths[0]} unit 1"
        c.subject.post("Clamp")
        c.until("Clamping")
        deadline = time.monotonic() + 5
        while not (server.coil(0) and server.holding(10, 1) == [30]):
            assert time.monotonic() < deadline
            time.sleep(0.005)
        server.set_registers(4, 0, _float_words(2.6))
        c.until("Clamped")
        assert dict(c.events)["Clamp completion"]["pressure"] == pytest.approx(2.6)
    finally:
        c.close()
        server.stop()
        line.close()


def test_a_fault_row_on_a_superstate_is_the_writes_fault_event(tmp_path: Path) -> None:
    """A fault event declared on the superstate of the state a command enters is the one
    a given-up write raises (a fault row on a superstate leaves every state inside it)."""
    from statectl.front.builder.build import load_chart
    from statectl.run.devices.modbus.driver import fault_event_for

    device = tmp_path / "valve.yaml"
    device.write_text(
        "device: Valve\n"
        "states:\n"
        "  - {state: Idle, control: default, api: Open()}\n"
        "  - {state: Working, control: monitoring required, api: Open()}\n"
        "  - {state: Opening, parent: Working, control: event trigger required, api: Open()}\n"
        "events:\n"
        "  - {event: Open, old: Idle, new: Opening, kind: command, api: Open}\n"
        "  - {event: Open completion, old: Opening, new: Idle, kind: completion, api: Open}\n"
        "  - {event: Jam, old: Working, new: Idle, kind: fault, api: Open}\n"
    )
    assert fault_event_for(load_chart(device), "Open") == "Jam"
