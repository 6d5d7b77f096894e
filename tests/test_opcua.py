"""``statectl run --opcua``: an asyncua client against the server, and the layout and config.

The Motor and the cell run as ``statectl run`` subprocesses; the test process is the
client (a separate process). The gantry (sub-state machines) is served in this process
on the server's own loop thread, and read by a client on this thread's loop. Loopback
only, free ports; every process and thread started here is stopped.
"""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from statectl.channels.opcua import layout
from statectl.channels.runconfig import load_run_config
from statectl.kernel.errors import DiagnosticError
from statectl.run.journal import load_device
from support import MOTOR, ROOT

pytest.importorskip("asyncua")

from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

GANTRY = ROOT / "examples" / "gantry" / "gantry.yaml"
CELL = ROOT / "examples" / "pick-and-place" / "cell.yaml"
USER, PASSWORD = "operator", "a-long-enough-password"
CLIENT_URI = "urn:statectl:test:client"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Served:
    url: str
    certs: Path
    client_cert: Path
    client_key: Path
    banner: str
    process: subprocess.Popen[str]


def serve(tmp: Path, path: Path, security: str) -> Iterator[Served]:
    """``statectl run PATH --opcua URL`` with a config; yields once it listens; stops it."""
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    certs = tmp / "certs"
    config = tmp / "run.yaml"
    config.write_text(
        f"opcua: {{user: {USER}, password: {PASSWORD}, security: {security}, "
        f"certificates: {certs}}}\n",
        encoding="utf-8",
    )
    env = {
        **os.environ,
        "PYTHONPATH": f"{ROOT / 'src'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
    }
    env.pop("STATECTL_OPCUA_USER", None)
    env.pop("STATECTL_OPCUA_PASSWORD", None)
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "statectl",
            "run",
            str(path),
            "--config",
            str(config),
            "--opcua",
            url,
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    assert process.stdout is not None
    banner = ""
    try:
        for line in process.stdout:
            banner += line
            if line.startswith("opcua: "):
                break
        else:
            pytest.fail(f"the server did not start:\n{banner}")
        out = process.stdout
        threading.Thread(target=lambda: [None for _ in out], daemon=True).start()  # drain
        key, cert = tmp / "client-key.pem", tmp / "client-cert.der"
        asyncio.run(
            setup_self_signed_certificate(
                key, cert, CLIENT_URI, "localhost", [ExtendedKeyUsageOID.CLIENT_AUTH],
                {"commonName": "statectl test client"},
            )
        )  # fmt: skip
        yield Served(url, certs, cert, key, banner, process)
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@pytest.fixture(scope="module")
def motor(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    yield from serve(tmp_path_factory.mktemp("motor"), MOTOR, "[Basic256Sha256]")


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    yield from serve(tmp_path_factory.mktemp("cell"), CELL, "[None]")


async def connect(
    served: Served, *, user: str | None = None, password: str | None = None
) -> Client:
    client = Client(served.url, timeout=10)
    client.application_uri = CLIENT_URI
    if "Basic256Sha256" in served.banner.split("security ")[1].split(";")[0]:
        await client.set_security(
            SecurityPolicyBasic256Sha256,
            str(served.client_cert),
            str(served.client_key),
            mode=ua.MessageSecurityMode.SignAndEncrypt,
        )
    if user is not None:
        client.set_user(user)
    if password is not None:
        client.set_password(password)
    await client.connect()
    return client


def run(coro: Any) -> Any:
    return asyncio.run(asyncio.wait_for(coro, 60))


async def child(node: Any, *names: str) -> Any:
    return await node.get_child([f"2:{n}" for n in names])


async def browse(client: Client, device: str) -> dict[str, Any]:
    """The device's machine: type, its supertype, its states and transitions with numbers."""
    motor = await client.nodes.objects.get_child([f"2:{device}"])
    machine = await child(motor, "StateMachine")
    kind = client.get_node(await machine.read_type_definition())
    states, transitions = {}, {}
    for node in await machine.get_children():
        name = (await node.read_browse_name()).Name
        typedef = (await node.read_type_definition()).Identifier
        if typedef in (ua.ObjectIds.StateType, ua.ObjectIds.InitialStateType):
            states[name] = (await (await node.get_child("0:StateNumber")).read_value(), typedef)
        elif typedef == ua.ObjectIds.TransitionType:
            number = await (await node.get_child("0:TransitionNumber")).read_value()
            ends = []
            for ref in (ua.ObjectIds.FromState, ua.ObjectIds.ToState):
                (target,) = await node.get_referenced_nodes(ref, ua.BrowseDirection.Forward)
                ends.append((await target.read_browse_name()).Name)
            transitions[name] = (number, *ends)
    methods = [(await m.read_browse_name()).Name for m in await motor.get_methods()]
    return {
        "supertype": [
            n.nodeid.Identifier
            for n in await kind.get_referenced_nodes(
                ua.ObjectIds.HasSubtype, ua.BrowseDirection.Inverse
            )
        ],
        "states": states,
        "transitions": transitions,
        "methods": sorted(methods),
        "invokes": await (await child(motor, "Invokes")).read_value(),
    }


def test_an_anonymous_client_browses_the_motor_state_machine(motor: Served) -> None:
    """The Motor's machine is a FiniteStateMachineType subtype with numbered states/transitions."""

    async def go() -> dict[str, Any]:
        client = await connect(motor)
        try:
            return await browse(client, "Motor")
        finally:
            await client.disconnect()

    seen = run(go())
    assert seen["supertype"] == [ua.ObjectIds.FiniteStateMachineType]
    assert seen["states"] == {
        "Blocked": (1, ua.ObjectIds.InitialStateType),
        "Moving": (2, ua.ObjectIds.StateType),
        "Returning": (3, ua.ObjectIds.StateType),
    }
    assert seen["transitions"]["Blocked to Moving on Movement"] == (1, "Blocked", "Moving")
    assert seen["transitions"]["Moving to Returning on Error"] == (5, "Moving", "Returning")
    assert len(seen["transitions"]) == 6
    assert seen["methods"] == ["Initialization", "Movement"]
    assert seen["invokes"] == ["0 Moving Movement", "1 Returning Initialization", "2 Error Error"]


class Heard:
    """A subscription handler that keeps data changes and events."""

    def __init__(self) -> None:
        self.values: list[Any] = []
        self.events: list[Any] = []
        self.changed = asyncio.Event()

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        self.values.append(val.Text)
        self.changed.set()

    def event_notification(self, event: Any) -> None:
        self.events.append(event)
        self.changed.set()

    async def until(self, test: Any) -> None:
        while not test():
            self.changed.clear()
            await asyncio.wait_for(self.changed.wait(), 15)


def test_a_user_calls_movement_and_subscribers_see_moving_then_blocked(motor: Served) -> None:
    """Calling Movement as the user is handled; CurrentState and transition events follow."""

    async def go() -> tuple[Any, Any, Heard, int]:
        client = await connect(motor, user=USER, password=PASSWORD)
        try:
            device = await client.nodes.objects.get_child(["2:Motor"])
            machine = await child(device, "StateMachine")
            current = await machine.get_child("0:CurrentState")
            heard = Heard()
            sub = await client.create_subscription(10, heard)
            await sub.subscribe_data_change(current)
            await sub.subscribe_events(device, ua.ObjectIds.TransitionEventType)
            await heard.until(lambda: heard.values == ["Blocked"])
            refused = await device.call_method("2:Initialization")  # guard: previous Moving
            first = await device.call_method("2:Movement")
            await heard.until(  # data changes and events come on their own: wait for both
                lambda: (
                    heard.values[-1:] == ["Blocked"]
                    and len(heard.values) > 2
                    and len(heard.events) >= 2
                )
            )
            number = await (await current.get_child("0:Number")).read_value()
            await sub.delete()
            return first, refused, heard, number
        finally:
            await client.disconnect()

    first, refused, heard, number = run(go())
    assert first == [True, ""]
    assert refused == [False, "declared ignored"]  # Initialization's guard is false
    assert heard.values == ["Blocked", "Moving", "Blocked"]
    steps = [(e.Transition.Text, e.FromState.Text, e.ToState.Text) for e in heard.events]
    assert steps == [
        ("Blocked to Moving on Movement", "Blocked", "Moving"),
        ("Moving to Blocked on Movement completion", "Moving", "Blocked"),
    ]
    assert number == 1


def test_a_call_without_a_user_is_refused(motor: Served) -> None:
    """An anonymous session may browse but not call; a wrong password gets no session."""

    async def anonymous() -> None:
        client = await connect(motor)
        try:
            device = await client.nodes.objects.get_child(["2:Motor"])
            await device.call_method("2:Movement")
        finally:
            await client.disconnect()

    with pytest.raises(ua.uaerrors.BadUserAccessDenied):
        run(anonymous())
    with pytest.raises(ua.uaerrors.BadUserAccessDenied):
        run(connect(motor, user=USER, password="not-the-password-at-all"))


def test_security_is_basic256sha256_only_with_a_stored_certificate(motor: Served) -> None:
    """Default endpoints: SignAndEncrypt only; the certificate is kept; the password unseen."""

    async def endpoints() -> list[Any]:
        client = Client(motor.url, timeout=10)
        return list(await client.connect_and_get_server_endpoints())

    found = run(endpoints())
    assert {(e.SecurityPolicyUri, e.SecurityMode) for e in found} == {
        (SecurityPolicyBasic256Sha256.URI, ua.MessageSecurityMode.SignAndEncrypt)
    }
    assert {e.EndpointUrl for e in found} == {motor.url}
    key = motor.certs / "server-key.pem"
    assert (motor.certs / "server-cert.der").stat().st_size > 0
    assert key.stat().st_mode & 0o077 == 0
    assert PASSWORD not in motor.banner
    assert f"user {USER!r}" in motor.banner


def test_a_cell_exposes_every_device(cell: Served) -> None:
    """Each device of the cell is an object with its own state machine, on a None endpoint."""

    async def go() -> dict[str, str]:
        client = await connect(cell)
        try:
            shown = {}
            for name in ("conveyor", "arm", "gripper", "sensor"):
                device = await client.nodes.objects.get_child([f"2:{name}"])
                current = await (await child(device, "StateMachine")).get_child("0:CurrentState")
                shown[name] = (await current.read_value()).Text
            return shown
        finally:
            await client.disconnect()

    shown = run(go())
    assert set(shown) == {"conveyor", "arm", "gripper", "sensor"}
    assert all(shown.values()), shown


def test_the_gantry_has_sub_state_machines_and_sibling_regions() -> None:
    """A compound state has a sub-state machine; a parallel state's regions are siblings."""
    lay = layout(load_device(str(GANTRY)).chart)
    assert [(m.name, m.parent, m.holder, m.states) for m in lay.machines] == [
        ("StateMachine", None, None, ("Running", "Paused", "EStopped")),
        ("SubStateMachine", 0, "Running", ("Idle", "Cycle")),
        ("Axis", 1, "Cycle", ("Traversing", "AtTarget")),
        ("Gripper", 1, "Cycle", ("Closing", "Gripped")),
    ]
    assert sorted(lay.state_numbers.values()) == list(range(1, len(lay.state_numbers) + 1))


def test_the_gantry_serves_sub_state_machines_in_process() -> None:
    """Over the wire, HasSubStateMachine leads from Cycle to its two region machines."""
    from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
    from statectl.run.runtime import SimClock
    from statectl.run.system import DeviceSetup, System

    chart = load_device(str(GANTRY)).chart
    system = System((DeviceSetup(chart.name, chart),), SimClock())
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    server = OpcuaServer(system, OpcuaSettings(endpoint=url, security=("None",)))
    server.start()
    try:
        system.start()
        server.refresh()

        async def go() -> tuple[list[str], str]:
            async with Client(url, timeout=10) as client:
                device = await client.nodes.objects.get_child([f"2:{chart.name}"])
                cycle = await child(device, "StateMachine", "Running", "SubStateMachine", "Cycle")
                subs = await cycle.get_referenced_nodes(ua.ObjectIds.HasSubStateMachine)
                names = sorted([(await s.read_browse_name()).Name for s in subs])
                current = await (await child(device, "StateMachine")).get_child("0:CurrentState")
                for _ in range(100):
                    text = (await current.read_value()).Text
                    if text:
                        break
                    await asyncio.sleep(0.05)
                return names, text

        names, text = run(go())
    finally:
        server.stop()
        system.close()
    assert names == ["Axis", "Gripper"]
    assert text in chart.initial or text == "Running"


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ("opcua: 5", "'opcua' must be a mapping"),
        ("opcua: {endpoint: http://x}", "endpoint must be an opc.tcp:// URL"),
        ("opcua: {endpoint: 'opc.tcp://127.0.0.1:99999'}", "(Port out of range"),
        ("opcua: {endpoint: 'opc.tcp://[::1:4840'}", "(Invalid IPv6 URL)"),
        ("opcua: {endpoint: 'opc.tcp://:4840'}", "names no host"),
        ("opcua: {user: op, password: short}", "password must be text of 12 characters"),
        ("opcua: {user: op}", "give both user and password"),
        ("opcua: {security: [Basic128]}", "security must list Basic256Sha256"),
        ("opcua: {colour: red}", "unknown key 'colour'"),
    ],
)
def test_a_bad_opcua_section_is_d520_with_its_line(
    tmp_path: Path, section: str, message: str
) -> None:
    """Each problem in the opcua: section is a D520 error naming the file and line."""
    path = tmp_path / "run.yaml"
    path.write_text(f"# run config\n{section}\n", encoding="utf-8")
    with pytest.raises(DiagnosticError) as caught:
        load_run_config(path)
    (diag,) = [d for d in caught.value.diagnostics if message in d.message]
    assert diag.code == "D520"
    assert diag.where.line == 2
    assert "'short'" not in str(caught.value.diagnostics)  # a password is never echoed


