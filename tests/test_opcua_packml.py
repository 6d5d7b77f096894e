"""A device that declares ``profile: packml`` seen by an asyncua client as a PackML client
expects it (OPC 30050): machine names and types, state numbers, command methods.

The unit runs as a ``statectl run --opcua`` subprocess (the shipped PackML profile, as
``statectl new`` writes it); the test process is the client. Loopback only; the server
process is stopped by the fixture (SIGINT to its PID, then kill).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

pytest.importorskip("asyncua")

from asyncua import Client, ua

from statectl.channels.cli import main
from statectl.channels.opcua import layout
from statectl.channels.opcua.packml import PACKML_URI, naming, status_of
from statectl.front.builder.build import build
from statectl.front.profiles import find, profile_tables
from test_opcua import PASSWORD, USER, Served, connect, run, serve


@pytest.fixture(scope="module")
def unit(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    tmp = tmp_path_factory.mktemp("packml")
    assert main(["new", "Unit", "--profile", "packml", "--out", str(tmp)]) == 0
    yield from serve(tmp, tmp / "Unit.yaml", "[None]")


async def machines(client: Client) -> dict[str, Any]:
    """The unit's three PackML machines, found by their companion browse names."""
    ns = await client.get_namespace_index(PACKML_URI)
    device = await client.nodes.objects.get_child(["2:Unit"])
    base = await device.get_child([f"{ns}:BaseStateMachine"])
    machine = await base.get_child(["2:Cleared", f"{ns}:MachineState"])
    execute = await machine.get_child(["2:Running", f"{ns}:ExecuteState"])
    return {"ns": ns, "device": device, "base": base, "machine": machine, "execute": execute}


async def supertype(kind: Any) -> Any:
    (parent,) = await kind.get_referenced_nodes(ua.ObjectIds.HasSubtype, ua.BrowseDirection.Inverse)
    return parent


async def current(node: Any) -> tuple[str, int]:
    state = await node.get_child("0:CurrentState")
    number = await (await state.get_child("0:Number")).read_value()
    return (await state.read_value()).Text, number


async def until(node: Any, wanted: tuple[str, int]) -> tuple[str, int]:
    """The machine's CurrentState once it shows ``wanted`` (or what it shows after 10 s)."""
    import asyncio

    seen = await current(node)
    for _ in range(200):
        if seen == wanted:
            break
        await asyncio.sleep(0.05)
        seen = await current(node)
    return seen


def test_a_packml_client_finds_the_companion_names(unit: Served) -> None:
    """The machines are BaseStateMachine, MachineState and ExecuteState in the PackML
    namespace, of the companion's types (subtypes of FiniteStateMachineType), with the
    PackML state numbers and the command methods where OPC 30050 puts them; the unit is
    filed under PackMLObjects."""

    async def go() -> dict[str, Any]:
        client = await connect(unit)
        try:
            m = await machines(client)
            seen: dict[str, Any] = {"methods": {}, "types": {}, "numbers": {}}
            for key in ("base", "machine", "execute"):
                node = m[key]
                names = [(await x.read_browse_name()) for x in await node.get_methods()]
                seen["methods"][key] = sorted(n.Name for n in names if n.NamespaceIndex == m["ns"])
                kind = client.get_node(await node.read_type_definition())
                name = await kind.read_browse_name()
                grand = await supertype(await supertype(kind))
                ours = name.NamespaceIndex == m["ns"]
                seen["types"][key] = (name.Name, ours, grand.nodeid.Identifier)
            for state in ("Execute", "Idle", "Resetting", "Complete", "Held"):
                node = await m["execute"].get_child([f"2:{state}"])
                seen["numbers"][state] = await (await node.get_child("0:StateNumber")).read_value()
            for state in ("Stopped", "Clearing", "Stopping"):
                node = await m["machine"].get_child([f"2:{state}"])
                seen["numbers"][state] = await (await node.get_child("0:StateNumber")).read_value()
            for state in ("Aborting", "Aborted"):
                node = await m["base"].get_child([f"2:{state}"])
                seen["numbers"][state] = await (await node.get_child("0:StateNumber")).read_value()
            folder = await client.nodes.objects.get_child([f"{m['ns']}:PackMLObjects"])
            forward = ua.BrowseDirection.Forward
            filed = await folder.get_referenced_nodes(ua.ObjectIds.Organizes, forward)
            seen["filed"] = [(await n.read_browse_name()).Name for n in filed]
            seen["current"] = [await current(m[k]) for k in ("base", "machine")]
            return seen
        finally:
            await client.disconnect()

    seen = run(go())
    assert seen["methods"] == {
        "base": ["Abort", "Clear"],
        "machine": ["Reset", "Stop"],
        "execute": ["Hold", "Reset", "Start", "Suspend", "Unhold", "Unsuspend"],
    }
    fsm = ua.ObjectIds.FiniteStateMachineType
    assert seen["types"] == {
        "base": ("PackMLBaseStateMachineType", True, fsm),
        "machine": ("PackMLMachineStateMachineType", True, fsm),
        "execute": ("PackMLExecuteStateMachineType", True, fsm),
    }
    assert seen["numbers"] == {
        "Execute": 6,
        "Idle": 4,
        "Resetting": 15,
        "Complete": 17,
        "Held": 11,
        "Stopped": 2,
        "Clearing": 1,
        "Stopping": 7,
        "Aborting": 8,
        "Aborted": 9,
    }
    assert seen["filed"] == ["Unit"]
    assert seen["current"][1] == ("Stopped", 2)


