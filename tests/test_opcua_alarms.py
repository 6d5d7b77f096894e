"""OPC UA alarms: a fault in a monitored state is an ``AlarmConditionType`` condition that a
client sees raised, acknowledges (journalled), refreshes and sees cleared on recovery.

The Motor (its ``Error`` fault given ``severity: 800``) is served in this process on the
server's own loop thread, with a journal and an owner thread; the fault is posted as its
monitor posts it (``{"detail": ...}``). The client is asyncua on this thread's loop.
Loopback only, a free port; the server, the owner and the system are stopped.
"""

from __future__ import annotations

import asyncio
import io
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from statectl.channels.cli import main
from statectl.front.tables import load
from statectl.run.journal import JournalReader, load_device, replay
from support import MOTOR
from test_opcua import PASSWORD, USER, free_port, run

pytest.importorskip("asyncua")

from asyncua import Client, ua


def test_a_bad_severity_is_t126(tmp_path: Path) -> None:
    """A severity out of 1..1000, not a number, or on a command row is T126 at its row."""
    rows = [
        ("{event: Err, old: A, new: B, kind: fault, severity: 0}", "from 1 to 1000"),
        ("{event: Err, old: A, new: B, kind: fault, severity: 1001}", "from 1 to 1000"),
        ("{event: Err, old: A, new: B, kind: fault, severity: high}", "got 'high'"),
        ("{event: Err, old: A, new: B, severity: 700}", "severity on command event 'Err'"),
    ]
    for row, message in rows:
        path = tmp_path / "d.yaml"
        path.write_text(
            "device: D\nstates:\n  - {state: A, control: [default, monitoring required]}\n"
            f"  - {{state: B}}\nevents:\n  - {row}\n",
            encoding="utf-8",
        )
        _, diags = load(path)
        assert [(d.code, d.where.line) for d in diags] == [("T126", 6)], [str(d) for d in diags]
        assert message in diags[0].message


def test_a_good_severity_reaches_the_chart_and_round_trips(tmp_path: Path) -> None:
    """``severity: 800`` on a fault row is the event's severity, kept by every format."""
    path = _motor(tmp_path)
    assert load_device(str(path)).chart.event("Error").severity == 800  # type: ignore[union-attr]
    for fmt in ("md", "xlsx", "csv"):
        out = tmp_path / fmt
        out.mkdir()
        assert main(["tables", str(path), "--to", fmt, "--out", str(out)]) == 0
        extra = (".data.csv", ".recovery.csv")
        again = next(p for p in out.iterdir() if not p.name.endswith(extra))
        chart = load_device(str(again)).chart
        assert chart.event("Error").severity == 800, fmt  # type: ignore[union-attr]


def _motor(tmp: Path) -> Path:
    """The Motor with ``severity: 800`` on its Error fault."""
    text = MOTOR.read_text(encoding="utf-8")
    marker = "    new: Returning\n    kind: fault\n"
    assert marker in text
    path = tmp / "motor.yaml"
    path.write_text(text.replace(marker, marker + "    severity: 800\n"), encoding="utf-8")
    return path


@dataclass
class Served:
    url: str
    system: Any
    journal: Path
    stop: Callable[[], None]  # the owner, the server and the system; once


@pytest.fixture
def served(tmp_path: Path) -> Iterator[Served]:
    from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
    from statectl.run.journal import Journal
    from statectl.run.runtime import SimClock
    from statectl.run.system import DeviceSetup, System

    chart = load_device(str(_motor(tmp_path))).chart
    journal = tmp_path / "j.db"
    system = System((DeviceSetup(chart.name, chart),), SimClock(), Journal(journal))
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    settings = OpcuaSettings(endpoint=url, user=USER, password=PASSWORD, security=("None",))
    server = OpcuaServer(system, settings)
    server.start()
    halts: list[Callable[[], None]] = []

    def stop() -> None:
        while halts:
            halts.pop()()

    halts += [system.close, server.stop]
    try:
        system.start()
        server.refresh()
        halts.append(system.start_owner())
        yield Served(url, system, journal, stop)
    finally:
        stop()


