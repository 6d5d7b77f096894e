"""OPC UA, clean for generic clients (issue 31): every node of every example device reads
without a Bad status or a server traceback on a fresh server, and the machines'
``AvailableStates`` / ``AvailableTransitions`` are arrays of node ids kept current.

Served in this process (its own loop thread), read by an asyncua client on this thread's
loop, as a generic browser (``uals -d 4 -l``) does. Loopback only, free ports; every
server started here is stopped.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from statectl.kernel.errors import StatectlError
from statectl.run.journal import load_device
from statectl.run.runtime import SimClock
from statectl.run.system import DeviceSetup, System
from support import ROOT

pytest.importorskip("asyncua")

from asyncua import Client, ua

from statectl.channels.opcua.server import NAMESPACE, OpcuaServer, OpcuaSettings
from test_opcua import free_port, run
from test_opcua_trust import Plant

INVALID = ua.StatusCodes.BadAttributeIdInvalid  # an attribute the node class has not


def example_devices() -> list[tuple[str, Any]]:
    """Every device file under examples/ that loads (cells and configs do not), named after
    its directory and file so that two Motors do not clash."""
    found = []
    for path in sorted((ROOT / "examples").rglob("*.yaml")):
        try:
            chart = load_device(str(path)).chart
        except StatectlError:
            continue
        found.append((f"{path.parent.name}-{path.stem}", chart))
    return found


class Heard(logging.Handler):
    """Every record asyncua logs while the server runs (its tracebacks included)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@pytest.fixture
def heard() -> Iterator[Heard]:
    handler = Heard()
    log = logging.getLogger("asyncua")
    log.addHandler(handler)
    try:
        yield handler
    finally:
        log.removeHandler(handler)


async def _read_all(client: Client, node_id: Any) -> list[tuple[str, Any]]:
    """Every attribute of one node: (attribute, status). A request the server fails as a
    whole (BadInternalError) is read again attribute by attribute, so each gets its own."""
    wanted = list(ua.AttributeIds)

    def request(*attributes: Any) -> Any:
        params = ua.ReadParameters()
        for attribute in attributes:
            item = ua.ReadValueId()
            item.NodeId, item.AttributeId = node_id, attribute
            params.NodesToRead.append(item)
        return params

    try:
        results = await client.uaclient.read(request(*wanted))
        return [(a.name, r) for a, r in zip(wanted, results, strict=True)]
    except ua.UaStatusCodeError:
        pass
    out = []
    for attribute in wanted:
        try:
            out.append((attribute.name, (await client.uaclient.read(request(attribute)))[0]))
        except ua.UaStatusCodeError as exc:
            out.append((attribute.name, ua.DataValue(StatusCode=ua.StatusCode(exc.code))))
    return out


async def _browse_all(client: Client) -> list[Any]:
    """Every node reachable from Objects by hierarchical references in statectl's namespace."""
    ns = await client.get_namespace_index(NAMESPACE)
    seen: dict[Any, None] = {}
    todo = [client.nodes.objects]
    while todo:
        node = todo.pop()
        for ref in await node.get_references(
            refs=ua.ObjectIds.HierarchicalReferences, direction=ua.BrowseDirection.Forward
        ):
            if ref.NodeId.NamespaceIndex == ns and ref.NodeId not in seen:
                seen[ref.NodeId] = None
                todo.append(client.get_node(ref.NodeId))
    return list(seen)


