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

from statectl.front.observers import Notification
from statectl.kernel.errors import DiagnosticError
from statectl.run.devices import load_driver_config
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

    def __init__(self) -> None:
        self.port = free_port()
        self.delay = 0.0
        device = ModbusDeviceContext(
            di=ModbusSequentialDataBlock(1, [False] * 80),
            co=ModbusSequentialDataBlock(1, [False] * 16),
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

    def stop(self) -> None:
        if self.thread.is_alive() and self.server is not None:
            self._on_loop(self.server.shutdown())
            self.thread.join(5)


class Gripper:
    """A ModbusIO gripper bound to a recording report on a WallClock."""

    def __init__(self, port: int, **options: Any) -> None:
        self.events: list[tuple[str, Any]] = []
        self.clock = WallClock()
        self.driver = ModbusIO(
            port=port, coils=COILS, inputs=INPUTS, actions=ACTIONS, timeout=0.3, **options
        )
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
        assert [c.function for c in g.driver.api_log] == ["actuate"]
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