class Alarms:
    """A subscription handler that keeps the alarm events it is sent."""

    def __init__(self) -> None:
        self.events: list[Any] = []
        self.changed = asyncio.Event()
        self.cursor = 0

    def event_notification(self, event: Any) -> None:
        self.events.append(event)
        self.changed.set()

    async def next(self, test: Any) -> Any:
        """The first event after the last one returned that passes ``test``."""
        while True:
            for at in range(self.cursor, len(self.events)):
                if test(self.events[at]):
                    self.cursor = at + 1
                    return self.events[at]
            self.changed.clear()
            await asyncio.wait_for(self.changed.wait(), 15)


#: What an alarm client subscribes to: the alarms and the refresh brackets (a where
#: clause lets only these types through, as OPC 10000-4's event filter does).
KINDS = [
    ua.ObjectIds.AlarmConditionType,
    ua.ObjectIds.RefreshStartEventType,
    ua.ObjectIds.RefreshEndEventType,
]


def _state(event: Any, name: str) -> Any:
    return getattr(event, f"{name}/Id", None)


async def _client(url: str, user: bool = True) -> Client:
    client = Client(url, timeout=10)
    if user:
        client.set_user(USER)
        client.set_password(PASSWORD)
    await client.connect()
    return client


def test_a_fault_raises_an_alarm_acknowledged_refreshed_and_cleared(served: Served) -> None:
    """Raised with the table's severity, the detail as message and Retain; the condition's
    variables follow; Acknowledge sets AckedState and is journalled; ConditionRefresh
    sends the retained alarm again; recovery clears it and a refresh then sends none."""
    system = served.system

    async def go() -> dict[str, Any]:
        client = await _client(served.url)
        seen: dict[str, Any] = {}
        try:
            heard = Alarms()
            sub = await client.create_subscription(0, heard)
            server_node = client.get_node(ua.ObjectIds.Server)
            await sub.subscribe_events(server_node, KINDS)
            motor = await client.nodes.objects.get_child(["2:Motor"])
            condition = await motor.get_child(["2:Alarms", "2:Error"])
            seen["refs"] = [
                n.nodeid for n in await motor.get_referenced_nodes(ua.ObjectIds.HasCondition)
            ]
            active = await condition.get_child(["0:ActiveState", "0:Id"])  # as uaread reads it
            seen["before"] = await active.read_value()
            assert await motor.call_method("2:Movement") == [True, ""]
            system.post("Motor", "Error", {"detail": "motor stalled"})
            raised = await heard.next(lambda e: _state(e, "ActiveState") is True)
            seen["raised"] = raised
            seen["variable"] = await active.read_value()
            refreshed = await _refresh(client, sub, heard)
            seen["refreshed"] = refreshed
            seen["ack"] = await _status(
                condition.call_method(
                    "0:Acknowledge",
                    ua.Variant(raised.EventId, ua.VariantType.ByteString),
                    ua.LocalizedText("seen it"),
                )
            )
            seen["acked"] = await heard.next(lambda e: _state(e, "AckedState") is True)
            seen["again"] = await _status(
                condition.call_method(
                    "0:Acknowledge",
                    ua.Variant(seen["acked"].EventId, ua.VariantType.ByteString),
                    ua.LocalizedText("twice"),
                )
            )
            seen["stale"] = await _status(
                condition.call_method(
                    "0:Acknowledge",
                    ua.Variant(b"not an event", ua.VariantType.ByteString),
                    ua.LocalizedText(""),
                )
            )
            seen["bad"] = [
                await _status(condition.call_method("0:Acknowledge", *args))
                for args in (
                    (ua.Variant(raised.EventId, ua.VariantType.ByteString),),
                    (ua.Variant("text", ua.VariantType.String), ua.LocalizedText("")),
                )
            ]
            system.post("Motor", "Error completion")
            seen["cleared"] = await heard.next(lambda e: _state(e, "ActiveState") is False)
            seen["after"] = await _refresh(client, sub, heard)
            seen["condition"] = condition.nodeid
        finally:
            await client.disconnect()
        return seen

    seen = run(go())
    served.stop()  # the journal's writer commits what it holds
    raised = seen["raised"]
    assert seen["before"] is False and seen["variable"] is True
    assert seen["refs"] == [seen["condition"]]
    assert (raised.Severity, raised.Message.Text, raised.Retain) == (800, "motor stalled", True)
    assert (_state(raised, "AckedState"), raised.ConditionName) == (False, "Error")
    assert raised.NodeId == seen["condition"]  # ConditionId
    assert [e.EventId for e in seen["refreshed"]] == [raised.EventId]
    assert seen["ack"] == "Good"
    assert (seen["acked"].Comment.Text, seen["acked"].ClientUserId) == ("seen it", USER)
    assert seen["again"] == "BadConditionBranchAlreadyAcked"
    assert seen["stale"] == "BadEventIdUnknown"
    assert seen["bad"] == ["BadArgumentsMissing", "BadInvalidArgument"]
    assert (seen["cleared"].Retain, _state(seen["cleared"], "AckedState")) == (False, True)
    assert seen["after"] == []
    _the_journal_keeps_the_acknowledgement(served)