def test_commands_move_the_unit_and_a_wrong_one_is_bad_invalid_state(unit: Served) -> None:
    """As the user: Reset (MachineState) shows Resetting 15, Start there is refused with
    BadInvalidState, Stop shows Stopping 7 and Abort (BaseStateMachine) Aborting 8."""

    async def go() -> list[Any]:
        client = await connect(unit, user=USER, password=PASSWORD)
        try:
            m = await machines(client)
            ns = m["ns"]
            seen: list[Any] = []
            await m["machine"].call_method(f"{ns}:Reset")
            seen.append(await until(m["execute"], ("Resetting", 15)))
            try:
                await m["execute"].call_method(f"{ns}:Start")
                seen.append("Start accepted")
            except ua.uaerrors.BadInvalidState:
                seen.append("BadInvalidState")
            await m["machine"].call_method(f"{ns}:Stop")
            seen.append(await until(m["machine"], ("Stopping", 7)))
            await m["base"].call_method(f"{ns}:Abort")
            seen.append(await until(m["base"], ("Aborting", 8)))
            return seen
        finally:
            await client.disconnect()

    assert run(go()) == [("Resetting", 15), "BadInvalidState", ("Stopping", 7), ("Aborting", 8)]


def test_an_anonymous_packml_call_is_refused(unit: Served) -> None:
    """A PackML method needs the configured user, like every method."""

    async def go() -> None:
        client = await connect(unit)
        try:
            m = await machines(client)
            await m["base"].call_method(f"{m['ns']}:Abort")
        finally:
            await client.disconnect()

    with pytest.raises(ua.uaerrors.BadUserAccessDenied):
        run(go())


def test_a_packml_call_with_an_input_or_on_another_object_is_refused(unit: Served) -> None:
    """A PackML command takes no input (BadTooManyArguments) and belongs to the machine
    that holds it: called with the device object as its object, BadMethodInvalid."""

    async def go() -> list[str]:
        client = await connect(unit, user=USER, password=PASSWORD)
        got = []
        try:
            m = await machines(client)
            abort = await m["base"].get_child([f"{m['ns']}:Abort"])
            for target, inputs in ((m["base"], ("now",)), (m["device"], ())):
                try:
                    await target.call_method(abort, *inputs)
                    got.append("Good")
                except ua.uaerrors.UaStatusCodeError as exc:
                    got.append(type(exc).__name__)
            return got
        finally:
            await client.disconnect()

    assert run(go()) == ["BadTooManyArguments", "BadMethodInvalid"]


@pytest.mark.parametrize(
    ("profile", "expected"),
    [("packml", {"BaseStateMachine", "MachineState", "ExecuteState"}), ("motor", None)],
)
def test_only_a_device_that_declares_packml_gets_the_names(
    profile: str, expected: set[str] | None
) -> None:
    """The PackML names go to a device whose file declares the profile, no other."""
    chart, _ = build(profile_tables(find(profile)))  # type: ignore[arg-type]
    assert chart is not None
    names = naming(chart, layout(chart))
    got = None if names is None else {n for n, _ in names.machines.values()}
    assert got == expected


@pytest.mark.parametrize(
    ("outcome", "code"),
    [
        ("handled", None),
        ("declared ignored", ua.StatusCodes.BadInvalidState),
        ("guard false", ua.StatusCodes.BadInvalidState),
        ("no transition", ua.StatusCodes.BadInvalidState),
        ("Unit: 64 events are queued already (max_queue)", ua.StatusCodes.BadResourceUnavailable),
    ],
)
def test_outcome_to_status_code(outcome: str, code: int | None) -> None:
    """A PackML method answers Good, BadInvalidState (the state does not take the command)
    or BadResourceUnavailable (not accepted)."""
    assert status_of(outcome) == code


def test_table_numbers_are_kept_and_the_others_count_on() -> None:
    """OPC UA state numbers: a state's table number is kept; states without one are
    numbered after the highest, in chart order (PackML's Cleared and Running)."""
    chart, _ = build(profile_tables(find("packml")))  # type: ignore[arg-type]
    assert chart is not None
    numbers = layout(chart).state_numbers
    assert {s: numbers[s] for s in ("Clearing", "Execute", "Complete", "Cleared", "Running")} == {
        "Clearing": 1,
        "Execute": 6,
        "Complete": 17,
        "Cleared": 18,
        "Running": 19,
    }
    assert len(set(numbers.values())) == len(numbers)
