"""OPC UA trust: only the configured security policies open a session, every method call
is authorised inside statectl and its inputs are checked (issue 28).

The attack runs against ``statectl run --opcua`` as a subprocess, exactly as it was
reported; the rest against a server in this process (its own loop thread) and a client
on this thread's loop. Loopback only, free ports; everything started here is stopped.
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from statectl.run.commands import Commands, Grant
from statectl.run.journal import REFUSED, Journal, JournalReader, load_device
from statectl.run.runtime import SimClock
from statectl.run.system import DeviceSetup, System
from support import MOTOR, ROOT

pytest.importorskip("asyncua")

from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyNone
from cryptography.x509.oid import ExtendedKeyUsageOID

from statectl.channels.opcua import server as opcua_server
from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
from test_opcua import CLIENT_URI, PASSWORD, USER, Served, connect, free_port, run

errors = ua.uaerrors


@pytest.fixture(scope="module")
def attacked(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    """``STATECTL_OPCUA_USER=operator STATECTL_OPCUA_PASSWORD=... statectl run
    examples/motor/motor.yaml --opcua URL``: Basic256Sha256 only, as the banner says."""
    tmp = tmp_path_factory.mktemp("attacked")
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    env = {
        **os.environ,
        "PYTHONPATH": f"{ROOT / 'src'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
        "STATECTL_OPCUA_USER": USER,
        "STATECTL_OPCUA_PASSWORD": PASSWORD,
        "XDG_STATE_HOME": str(tmp / "state"),
    }
    process = subprocess.Popen(
        [sys.executable, "-m", "statectl", "run", str(MOTOR), "--opcua", url],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    assert process.stdout is not None
    try:
        banner = ""
        for line in process.stdout:
            banner += line
            if line.startswith("opcua: "):
                break
        assert "security Basic256Sha256;" in banner, banner
        out = process.stdout
        threading.Thread(target=lambda: [None for _ in out], daemon=True).start()  # drain
        key, cert = tmp / "client-key.pem", tmp / "client-cert.der"
        asyncio.run(
            setup_self_signed_certificate(
                key, cert, CLIENT_URI, "localhost", [ExtendedKeyUsageOID.CLIENT_AUTH],
                {"commonName": "statectl test client"},
            )
        )  # fmt: skip
        yield Served(url, tmp / "state", cert, key, banner, process)
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


async def last_invoke(served: Served) -> int:
    """The Motor's LastInvoke (-1: no invoke issued yet; Movement issues 0), read by an
    anonymous session over the configured Basic256Sha256 channel."""
    client = await connect(served)
    try:
        motor = await client.nodes.objects.get_child(["2:Motor"])
        return int(await (await motor.get_child(["2:LastInvoke"])).read_value())
    finally:
        await client.disconnect()


def test_the_none_bypass_is_refused_and_the_motor_does_not_move(
    attacked: Served, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The reported attack: a client with no security and no user, its endpoint check
    bypassed, opens a None channel and calls Movement. The channel may discover (that is
    how a client learns the endpoints), but no session opens on it:
    BadSecurityPolicyRejected; nothing is called and the Motor issues no invoke."""
    monkeypatch.setattr(Client, "find_endpoint", staticmethod(lambda e, m, u: e[0]))

    async def attack() -> Any:
        client = Client(attacked.url, timeout=10)
        await client.connect()  # a None channel: the server never offered one
        try:
            motor = await client.nodes.objects.get_child(["2:Motor"])
            return await motor.call_method("2:Movement")
        finally:
            await client.disconnect()

    async def discover() -> set[str]:
        return {e.SecurityPolicyUri for e in await Client(attacked.url, timeout=10)
                .connect_and_get_server_endpoints()}  # fmt: skip

    with pytest.raises(errors.BadSecurityPolicyRejected):
        run(attack())
    assert SecurityPolicyNone.URI not in run(discover())
    assert run(last_invoke(attacked)) == -1


def test_a_raw_client_that_ignores_the_refusals_gets_nothing_done(attacked: Served) -> None:
    """Built by hand on a None channel: CreateSession and ActivateSession are refused, and a
    Call sent anyway on the same channel is refused too; the Motor issues no invoke."""

    async def attack() -> list[str]:
        client = Client(attacked.url, timeout=10)
        refused: list[str] = []
        await client.connect_socket()
        try:
            await client.send_hello()
            await client.open_secure_channel()  # SecurityPolicy None, directly
            for step in (client.create_session, client.activate_session):
                try:
                    await step()
                except errors.UaStatusCodeError as exc:
                    refused.append(type(exc).__name__)
            request = ua.CallMethodRequest()
            request.ObjectId = ua.NodeId(ua.ObjectIds.ObjectsFolder)
            request.MethodId = ua.NodeId(ua.ObjectIds.Server_GetMonitoredItems)
            try:
                await client.uaclient.call([request])
            except errors.UaStatusCodeError as exc:
                refused.append(type(exc).__name__)
        finally:
            client.disconnect_socket()
        return refused

    refused = run(attack())
    assert refused == ["BadSecurityPolicyRejected"] * 3  # CreateSession, Activate, Call
    assert run(last_invoke(attacked)) == -1


# -- in this process: the policy, the inputs, the object -----------------------------------