def test_a_good_opcua_section_reads_and_never_shows_the_password(tmp_path: Path) -> None:
    """The values come through; the config's repr hides the password."""
    path = tmp_path / "run.yaml"
    path.write_text(
        f"opcua: {{endpoint: 'opc.tcp://127.0.0.1:4841', user: op, password: {PASSWORD}, "
        "security: [Basic256Sha256, None]}\n",
        encoding="utf-8",
    )
    section = load_run_config(path).opcua
    assert (section.endpoint, section.user, section.password, section.security) == (
        "opc.tcp://127.0.0.1:4841", "op", PASSWORD, ("Basic256Sha256", "None"),
    )  # fmt: skip
    assert PASSWORD not in repr(section)


def test_a_journalled_run_answers_a_call_once_the_step_ran(tmp_path: Path) -> None:
    """With a journal the call goes through it and returns the step's outcome."""
    from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
    from statectl.run.journal import Journal
    from statectl.run.runtime import SimClock
    from statectl.run.system import DeviceSetup, System

    chart = load_device(str(MOTOR)).chart
    system = System((DeviceSetup(chart.name, chart),), SimClock(), Journal(tmp_path / "j.db"))
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    settings = OpcuaSettings(endpoint=url, user=USER, password=PASSWORD, security=("None",))
    server = OpcuaServer(system, settings)
    server.start()
    halt = None
    try:
        system.start()
        server.refresh()
        halt = system.start_owner()

        async def go() -> list[Any]:
            client = Client(url, timeout=10)
            client.set_user(USER)
            client.set_password(PASSWORD)
            async with client:
                device = await client.nodes.objects.get_child([f"2:{chart.name}"])
                return [
                    await device.call_method("2:Movement"),
                    await device.call_method("2:Movement"),  # Moving: no driver completes it
                ]

        answers = run(go())
    finally:
        if halt is not None:
            halt()
        server.stop()
        system.close()
    assert answers == [[True, ""], [False, "declared ignored"]]


