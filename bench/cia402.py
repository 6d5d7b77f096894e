"""Bus driver benchmarks (not tests): the CiA 402 driver's enable time, the Modbus poll rate.

Run: ``python bench/cia402.py [--rounds N] [--seconds S]`` (needs the ``canopen``
and ``modbus`` extras). Targets (issue 11):

- CiA 402: from the observer call ``Movement()`` to the drive's Operation-enabled
  statusword seen by the driver (the Subject's observer), on python-can's
  virtual bus, against a bare python-can client sending the same three
  controlwords (0x06, 0x07, 0x0F) and waiting for each statusword from the same
  simulated drive, in the same run, rounds interleaved: driver <= 2x bare.
- Modbus: one ModbusIO reading 64 discrete inputs per request from a pymodbus
  server on 127.0.0.1 (same process): >= 500 reads/s.
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import statistics
import struct
import sys
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "src"))

import can

from statectl.front.observers import Notification
from statectl.run.devices.cia402 import Cia402SimDriver
from statectl.run.devices.cia402.profile import PowerState, decode
from statectl.run.devices.modbus import ModbusIO
from statectl.run.runtime import WallClock

_PDO = struct.Struct("<Hi")


class Timed(Cia402SimDriver):
    """The driver, noting when it first sees Operation enabled after a start."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.enabled = threading.Event()

    def _on_tpdo(self, pdo: Any) -> None:
        super()._on_tpdo(pdo)
        if decode(self.statusword) is PowerState.OPERATION_ENABLED:
            self.enabled.set()


def _disable(bus: can.BusABC, node: int, drive: Any) -> None:
    """Put the drive back in Switch on disabled (controlword 0x00) and wait for it."""
    bus.send(can.Message(arbitration_id=0x200 + node, data=_PDO.pack(0, 0), is_extended_id=False))
    deadline = time.monotonic() + 2
    while drive.state is not PowerState.SWITCH_ON_DISABLED:
        if time.monotonic() > deadline:
            raise SystemExit("the simulated drive did not disable")
        time.sleep(0.001)
    time.sleep(0.005)  # let the statusword reach everyone


def _bare(bus: can.BusABC, node: int) -> float:
    """Three controlwords, each answered by its statusword: the bare bus round trips."""
    want = {
        0x06: PowerState.READY,
        0x07: PowerState.SWITCHED_ON,
        0x0F: PowerState.OPERATION_ENABLED,
    }
    while bus.recv(0) is not None:  # drop what queued while idle
        pass
    t0 = time.perf_counter()
    for cw, state in want.items():
        bus.send(
            can.Message(arbitration_id=0x200 + node, data=_PDO.pack(cw, 0), is_extended_id=False)
        )
        while True:
            msg = bus.recv(1.0)
            if msg is None:
                raise SystemExit("no statusword on the bare bus")
            if msg.arbitration_id == 0x180 + node and decode(_PDO.unpack(msg.data)[0]) is state:
                break
    return time.perf_counter() - t0


def _driver(driver: Timed) -> float:
    driver.enabled.clear()
    note = Notification("Motor", 0, "Moving", "Movement", "Movement", {"target": 0})
    t0 = time.perf_counter()
    driver.update(note)
    if not driver.enabled.wait(2.0):
        raise SystemExit("the driver did not reach Operation enabled")
    return time.perf_counter() - t0


def bench_cia402(rounds: int) -> tuple[float, float]:
    clock = WallClock()
    driver = Timed()
    driver.bind(lambda e, d: None, clock)
    bus = can.Bus(interface="virtual", channel=driver.channel)
    drive, node = driver.drive, driver.node_id
    bare: list[float] = []
    ours: list[float] = []
    try:
        for i in range(rounds + 3):
            order = ("bare", "driver") if i % 2 else ("driver", "bare")
            for who in order:
                _disable(bus, node, drive)
                driver._phase = None
                if who == "bare":
                    t = _bare(bus, node)
                    (bare if i >= 3 else []).append(t)
                else:
                    t = _driver(driver)
                    (ours if i >= 3 else []).append(t)
                time.sleep(0.01)
    finally:
        bus.shutdown()
        driver.close()
        clock.stop()
    return statistics.median(bare), statistics.median(ours)


def bench_modbus(seconds: float) -> float:
    from pymodbus.datastore import (
        ModbusDeviceContext,
        ModbusSequentialDataBlock,
        ModbusServerContext,
    )
    from pymodbus.server import ModbusTcpServer

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    device = ModbusDeviceContext(di=ModbusSequentialDataBlock(1, [False] * 64))
    context = ModbusServerContext(devices=device, single=True)
    loop = asyncio.new_event_loop()
    holder: dict[str, Any] = {}

    async def serve() -> None:
        holder["server"] = ModbusTcpServer(context, address=("127.0.0.1", port))
        await holder["server"].serve_forever()

    thread = threading.Thread(target=lambda: loop.run_until_complete(serve()), daemon=True)
    thread.start()
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            break
        except OSError:
            time.sleep(0.01)
    clock = WallClock()
    io = ModbusIO(port=port, inputs={f"in{i}": i for i in range(64)}, period=3600.0)
    io.bind(lambda e, d: None, clock)
    try:
        if not io.poll_once():  # connect
            raise SystemExit("the Modbus server does not answer")
        start, t0 = io.reads, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            io.poll_once()
        rate = (io.reads - start) / (time.perf_counter() - t0)  # successful reads only
        if len(io.values) != 64:
            raise SystemExit(f"read {len(io.values)} inputs, not 64")
    finally:
        io.close()
        clock.stop()
        asyncio.run_coroutine_threadsafe(holder["server"].shutdown(), loop).result(5)
        thread.join(5)
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    bare, ours = bench_cia402(args.rounds)
    ratio = ours / bare
    print(f"CiA 402 enable (0x06, 0x07, 0x0F), median of {args.rounds} interleaved rounds:")
    print(f"  bare python-can round trips   {bare * 1e3:8.2f} ms")
    print(f"  Movement() -> Op. enabled     {ours * 1e3:8.2f} ms")
    print(f"  ratio                         {ratio:8.2f}x  (target <= 2x: "
          f"{'met' if ratio <= 2 else 'NOT met'})")  # fmt: skip
    rate = bench_modbus(args.seconds)
    print(f"Modbus: 64 discrete inputs per read, {args.seconds:.0f} s on loopback:")
    print(f"  {rate:8.0f} reads/s  (target >= 500: {'met' if rate >= 500 else 'NOT met'})")


if __name__ == "__main__":
    main()