async def _refresh(client: Client, sub: Any, heard: Alarms) -> list[Any]:
    """ConditionRefresh: the alarm events between RefreshStart and RefreshEnd."""
    start = heard.cursor
    refresh = client.get_node(ua.ObjectIds.ConditionType)
    await refresh.call_method(
        ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh),
        ua.Variant(sub.subscription_id, ua.VariantType.UInt32),
    )
    await heard.next(lambda e: e.EventType == ua.NodeId(ua.ObjectIds.RefreshEndEventType))
    kinds = (ua.ObjectIds.RefreshStartEventType, ua.ObjectIds.RefreshEndEventType)
    got = heard.events[start : heard.cursor]
    assert [e.EventType.Identifier for e in got if e.EventType.Identifier in kinds] == list(kinds)
    return [e for e in got if e.EventType == ua.NodeId(ua.ObjectIds.AlarmConditionType)]


async def _status(call: Any) -> str:
    """The name of the status a call answered with."""
    try:
        await call
    except ua.UaStatusCodeError as exc:
        return type(exc).__name__
    return "Good"


def _the_journal_keeps_the_acknowledgement(served: Served) -> None:
    """One ``acknowledged`` step, shown by journal show, passed over by replay."""
    with JournalReader(served.journal) as reader:
        steps = [s for s in reader.steps("Motor") if s.outcome.startswith("acknowledged")]
        assert [(s.event, s.data, s.outcome) for s in steps] == [
            ("Error", {"comment": "seen it"}, f"acknowledged: opcua {USER}")
        ]
        chart = load_device(str(served.journal.parent / "motor.yaml")).chart
        assert replay(reader, {"Motor": chart}).mismatches == ()
    out = io.StringIO()
    from statectl.channels.cli.journal import journal_show

    assert journal_show(str(served.journal), out=out) == 0
    line = next(x for x in out.getvalue().splitlines() if "acknowledged" in x)
    assert "Error {comment: seen it}" in line and f"acknowledged: opcua {USER}" in line


def test_anonymous_clients_refresh_but_never_acknowledge(served: Served) -> None:
    """An anonymous session may call ConditionRefresh; its Acknowledge is refused."""

    async def go() -> tuple[list[Any], str]:
        client = await _client(served.url, user=False)
        try:
            heard = Alarms()
            sub = await client.create_subscription(0, heard)
            motor = await client.nodes.objects.get_child(["2:Motor"])
            await sub.subscribe_events(motor, KINDS)
            served.system.post("Motor", "Movement")
            served.system.post("Motor", "Error", {"detail": "hot"})
            raised = await heard.next(lambda e: _state(e, "ActiveState") is True)
            refreshed = await _refresh(client, sub, heard)
            condition = await motor.get_child(["2:Alarms", "2:Error"])
            refused = await _status(
                condition.call_method(
                    "0:Acknowledge",
                    ua.Variant(raised.EventId, ua.VariantType.ByteString),
                    ua.LocalizedText(""),
                )
            )
            return [e.Message.Text for e in refreshed], refused
        finally:
            await client.disconnect()

    assert run(go()) == (["hot"], "BadUserAccessDenied")
