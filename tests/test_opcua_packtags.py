"""PackTags (OPC 30050) of a PackML device: ``Status`` and ``Admin`` read by an asyncua
client after each step, filled from the unit's state and its declared data items.

The unit is served in this process on the server's own loop thread; the client runs on
this thread's loop. Loopback only, a free port; the server and the system are stopped.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest

from statectl.run.journal import load_device
from test_opcua import free_port, run

pytest.importorskip("asyncua")

from asyncua import Client, ua

from statectl.channels.opcua.packml import PACKML_URI
from statectl.channels.opcua.packtags import tag_items

UNIT = """\
device: Unit
profile: packml
data:
  prod_processed_count: 0
  ProdDefectiveCount: 0
  stop_reason: 0
  speed: 1.5
states:
  - {state: Stopped, number: 2, control: default, ignore: [Start, Produce, Stop]}
  - {state: Idle, number: 4, ignore: [Reset, Produce, Stop]}
  - {state: Execute, number: 6, ignore: [Reset, Start]}
events:
  - {event: Reset, old: Stopped, new: Idle}
  - {event: Start, old: Idle, new: Execute}
  - event: Produce
    old: Execute
    new: Execute
    data: {good: bool}
    assign: >-
      prod_processed_count = prod_processed_count + 1;
      ProdDefectiveCount = ProdDefectiveCount + (0 if _event.data.good else 1)
  - {event: Stop, old: Execute, new: Stopped, data: {reason: any},
     assign: {stop_reason: _event.data.reason}}
"""


def test_tags_are_filled_by_items_of_their_name_in_either_spelling() -> None:
    """A tag's own name, its snake_case spelling, or unit_mode for the mode; nothing else."""
    data = {"prod_processed_count": 0, "ProdDefectiveCount": 0, "unit_mode": 2, "speed": 1.0}
    assert tag_items(data) == {
        "UnitModeCurrent": "unit_mode",
        "ProdProcessedCount": "prod_processed_count",
        "ProdDefectiveCount": "ProdDefectiveCount",
    }


def test_a_packml_client_reads_the_packtags_after_each_step(tmp_path: Path) -> None:
    """StateCurrent follows the PackML number, UnitModeCurrent is Production (1), the
    counters and the stop reason follow the data items; a text stop reason in the Int32
    tag keeps the last value, marked UncertainLastUsableValue; the PackTags folder and
    the device lead to the same Status and Admin; a tag no item fills is not there."""
    from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
    from statectl.run.runtime import SimClock
    from statectl.run.system import DeviceSetup, System

    path = tmp_path / "unit.yaml"
    path.write_text(UNIT, encoding="utf-8")
    chart = load_device(str(path)).chart
    system = System((DeviceSetup(chart.name, chart),), SimClock())
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    server = OpcuaServer(system, OpcuaSettings(endpoint=url, security=("None",)))
    server.start()
    try:
        system.start()
        server.refresh()

        async def go() -> dict[str, Any]:
            async with Client(url, timeout=10) as client:
                ns = await client.get_namespace_index(PACKML_URI)
                unit = await client.nodes.objects.get_child(["2:Unit"])
                names = {
                    "state": [f"{ns}:Status", f"{ns}:StateCurrent"],
                    "mode": [f"{ns}:Status", f"{ns}:UnitModeCurrent"],
                    "processed": [f"{ns}:Admin", f"{ns}:ProdProcessedCount"],
                    "defective": [f"{ns}:Admin", f"{ns}:ProdDefectiveCount"],
                    "stop": [f"{ns}:Admin", f"{ns}:StopReason"],
                }
                tags = {k: await unit.get_child(v) for k, v in names.items()}
                via = await unit.get_child(["2:PackTags", f"{ns}:Status", f"{ns}:StateCurrent"])
                seen: dict[str, Any] = {"same": via.nodeid == tags["state"].nodeid}
                try:
                    await unit.get_child([f"{ns}:Status", f"{ns}:CurMachSpeed"])
                    seen["speed"] = "there"
                except ua.UaError:
                    seen["speed"] = "absent"

                async def read() -> tuple[Any, ...]:  # an uncertain value reads as well
                    values = [await t.read_data_value(False) for t in tags.values()]
                    return tuple(v.Value.Value for v in values)

                async def after(*steps: tuple[str, Any], want: tuple[Any, ...]) -> Any:
                    for event, data in steps:
                        system.post("Unit", event, data)
                    system.drain()
                    got = await read()
                    for _ in range(100):
                        if got == want:
                            break
                        await asyncio.sleep(0.05)
                        got = await read()
                    return got

                seen["start"] = await after(want=(2, 1, 0, 0, 0))
                seen["execute"] = await after(
                    ("Reset", None), ("Start", None), want=(6, 1, 0, 0, 0)
                )
                seen["produced"] = await after(
                    ("Produce", {"good": True}), ("Produce", {"good": False}),
                    ("Produce", {"good": True}), want=(6, 1, 3, 1, 0),
                )  # fmt: skip
                seen["stopped"] = await after(("Stop", {"reason": 42}), want=(2, 1, 3, 1, 42))
                await after(("Reset", None), ("Start", None), want=(6, 1, 3, 1, 42))
                seen["text"] = await after(("Stop", {"reason": "jam"}), want=(2, 1, 3, 1, 42))
                value = await tags["stop"].read_data_value(raise_on_bad_status=False)
                seen["status"] = value.StatusCode.name
                seen["type"] = await tags["processed"].read_data_type_as_variant_type()
                return seen

        seen = run(go())
    finally:
        server.stop()
        system.close()
    assert seen["same"] and seen["speed"] == "absent"
    assert seen["start"] == (2, 1, 0, 0, 0)
    assert seen["execute"] == (6, 1, 0, 0, 0)
    assert seen["produced"] == (6, 1, 3, 1, 0)
    assert seen["stopped"] == (2, 1, 3, 1, 42)
    assert seen["text"] == (2, 1, 3, 1, 42)
    assert seen["status"] == "UncertainLastUsableValue"
    assert seen["type"] == ua.VariantType.Int32