def test_every_node_of_every_example_device_reads_cleanly_on_a_fresh_server(
    heard: Heard,
) -> None:
    """No Bad status where the node class has the attribute, no variable whose value is a
    Null variant (a null must have its type: an empty text, a null NodeId, 1601-01-01),
    and no record logged with a traceback, before any transition was taken."""
    devices = example_devices()
    assert len(devices) >= 10  # the motor, press, gantry, packml unit, pick-and-place, ...
    system = System(tuple(DeviceSetup(n, c) for n, c in devices), SimClock())
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    server = OpcuaServer(system, OpcuaSettings(endpoint=url, security=("None",)))
    server.start()
    try:
        system.start()
        server.refresh()

        async def go() -> tuple[int, list[str], list[str]]:
            bad, null = [], []
            async with Client(url, timeout=30) as client:
                nodes = await _browse_all(client)
                for node_id in nodes:
                    read = await _read_all(client, node_id)
                    for attribute, result in read:
                        code = result.StatusCode
                        if not code.is_good() and code.value != INVALID:
                            bad.append(f"{node_id.to_string()} {attribute}: {code.name}")
                    value = dict(read)["Value"]
                    kind = dict(read)["NodeClass"].Value.Value
                    if kind == ua.NodeClass.Variable and value.Value.VariantType is (
                        ua.VariantType.Null
                    ):
                        name = dict(read)["BrowseName"].Value.Value.Name
                        null.append(f"{node_id.to_string()} {name}")
            return len(nodes), bad, null

        count, bad, null = run(go())
    finally:
        server.stop()
        system.close()
    assert count > 500
    assert bad == []
    assert null == []
    noisy = [r for r in heard.records if r.exc_info or r.levelno >= logging.ERROR]
    assert [r.getMessage() for r in noisy] == []


def test_available_states_and_transitions_follow_the_current_state(tmp_path: Path) -> None:
    """The Motor in Blocked offers Blocked -> Moving and Blocked -> Returning; after a call
    of Movement it is Moving, which offers its completion (to Blocked) and Error (to
    Returning). Both are NodeId arrays naming the state and transition objects."""
    plant = Plant(tmp_path, (), False)
    try:
        plant.server.refresh()

        async def offered(client: Client, machine: Any) -> tuple[list[str], list[str]]:
            names = []
            for variable in ("AvailableStates", "AvailableTransitions"):
                value = await (await machine.get_child(f"0:{variable}")).read_data_value()
                assert value.Value.VariantType is ua.VariantType.NodeId
                assert value.Value.is_array
                ids = value.Value.Value
                names.append([(await client.get_node(i).read_browse_name()).Name for i in ids])
            return names[0], names[1]

        async def settled(unlike: tuple[list[str], list[str]]) -> tuple[list[str], list[str]]:
            """What the machine offers once the writer has shown something else than
            ``unlike`` (it writes after each step, on its own loop)."""
            async with Client(plant.url, timeout=10) as client:
                machine = await client.nodes.objects.get_child(["2:Motor", "2:StateMachine"])
                for _ in range(500):
                    seen = await offered(client, machine)
                    if seen != unlike:
                        return seen
                    await asyncio.sleep(0.01)
                return seen

        before = run(settled(([], [])))
        assert before == (
            ["Moving", "Returning"],
            ["Blocked to Moving on Movement", "Blocked to Returning on Initialization"],
        )
        assert plant.calls(("Movement", ())) == [[True, ""]]
        assert run(settled(before)) == (
            ["Blocked", "Returning"],
            ["Moving to Blocked on Movement completion", "Moving to Returning on Error"],
        )
    finally:
        plant.close()


def test_a_step_the_writer_cannot_show_is_logged_and_later_steps_are_still_shown(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The writer task outlives an update that fails: the failure is one logged error
    naming the device, and the next step's state still reaches the clients (before, the
    task ended and every later CurrentState stayed stale, silently)."""
    plant = Plant(tmp_path, (), False)
    server: Any = plant.server
    write, failed = server._write, []

    async def first_fails(update: Any) -> None:
        if not failed:
            failed.append(update[0].name)
            raise RuntimeError("broken update")
        await write(update)

    server._write = first_fails
    try:
        with caplog.at_level(logging.ERROR, logger="statectl.opcua"):
            plant.server.refresh()  # the update that fails: the initial state
            assert plant.calls(("Movement", ())) == [[True, ""]]

            async def current() -> str:
                async with Client(plant.url, timeout=10) as client:
                    machine = await client.nodes.objects.get_child(
                        ["2:Motor", "2:StateMachine", "0:CurrentState"]
                    )
                    shown = None
                    for _ in range(500):
                        shown = (await machine.read_value()).Text
                        if shown == "Moving":
                            break
                        await asyncio.sleep(0.01)
                    return str(shown)

            assert run(current()) == "Moving"
    finally:
        plant.close()
    assert failed == ["Motor"]
    errors = [r.getMessage() for r in caplog.records if r.name == "statectl.opcua"]
    assert errors == ["cannot show a step of Motor; later ones still"]
