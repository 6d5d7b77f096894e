"""A node's receiving side of link streams, in one process, without a Zenoh session.

The wire's per-stream receiver (statectl.channels.distributed.wire) is fed samples as Zenoh
would hand them: it must apply each link event once and in order, run the device
on the calling thread only when nobody owns the devices (else leave it to the
owner), and drop a payload it cannot read.
"""

from __future__ import annotations

import io
import json
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from statectl.cell.model import load_cell
from statectl.channels.distributed import NodeSystem, Wire
from statectl.kernel.errors import StatectlError
from statectl.run.door import Submitted
from statectl.run.runner.cells import cell_setups
from statectl.run.runtime import SimClock

PING = """device: Ping
states:
  - {component: Ping, api: Go(), state: Idle, control: default, description: waits}
  - {component: Ping, api: Go(), state: Busy, control: event trigger required,
     description: toggles}
events:
  - {event: Go, condition: go, old: Idle, new: Busy, kind: command, api: Go}
  - {event: Go, condition: go, old: Busy, new: Idle, kind: command, api: Go}
"""
PONG = """device: Pong
states:
  - {component: Pong, api: Hit(), state: Up, control: default, description: waits}
  - {component: Pong, api: Hit(), state: Down, control: event trigger required,
     description: toggles}
events:
  - {event: Hit, condition: hit, old: Up, new: Down, kind: command, api: Hit}
  - {event: Hit, condition: hit, old: Down, new: Up, kind: command, api: Hit}
"""
CELL = """cell: Receive
devices: {ping: ping.yaml, pong: pong.yaml, ping2: ping.yaml}
nodes:
  a: {devices: [ping], listen: [tcp/127.0.0.1:1]}
  b: {devices: [pong], listen: [tcp/127.0.0.1:2]}
  c: {devices: [ping2], listen: [tcp/127.0.0.1:3]}
links:
  - {from: ping, raises: Go, to: pong, send: Hit, forward_data: true}
  - {from: ping2, raises: Go, to: pong, send: Hit}
"""


class _Payload:
    def __init__(self, data: bytes) -> None:
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


class _Sample:
    """What a Zenoh subscriber callback reads of a sample: its payload."""

    def __init__(self, data: bytes) -> None:
        self.payload = _Payload(data)


class _Pub:
    """A link publisher that keeps what is put."""

    def __init__(self) -> None:
        self.puts: list[bytes] = []

    def put(self, data: bytes) -> None:
        self.puts.append(data)


class _Hits:
    """pong's observer: each call's thread, and whether two calls ever overlapped."""

    def __init__(self, pause: float = 0.0) -> None:
        self.threads: list[threading.Thread] = []
        self.inside = 0
        self.overlapped = False
        self.pause = pause

    def update(self, notification: Any) -> None:
        self.inside += 1
        if self.inside > 1:
            self.overlapped = True
        self.threads.append(threading.current_thread())
        if self.pause:
            time.sleep(self.pause)
        self.inside -= 1


def _node(tmp_path: Path, name: str) -> tuple[NodeSystem, Wire]:
    (tmp_path / "ping.yaml").write_text(PING)
    (tmp_path / "pong.yaml").write_text(PONG)
    (tmp_path / "cell.yaml").write_text(CELL)
    cell, diags = load_cell(tmp_path / "cell.yaml")
    assert cell is not None and cell.nodes is not None, diags
    mine = cell.nodes.node(name).devices
    setups = tuple(s for s in cell_setups(cell, journalled=False) if s.name in mine)
    system = NodeSystem(setups, SimClock(), None, cell)
    wire = Wire(cell, name, system, out=io.StringIO())
    system.start()
    return system, wire


def _receiver_b(tmp_path: Path, pause: float = 0.0) -> tuple[NodeSystem, Wire, _Hits]:
    system, wire = _node(tmp_path, "b")
    for node, epoch in (("a", "ep1"), ("c", "ep-c")):  # as the senders' hellos would
        wire.inbound.announce(node, "pong", epoch)
    hits = _Hits(pause)
    system.subjects["pong"].attach(hits)
    return system, wire, hits


def _event(e: str, n: int, event: str = "Hit") -> _Sample:
    return _Sample(f'["{e}",{n},"{event}",null]'.encode())


@pytest.mark.parametrize(
    ("numbers", "applied", "ack"),
    [
        ([1, 2, 3], 3, (3, False)),  # in order: each applied
        ([1, 2, 2, 1, 3], 3, (3, False)),  # duplicates (a resend after a reconnect) dropped
        ([1, 3], 1, (1, True)),  # a gap: not applied, the sender is asked to resend after 1
        ([5, 6], 2, (6, False)),  # a new epoch starts wherever its first event is
    ],
)
def test_receiver_applies_each_number_once_in_order(
    tmp_path: Path, numbers: list[int], applied: int, ack: tuple[int, bool]
) -> None:
    """A stream's receiver runs the next number only, and acknowledges how far it got."""
    _system, wire, hits = _receiver_b(tmp_path)
    on_link = wire._receiver("a", "pong")
    for n in numbers:
        on_link(_event("ep1", n))
    assert len(hits.threads) == applied
    assert wire._ack_due["a", "pong"] == ("ep1", *ack)