class Plant:
    """A Motor (no driver: Movement leaves it Moving) served in this process, on None
    security as configured, with a user and a commands policy."""

    def __init__(self, tmp: Path, grants: tuple[Grant, ...], journal: bool) -> None:
        chart = load_device(str(MOTOR)).chart
        self.path = tmp / "j.db"
        store = Journal(self.path) if journal else None
        self.system = System(
            (DeviceSetup("Motor", chart),), SimClock(), store, commands=Commands(grants)
        )
        self.url = f"opc.tcp://127.0.0.1:{free_port()}"
        settings = OpcuaSettings(
            endpoint=self.url, user=USER, password=PASSWORD, security=("None",)
        )
        self.server = OpcuaServer(self.system, settings)
        self.server.start()
        self.system.start()
        self.halt = self.system.start_owner(paced=False)

    def close(self) -> None:
        self.halt()
        self.server.stop()
        self.system.close()

    @property
    def state(self) -> frozenset[str]:
        with self.system.owner:
            return self.system.subjects["Motor"].configuration

    def calls(self, *calls: tuple[str, tuple[Any, ...]], user: bool = True,
              on: str = "Motor") -> list[Any]:  # fmt: skip
        """Each ``(method, inputs)`` called on the Motor (or the Objects folder): its
        outputs, or the name of the bad status it got."""

        async def go() -> list[Any]:
            client = Client(self.url, timeout=10)
            if user:
                client.set_user(USER)
                client.set_password(PASSWORD)
            async with client:
                motor = await client.nodes.objects.get_child(["2:Motor"])
                target = motor if on == "Motor" else client.nodes.objects
                answers: list[Any] = []
                for method, inputs in calls:
                    node = await motor.get_child([f"2:{method}"])
                    try:
                        answers.append(await target.call_method(node, *inputs))
                    except errors.UaStatusCodeError as exc:
                        answers.append(type(exc).__name__)
                return answers

        return list(run(go()))


@pytest.fixture
def plant(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Plant]:
    grants, journal = getattr(request, "param", ((), False))
    served = Plant(tmp_path, grants, journal)
    try:
        yield served
    finally:
        served.close()


OPERATOR_INITIALIZES = (Grant("opcua", USER, None, frozenset({"Initialization"})),)


@pytest.mark.parametrize("plant", [(OPERATOR_INITIALIZES, True)], indirect=True)
def test_the_commands_policy_decides_what_the_user_may_call(plant: Plant) -> None:
    """The user may call what a grant covers; the rest is BadUserAccessDenied, journalled
    as refused, and the Motor does not move."""
    answers = plant.calls(("Movement", ()), ("Initialization", ()))
    assert answers == ["BadUserAccessDenied", [False, "declared ignored"]]
    assert plant.state == frozenset({"Blocked"})
    plant.system.journal.flush()  # type: ignore[union-attr]
    with JournalReader(plant.path) as reader:
        outcomes = [(r.event, r.outcome) for r in reader.steps() if r.event is not None]
    assert outcomes == [
        ("Movement", f"{REFUSED}: opcua {USER}"),
        ("Initialization", "declared ignored"),
    ]


def test_an_anonymous_call_is_refused_inside_statectl_whatever_asyncua_allows(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Even with asyncua's rules letting every session call (as on a channel where it
    checks nothing), statectl's own check refuses an anonymous call: BadUserAccessDenied."""

    class Open:
        def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
            return True

    monkeypatch.setattr(opcua_server, "_Rules", Open)
    plant = Plant(tmp_path, (), False)
    try:
        assert plant.calls(("Movement", ()), user=False) == ["BadUserAccessDenied"]
        assert plant.state == frozenset({"Blocked"})
    finally:
        plant.close()


@pytest.mark.parametrize(
    ("inputs", "status"),
    [
        (("{}", "{}"), "BadTooManyArguments"),  # an extra input
        (("",) * 100, "BadTooManyArguments"),
        ((ua.Variant(float("nan"), ua.VariantType.Double),), "BadInvalidArgument"),  # a NaN
        ((ua.Variant(5, ua.VariantType.Int32),), "BadInvalidArgument"),  # not a String
        ((ua.Variant(["{}"], ua.VariantType.String, is_array=True),), "BadInvalidArgument"),
        (("x" * 1_000_000,), "BadInvalidArgument"),  # a 1 MB string
        (('{"amount": NaN}',), "BadInvalidArgument"),  # NaN in the JSON
        (('{"amount": 1e999}',), "BadInvalidArgument"),  # infinite
        (("not json",), "BadInvalidArgument"),
        (("[1, 2]",), "BadInvalidArgument"),  # not an object
        (("[" * 60_000,), "BadInvalidArgument"),  # nested beyond what can be read
    ],
)
def test_a_bad_input_is_refused_and_nothing_moves(
    plant: Plant, inputs: tuple[Any, ...], status: str
) -> None:
    """A device method takes at most one input, Data: the event's data as a JSON object."""
    assert plant.calls(("Movement", inputs)) == [status]
    assert plant.state == frozenset({"Blocked"})


@pytest.mark.parametrize("plant", [((), True)], indirect=True)
def test_data_as_a_json_object_reaches_the_device(plant: Plant) -> None:
    """The one input a method takes carries the event's data; empty means none."""
    assert plant.calls(("Movement", ('{"amount": 5}',)), ("Movement", ("",))) == [
        [True, ""],
        [False, "declared ignored"],
    ]
    assert plant.state == frozenset({"Moving"})
    plant.system.journal.flush()  # type: ignore[union-attr]
    with JournalReader(plant.path) as reader:
        data = [(r.event, r.data) for r in reader.steps() if r.event is not None]
    assert data == [("Movement", {"amount": 5}), ("Movement", None)]


def test_a_method_called_on_another_object_is_bad_method_invalid(plant: Plant) -> None:
    """Movement called with the Objects folder as its object: BadMethodInvalid, no move."""
    assert plant.calls(("Movement", ()), on="Objects") == ["BadMethodInvalid"]
    assert plant.state == frozenset({"Blocked"})
