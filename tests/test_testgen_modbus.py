"""Generated suites accept (and reject) a real Modbus device: ModbusIO on a pymodbus server.

The gripper of examples/pick-and-place (gripper.yaml, run config gripper-modbus.yaml):
its completions come from discrete inputs (the jaw sensors) that the plant sets when
the driver writes the valve coils. The generated modules run in a subprocess whose
conftest makes, per device, a pymodbus TCP server on 127.0.0.1 and a free port with
a simulated gripper behind it, and a ModbusIO bound to it; no ``statectl_api``.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar

import pytest

from statectl.channels.cli import main
from statectl.front.builder.build import load_chart
from statectl.front.observers import Notification
from statectl.out.testgen.harness import DeviceUnderTest
from statectl.run.devices.base import Driver
from test_testgen import counts, run_pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
GRIPPER = EXAMPLES / "pick-and-place" / "gripper.yaml"
CLAMP = EXAMPLES / "modbus" / "clamp.yaml"
CRITERIA = ["rows", "transitions", "states", "pairs"]

#: The conftest beside the generated modules: per device, a plant on its own server.
CONFTEST = '''
"""The generated tests on ModbusIO, each device against a simulated plant on Modbus TCP."""

import asyncio
import socket
import threading
import time
from pathlib import Path

import pytest
from pymodbus.datastore import (
    ModbusDeviceContext,
    ModbusSequentialDataBlock,
    ModbusServerContext,
)
from pymodbus.server import ModbusTcpServer

from statectl.channels.runconfig import load_driver_config
from statectl.run.devices.modbus import ModbusIO, Register
from statectl.run.devices.modbus.registers import encode_register

EXAMPLES = Path(__EXAMPLES__)
CONFIGS = {"Gripper": "pick-and-place/gripper-modbus.yaml", "Clamp": "modbus/clamp-tcp.yaml"}


class Plant:
    """A device's I/O on a pymodbus TCP server on 127.0.0.1 and a free port (its own loop
    thread); ``written`` sees every write the driver makes."""

    def __init__(self, options):
        self.options = options
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.io = ModbusDeviceContext(
            co=ModbusSequentialDataBlock(1, [False] * 8),
            di=ModbusSequentialDataBlock(1, [False] * 8),
            hr=ModbusSequentialDataBlock(1, [0] * 16),
            ir=ModbusSequentialDataBlock(1, [0] * 16),
        )
        self.store = self.io.setValues
        self.io.setValues = self.set_values
        self.start()  # the inputs at power-on
        self.loop = asyncio.new_event_loop()
        self.server = None
        self.thread = threading.Thread(target=self.loop.run_until_complete, args=(self.serve(),))
        self.thread.start()
        deadline = time.monotonic() + 5
        while True:  # listening?
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "the Modbus server did not start"
                time.sleep(0.01)

    async def serve(self):
        context = ModbusServerContext(devices=self.io, single=True)
        self.server = ModbusTcpServer(context, address=("127.0.0.1", self.port))
        await self.server.serve_forever()

    def start(self):
        pass

    def set_values(self, function, address, values):
        done = self.store(function, address, values)
        if self.io.decode(function) in ("c", "h"):  # a coil or a holding register
            self.written()
        return done

    def coil(self, name):
        return bool(self.io.getValues(1, self.options["coils"][name], 1)[0])

    def stop(self):
        if self.server is not None:
            asyncio.run_coroutine_threadsafe(self.server.shutdown(), self.loop).result(5)
        self.thread.join(5)


class Gripper(Plant):
    """Jaws that follow the valves as soon as they are written."""

    def start(self):
        self.sense(closed=False)

    def written(self):
        close, open_ = self.coil("close_valve"), self.coil("open_valve")
        if close != open_:
            self.sense(closed=close)

    def sense(self, closed):
        inputs = self.options["inputs"]
        self.store(2, inputs["jaws_closed"], [closed])
        self.store(2, inputs["jaws_open"], [not closed])


class Clamp(Plant):
    """The pressure settles 2 s after the last write: at the set-point with the valve
    open, at 0 with it closed (the fault and monitor tests of Clamping assume a call
    takes more than 0.5 s)."""

    PRESSURE = Register("pressure", "input", 0, "float32", word_order="little")
    settling = None

    def written(self):  # on the server's loop: it answers the driver's write
        setpoint = self.io.getValues(3, 10, 1)[0] * 0.1  # 0.1 bar a count
        target = setpoint if self.coil("valve") else 0.0
        words = encode_register(self.PRESSURE, target)
        if self.settling is not None:
            self.settling.cancel()  # the valve changed again before it settled
        self.settling = self.loop.call_later(2.0, self.store, 4, 0, words)


PLANTS, DRIVER = {"Gripper": Gripper, "Clamp": Clamp}, ModbusIO


@pytest.fixture
def statectl_new_driver():
    made = []

    def new(chart):  # a device per test (per example in the Hypothesis module)
        stop()  # the one before is done with: a fresh device replaces it
        _, options = load_driver_config(EXAMPLES / CONFIGS[chart.name])[chart.name]
        plant = PLANTS[chart.name](options)
        driver = DRIVER(**(options | {"port": plant.port}), chart=chart)
        made.append((plant, driver))
        return driver

    def stop():
        while made:
            plant, driver = made.pop()
            driver.close()
            plant.stop()

    yield new
    stop()
'''

#: Broken variants, appended to the conftest: what each breaks.
BROKEN = {
    "wrong API": '''
class OldModbusIO(ModbusIO):
    """Logs each call as actuate('Grip'), the device's API as ModbusIO once named it."""

    def log_call(self, function, *args):
        super().log_call("actuate", function, *args)