@pytest.mark.parametrize(
    "payload",
    [
        b"not json",
        b'{"e":"ep1","n":1,"ev":"Hit","d":null}',  # an object, not the array
        b'["ep1","one","Hit",null]',  # a number that is not one
        b'["ep1",1]',  # too short
        b"",
    ],
)
def test_receiver_drops_a_payload_it_cannot_read(tmp_path: Path, payload: bytes) -> None:
    """A link payload that is not [e, n, ev, d] is dropped: nothing runs, nothing is acked."""
    _system, wire, hits = _receiver_b(tmp_path)
    wire._receiver("a", "pong")(_Sample(payload))
    assert hits.threads == []
    assert wire._ack_due == {}


def test_receiver_runs_the_device_on_its_thread_when_nobody_owns_it(tmp_path: Path) -> None:
    """With the owner lock free, the event runs on the callback's thread (no handoff)."""
    _system, wire, hits = _receiver_b(tmp_path)
    wire._receiver("a", "pong")(_event("ep1", 1))
    assert hits.threads == [threading.current_thread()]


class _Refuses(_Hits):
    """pong's observer as a driver that refuses the first notification's data."""

    def update(self, notification: Any) -> None:
        if not self.threads:
            self.threads.append(threading.current_thread())
            raise StatectlError("a hit needs {force: <number>}")
        super().update(notification)


def test_a_driver_refusing_a_link_event_fails_that_event_only(tmp_path: Path) -> None:
    """A link event whose observer raises goes to on_failure (the node counts it and exits
    1) and the stream goes on; it used to be said on the wire only, and count for nothing."""
    system, wire = _node(tmp_path, "b")
    refuses = _Refuses()
    system.subjects["pong"].attach(refuses)
    failures: list[str] = []
    system.on_failure.append(lambda exc: failures.append(str(exc)))
    wire.inbound.announce("a", "pong", "ep1")  # as the sender's hello would
    on_link = wire._receiver("a", "pong")
    on_link(_event("ep1", 1))
    on_link(_event("ep1", 2))
    assert failures == ["a hit needs {force: <number>}"]
    assert len(refuses.threads) == 2  # the next event ran
    assert system.subjects["pong"].configuration == frozenset({"Up"})  # both toggles taken


def test_receiver_leaves_the_event_to_a_busy_owner(tmp_path: Path) -> None:
    """While another thread owns the devices, the receiver only queues and wakes the owner;
    the owner then runs the stream's events in their order."""
    system, wire, hits = _receiver_b(tmp_path)
    on_link = wire._receiver("a", "pong")
    owned = threading.Event()
    release = threading.Event()

    def owner() -> None:
        with system.owner:
            owned.set()
            release.wait(10)
            system._drain()

    thread = threading.Thread(target=owner)
    thread.start()
    owned.wait(10)
    system.wake.clear()
    for n in (1, 2, 3):
        on_link(_event("ep1", n))
    assert hits.threads == []  # queued, not run by the callback's thread
    assert system.wake.is_set()
    assert system.subjects["pong"].queued == 3
    release.set()
    thread.join(10)
    assert hits.threads == [thread] * 3
    assert system.subjects["pong"].snapshot is not None
    assert system.subjects["pong"].configuration == frozenset({"Down"})  # three toggles