@pytest.mark.parametrize(
    ("endpoint", "env", "exit", "message"),
    [
        ("http://127.0.0.1:4840", {}, 2, "--opcua must be an opc.tcp://HOST:PORT URL"),
        (None, {"STATECTL_OPCUA_USER": "op", "STATECTL_OPCUA_PASSWORD": "tiny"}, 1, "shorter than"),
        (None, {"STATECTL_OPCUA_USER": "op"}, 1, "set both STATECTL_OPCUA_USER"),
        ("busy", {}, 1, "opcua: cannot serve"),
        ("opc.tcp://127.0.0.1:99999", {}, 1, "Port out of range"),
        ("opc.tcp://nonexistent.invalid:4840", {}, 1, "host 'nonexistent.invalid' is unknown"),
    ],
)
def test_a_bad_opcua_setting_fails_the_run_with_a_message(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture,
    endpoint: str | None, env: dict[str, str], exit: int, message: str,
) -> None:  # fmt: skip
    """A bad endpoint, environment user or a taken port: one line, no secret shown, and no
    traceback logged either (asyncua used to log one for a port in use, a port out of
    range or a host it cannot resolve); exit 1, or 2 for an --opcua URL that is no
    opc.tcp:// URL (a usage error, as --port's)."""
    import io

    from statectl.channels.cli.run import run as run_cli

    for name in ("STATECTL_OPCUA_USER", "STATECTL_OPCUA_PASSWORD"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    config = tmp_path / "run.yaml"
    config.write_text(f"opcua: {{security: [None], certificates: {tmp_path}}}\n", "utf-8")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        if endpoint is None:
            endpoint = f"opc.tcp://127.0.0.1:{free_port()}"
        elif endpoint == "busy":
            endpoint = f"opc.tcp://127.0.0.1:{taken.getsockname()[1]}"
        out, err = io.StringIO(), io.StringIO()
        code = run_cli(
            str(MOTOR), config=str(config), opcua=endpoint, events=io.StringIO(""), out=out,
            err=err, stop=threading.Event(),
        )  # fmt: skip
    assert code == exit
    assert message in err.getvalue()
    assert "Traceback" not in err.getvalue()
    assert "tiny" not in err.getvalue() + out.getvalue()
    assert [r.getMessage() for r in caplog.records if r.exc_info] == []


def test_the_stored_certificate_is_reused_by_the_next_run(motor: Served) -> None:
    """A second server on the same directory keeps the first run's certificate and key."""
    from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
    from statectl.run.runtime import SimClock
    from statectl.run.system import DeviceSetup, System

    files = [motor.certs / "server-cert.der", motor.certs / "server-key.pem"]
    before = [f.read_bytes() for f in files]
    chart = load_device(str(MOTOR)).chart
    system = System((DeviceSetup(chart.name, chart),), SimClock())
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    server = OpcuaServer(system, OpcuaSettings(endpoint=url, certificates=motor.certs))
    server.start()
    server.stop()
    system.close()
    assert [f.read_bytes() for f in files] == before