DRIVER = OldModbusIO
''',
    "jaws stuck open": '''
class StuckGripper(Gripper):
    """The close valve opens, but the jaws never reach the closed sensor."""

    def sense(self, closed):
        super().sense(closed=False)


PLANTS["Gripper"] = StuckGripper
''',
}


def generate(tmp_path: Path, tables: list[Path], criteria: list[str], broken: str = "") -> Path:
    """The modules of ``tables`` for each criterion, and the conftest (``broken``'s)."""
    for path in tables:
        for criterion in criteria:
            argv = ["testgen", str(path), "--criterion", criterion, "--out", str(tmp_path)]
            assert main(argv) == 0
    text = CONFTEST.replace("__EXAMPLES__", repr(str(EXAMPLES))) + BROKEN.get(broken, "")
    (tmp_path / "conftest.py").write_text(text, encoding="utf-8")
    return tmp_path


def test_the_generated_suites_accept_modbusio_on_a_real_server(tmp_path: Path) -> None:
    """Every test of the rows and transitions modules passes on ModbusIO over Modbus TCP,
    probes included (completions from the jaw sensors, the fault and monitor of Closed),
    with no statectl_api: the driver logs each call under its method's own name."""
    pytest.importorskip("pymodbus")
    result = run_pytest(generate(tmp_path, [GRIPPER, CLAMP], CRITERIA), "-rfs")
    found = counts(result)
    assert result.returncode == 0, result.stdout[-4000:]
    assert found.get("passed", 0) >= 40 and "failed" not in found, result.stdout[-2000:]
    assert "skipped" not in found, result.stdout[-2000:]  # Driver.inject_fault: faults run


#: (broken variant, what the generated rows module must say)
FAILS = [
    (
        "wrong API",
        "after Grip: Grip(): expected the API call Grip(), the driver called "
        "[\"OldModbusIO.actuate('Grip')\"]",
    ),
    (
        "jaws stuck open",
        "after Grip -> (until Grip completion): expected the device to report Grip "
        "completion within 5 s; it reported nothing",
    ),
]


@pytest.mark.parametrize(("broken", "says"), FAILS, ids=[b for b, _ in FAILS])
def test_the_generated_suite_rejects_a_broken_driver_or_plant(
    tmp_path: Path, broken: str, says: str
) -> None:
    """A driver that logs the wrong API function, or a plant whose sensor never comes,
    fails the rows module, naming the call or the completion that did not come."""
    pytest.importorskip("pymodbus")
    result = run_pytest(generate(tmp_path, [GRIPPER], ["rows"], broken=broken), "-rfs")
    assert result.returncode == 1, result.stdout[-4000:]
    assert counts(result).get("failed", 0) >= 1
    assert says in result.stdout, result.stdout[-4000:]


# -- the runtime adapter's rule 5, on a driver in wall time with no bus ----------------------


class WallGripper(Driver):
    """A device in wall time whose work is done at once: each call's completion is
    reported as soon as the call is made, or when :meth:`finish` says (a bus thread)."""

    realtime: ClassVar[bool] = True

    def __init__(self, *, at_once: bool = True, twice: bool = False) -> None:
        super().__init__()
        self.at_once, self.twice = at_once, twice
        self.owed: list[str] = []

    def serves(self) -> frozenset[str]:
        return frozenset({"Grip", "Release"})

    def update(self, notification: Notification) -> None:
        with self._lock:
            self.log_call(notification.method)
        self.owed.append(f"{notification.method} completion")
        if self.at_once:
            self.finish()

    def finish(self) -> None:
        """Report every completion owed, from another thread as a bus does."""
        done, self.owed = self.owed, []
        for event in done * (2 if self.twice else 1):
            t = threading.Thread(target=self.report, args=(event,))
            t.start()
            t.join()


@pytest.fixture
def device() -> Iterator[Any]:
    made: list[DeviceUnderTest] = []

    def new(driver: WallGripper) -> DeviceUnderTest:
        made.append(DeviceUnderTest(load_chart(GRIPPER), driver))
        return made[-1]

    yield new
    for d in made:
        d.impl.close()


def test_a_wall_time_report_waits_until_time_runs(device: Any) -> None:
    """A completion reported while the test sends its events is taken only when time
    runs: the device stays where the test's event left it (it was taken at once, before)."""
    d = device(WallGripper())
    d.send("Grip")
    d.expect(states=["Closing"], invokes=[[0, "Grip"]])
    d.complete("Grip completion")
    d.expect(states=["Closed"], invokes=[], raised=["Grip completion"])


@pytest.mark.parametrize("at_once", [True, False], ids=["reported before", "reported after"])
def test_the_devices_report_of_a_completion_the_test_sent_is_dropped(
    device: Any, at_once: bool
) -> None:
    """The test sends Grip completion in the device's place; the device's own report of
    that call, made before or after the test's, is dropped and noted, so the monitor
    probe of Closed sees no event the device took by itself."""
    driver = WallGripper(at_once=at_once)
    d = device(driver)
    d.given("Grip", "Grip completion")
    driver.finish()
    d.assert_monitored("Closed")
    assert d.runtime.wall.stood_in == ["Grip completion"]


def test_a_completion_reported_twice_is_still_seen(device: Any) -> None:
    """Only a report the test stood in for is dropped: a device that reports its
    completion twice fails the completion probe, naming the second report."""
    d = device(WallGripper(twice=True))
    d.send("Grip")
    d.complete("Grip completion")
    took = r"the device took \['Grip completion', 'Grip completion'\]"
    with pytest.raises(AssertionError, match=took):
        d.expect(states=["Closed"], invokes=[], raised=["Grip completion"])