def test_receivers_on_two_threads_never_step_the_device_at_once(tmp_path: Path) -> None:
    """Two streams' callbacks on two threads at once: one thread steps the device at a
    time, and each stream's events run once and in order."""
    system, wire, hits = _receiver_b(tmp_path, pause=0.0005)
    order: list[tuple[str, int]] = []
    pong = system.subjects["pong"]
    pong.on_step(lambda event, data, outcome: order.append(("step", 0)))
    count = 60
    errors: list[BaseException] = []
    wire.inbound.announce("a", "pong", "ep-a")

    def feed(node: str) -> Callable[[], None]:
        on_link = wire._receiver(node, "pong")

        def run() -> None:
            try:
                for n in range(1, count + 1):
                    on_link(_event(f"ep-{node}", n))
            except BaseException as exc:
                errors.append(exc)

        return run

    threads = [threading.Thread(target=feed(node)) for node in ("a", "c")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    system.drain()  # whatever a callback queued while the other owned the devices
    assert errors == []
    assert not hits.overlapped
    assert len(hits.threads) == 2 * count
    assert wire._ack_due["a", "pong"][:2] == ("ep-a", count)
    assert wire._ack_due["c", "pong"][:2] == ("ep-c", count)


def test_a_link_event_sent_is_read_by_the_receiver(tmp_path: Path) -> None:
    """What node a's wire puts for a link event is what node b's receiver applies."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    system_a, wire_a = _node(tmp_path / "a", "a")
    pub = _Pub()
    wire_a._pubs["pong"] = pub
    wire_a.up.add("b")
    wire_a._session = object()  # open, as far as send() asks
    wire_a.outbound["pong"].greeted = True  # its hello went out
    system_a.post("ping", "Go")
    system_a.drain()
    system_a.post("ping", "Go")
    system_a.drain()
    assert len(pub.puts) == 2
    _system_b, wire_b, hits = _receiver_b(tmp_path / "b")
    wire_b.inbound.announce("a", "pong", wire_a.epoch)
    on_link = wire_b._receiver("a", "pong")
    for data in pub.puts:
        on_link(_Sample(data))
    assert len(hits.threads) == 2
    assert wire_b._ack_due["a", "pong"] == (wire_a.epoch, 2, False)
    wire_a._session = None


def test_a_stream_on_two_threads_never_lets_a_later_number_overtake(tmp_path: Path) -> None:
    """Event 2 of a stream, arriving on another thread while event 1 is between its
    order check and its step, waits for event 1 (the device steps 1, then 2)."""
    system, wire, _hits = _receiver_b(tmp_path)
    order: list[Any] = []
    system.subjects["pong"].on_step(lambda event, data, outcome: order.append(data))
    paused = threading.Event()
    go_on = threading.Event()
    submit = system.submit

    def slow_first(device: str, event: str, data: Any, **how: Any) -> Submitted:
        if data == 1:  # event 1 has passed its order check: hold it before the door
            paused.set()
            go_on.wait(10)
        return submit(device, event, data, **how)

    system.submit = slow_first  # type: ignore[method-assign]
    on_link = wire._receiver("a", "pong")
    first = threading.Thread(target=on_link, args=(_Sample(b'["ep1",1,"Hit",1]'),))
    first.start()
    assert paused.wait(10)
    second = threading.Thread(target=on_link, args=(_Sample(b'["ep1",2,"Hit",2]'),))
    second.start()
    second.join(0.2)  # time for event 2 to overtake, if it could
    go_on.set()
    first.join(10)
    second.join(10)
    system.drain()
    assert order == [1, 2]


@pytest.mark.parametrize(
    ("data", "refused"),
    [
        ({"x": 1.5, "y": [1, "a"]}, False),
        ({"x": float("nan")}, True),
        ({"x": {"y": [float("inf")]}}, True),
        ([1.0, -float("inf")], True),
        ("nan", False),
    ],
)
def test_link_data_json_cannot_carry_is_refused_not_sent_as_null(data: Any, refused: bool) -> None:
    """A NaN or infinity in link data is refused with the event named (msgspec would send
    null); finite numbers and strings pass."""
    from statectl.channels.distributed.messages import refuse_non_finite as _refuse_non_finite

    if refused:
        with pytest.raises(ValueError, match=r"'Hit' to 'pong'.*cannot carry"):
            _refuse_non_finite(data, "pong", "Hit")
    else:
        _refuse_non_finite(data, "pong", "Hit")


class _Session:
    """What the wire's thread puts on its session (hellos, acks): (key, payload) in order."""

    def __init__(self) -> None:
        self.puts: list[tuple[str, str]] = []

    def put(self, key: str, data: str) -> None:
        self.puts.append((key, data))


def test_the_first_link_event_follows_the_acknowledged_hello_without_a_resend(
    tmp_path: Path,
) -> None:
    """Node a's first link event to pong is kept until b acknowledged a's hello (Zenoh may
    hand b the event before the hello, and b would refuse it), then put once; the hello is
    said again on the next tick while unheard. No stream waits for RESEND_AFTER."""
    system_a, wire_a = _node(tmp_path, "a")
    pub, session = _Pub(), _Session()
    wire_a._pubs["pong"] = pub
    wire_a._session = session  # open, as far as send() asks
    stream = wire_a.outbound["pong"]
    hello = (wire_a.keys.hello("a", "pong"), f'{{"e":"{wire_a.epoch}"}}')
    try:
        wire_a.up.add("b")  # b came up: a hello is due
        wire_a._hello_due.add("pong")
        wire_a._resend(session)
        system_a.post("ping", "Go")  # the first link event, before b answered
        system_a.drain()
        wire_a._resend(session)  # the same tick: not said again yet
        assert (session.puts, pub.puts) == ([hello], [])
        stream.hello_at -= 1.0  # a tick later, still unheard: said again
        wire_a._resend(session)
        assert (session.puts, pub.puts) == ([hello, hello], [])
        ack = _Sample(f'{{"e":"{wire_a.epoch}","n":0,"r":true}}'.encode())
        ack.key_expr = wire_a.keys.ack("a", "pong")  # type: ignore[attr-defined]
        wire_a._on_ack(ack)  # b heard the hello: nothing applied yet, send it all
        wire_a._resend(session)
        system_a.post("ping", "Go")  # the second goes at once
        system_a.drain()
        assert [json.loads(p)[1] for p in pub.puts] == [1, 2]
        assert wire_a.resends == 0
    finally:
        wire_a._session = None
