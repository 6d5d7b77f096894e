"""Typed OPC UA methods (issue 31): a command event that declares its data fields takes
them as typed inputs (``Press(pressure: Double, part: String)``), checked by the server.

The press (examples/press/press.yaml) is served in this process with a user on None
security; an asyncua client on this thread's loop calls it. Loopback only, free ports;
everything started here is stopped.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from typing import Any

import pytest

from statectl.run.journal import load_device
from statectl.run.runtime import SimClock
from statectl.run.system import DeviceSetup, System
from support import ROOT

pytest.importorskip("asyncua")

from asyncua import Client, ua

from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
from test_opcua import PASSWORD, USER, free_port, run

PRESS = ROOT / "examples" / "press" / "press.yaml"
errors = ua.uaerrors


class Press:
    """The press served in this process; its owner runs on its own thread."""

    def __init__(self) -> None:
        chart = load_device(str(PRESS)).chart
        self.system = System((DeviceSetup("Press", chart),), SimClock())
        self.url = f"opc.tcp://127.0.0.1:{free_port()}"
        settings = OpcuaSettings(endpoint=self.url, user=USER, password=PASSWORD,
                                 security=("None",))  # fmt: skip
        self.server = OpcuaServer(self.system, settings)
        self.server.start()
        self.system.start()
        self.halt = self.system.start_owner(paced=False)

    def close(self) -> None:
        self.halt()
        self.server.stop()
        self.system.close()

    def state(self) -> tuple[frozenset[str], Any]:
        with self.system.owner:
            subject = self.system.subjects["Press"]
            return subject.configuration, subject.data["strokes"]

    def call(self, method: str, *inputs: Any) -> Any:
        """The method's outputs, or the name of the bad status it got."""

        async def go() -> Any:
            client = Client(self.url, timeout=10)
            client.set_user(USER)
            client.set_password(PASSWORD)
            async with client:
                press = await client.nodes.objects.get_child(["2:Press"])
                node = await press.get_child([f"2:{method}"])
                try:
                    return await press.call_method(node, *inputs)
                except errors.UaStatusCodeError as exc:
                    return type(exc).__name__

        return run(go())


@pytest.fixture
def press() -> Iterator[Press]:
    served = Press()
    try:
        yield served
    finally:
        served.close()


def test_a_method_takes_its_events_declared_fields_as_typed_inputs(press: Press) -> None:
    """Press declares {pressure: float, part: str}: two inputs, Double and String; Reset
    declares nothing and keeps the one optional Data input (JSON)."""

    async def go() -> dict[str, list[tuple[str, str]]]:
        async with Client(press.url, timeout=10) as client:
            device = await client.nodes.objects.get_child(["2:Press"])
            found = {}
            for method in ("Press", "Reset"):
                node = await device.get_child([f"2:{method}", "0:InputArguments"])
                found[method] = [
                    (a.Name, ua.ObjectIdNames[a.DataType.Identifier])
                    for a in await node.read_value()
                ]
            return found

    assert run(go()) == {
        "Press": [("pressure", "Double"), ("part", "String")],
        "Reset": [("Data", "String")],
    }


def test_a_typed_call_reaches_the_device_with_its_data(press: Press) -> None:
    """The inputs become the event's data: the guard reads pressure, the row counts."""
    assert press.call("Press", 1.0, "B") == [False, "guard false"]
    assert press.call("Press", 3.0, "A") == [True, ""]
    assert press.state() == (frozenset({"Pressing"}), 1)


def test_an_integer_is_accepted_for_a_float_field(press: Press) -> None:
    """As at the runtime's door, an int is a float: an Int32 pressure of 3 presses."""
    assert press.call("Press", ua.Variant(3, ua.VariantType.Int32), "A") == [True, ""]


@pytest.mark.parametrize(
    ("inputs", "status"),
    [
        (("3.0", "A"), "BadInvalidArgument"),  # a String for a Double
        ((3.0, 7), "BadInvalidArgument"),  # an Int64 for a String
        ((ua.Variant(True, ua.VariantType.Boolean), "A"), "BadInvalidArgument"),
        ((float("nan"), "A"), "BadInvalidArgument"),
        ((float("inf"), "A"), "BadInvalidArgument"),
        ((3.0, "x" * 1_000_000), "BadInvalidArgument"),  # a 1 MB string
        ((ua.Variant([3.0], ua.VariantType.Double, is_array=True), "A"), "BadInvalidArgument"),
        ((3.0,), "BadArgumentsMissing"),
        ((), "BadArgumentsMissing"),
        ((3.0, "A", "extra"), "BadTooManyArguments"),
        (('{"pressure": 3.0, "part": "A"}',), "BadArgumentsMissing"),  # the old Data form
    ],
)
def test_a_bad_typed_input_is_refused_and_nothing_moves(
    press: Press, inputs: tuple[Any, ...], status: str
) -> None:
    assert press.call("Press", *inputs) == status
    assert press.state() == (frozenset({"Open"}), 0)


def test_each_input_gets_its_own_status(press: Press) -> None:
    """A raw Call: the bad input is BadTypeMismatch, the good one Good."""

    async def go() -> tuple[str, list[str]]:
        client = Client(press.url, timeout=10)
        client.set_user(USER)
        client.set_password(PASSWORD)
        async with client:
            device = await client.nodes.objects.get_child(["2:Press"])
            request = ua.CallMethodRequest()
            request.ObjectId = device.nodeid
            request.MethodId = (await device.get_child(["2:Press"])).nodeid
            request.InputArguments = [ua.Variant("high"), ua.Variant("A")]
            (result,) = await client.uaclient.call([request])
            return result.StatusCode.name, [c.name for c in result.InputArgumentResults]

    assert run(go()) == ("BadInvalidArgument", ["BadTypeMismatch", "Good"])


def test_data_items_are_read_only_variables_updated_after_each_step(press: Press) -> None:
    """The press's data (strokes 0, limit 3) are Int64 variables under Press/Data; a stroke
    counts itself, and the variable follows; nobody may write them."""
    assert press.call("Press", 3.0, "A") == [True, ""]

    async def go() -> tuple[list[tuple[str, Any, str]], str]:
        client = Client(press.url, timeout=10)
        client.set_user(USER)
        client.set_password(PASSWORD)
        async with client:
            folder = await client.nodes.objects.get_child(["2:Press", "2:Data"])
            strokes = await folder.get_child(["2:strokes"])
            for _ in range(500):  # the writer updates after the step, on its own loop
                if await strokes.read_value() == 1:
                    break
                await asyncio.sleep(0.01)
            found = []
            for variable in await folder.get_children():
                value = await variable.read_data_value()
                name = (await variable.read_browse_name()).Name
                found.append((name, value.Value.Value, value.Value.VariantType.name))
            try:
                await strokes.write_value(ua.Variant(7, ua.VariantType.Int64))
                refused = "written"
            except errors.UaStatusCodeError as exc:
                refused = type(exc).__name__
            return sorted(found), refused

    found, refused = run(go())
    assert found == [("limit", 3, "Int64"), ("strokes", 1, "Int64")]
    assert refused.startswith("Bad")
    assert press.state()[1] == 1


def test_a_data_value_shows_in_its_variables_type() -> None:
    """Rule 5: the type comes from the initial value; lists, mappings and null are JSON
    text; a later value that does not fit the type (text in a counter) is None, so the
    variable keeps its last value marked uncertain."""
    from statectl.channels.opcua.nodes import data_kind, data_variant

    kinds = [data_kind(v) for v in (True, 3, 2.5, "a", (79, 0), None, {"k": 1})]
    assert kinds == ["Boolean", "Int64", "Double", "String", "Json", "Json", "Json"]
    assert data_variant((79, 0), "Json").Value == "[79, 0]"
    assert data_variant(4.0, "Int64").Value == 4
    assert data_variant(4, "Double").Value == 4.0
    assert data_variant("x", "Int64") is None
    assert data_variant(4.5, "Int64") is None
    assert data_variant(True, "Int64") is None
