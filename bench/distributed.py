"""Distributed cell benchmark (not a test): a link event across two processes on Zenoh.

Run: ``python bench/distributed.py [--events N] [--burst N] [--breakdown]``. Two
processes on loopback: this one runs node ``a`` (device ``ping``), a child runs
node ``b`` (device ``pong``). Measured, all in the same run:

- latency: ``post(ping, Go)`` on node a -> the link event ``Hit`` -> pong's observer
  call ``Hit()`` on node b (one way; both processes read CLOCK_MONOTONIC, which Linux
  shares between processes), against a bare Zenoh ``put`` -> subscriber callback one
  way between the same two sessions, and the bare put/subscribe round trip;
- sustained: ``--burst`` Go events posted at once; link events/s until pong's
  observer has been called for every one, exactly once and in order;
- peer loss: SIGKILL of node b -> node a's liveliness subscriber says it is gone.

``--breakdown`` also stamps each hop of the paced link events (CLOCK_MONOTONIC on
both sides) and prints the median of each hop: post -> the wire's ``send`` ->
Zenoh ``put`` (entry, return) -> node b's link callback -> the device's step on
that thread (``System.submit``, the door) -> the observer call. The stamps wrap the calls, so
they add a little to the link's figures; leave it off for the targets.

Targets (issue 16): link p50 <= 1.5x bare Zenoh, p99 <= 2 ms, >= 20,000 link
events/s with nothing lost, peer loss noticed within 50 ms.
"""

from __future__ import annotations

import argparse
import io
import itertools
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from statectl.cell.model import load_cell
from statectl.channels.distributed import NodeSystem, Wire
from statectl.run.runner.cells import cell_setups
from statectl.run.runtime import WallClock

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
CELL = """cell: Bench
devices: {ping: ping.yaml, pong: pong.yaml}
nodes:
  a: {devices: [ping], listen: [tcp/127.0.0.1:%(a)d], lease: 0.5}
  b: {devices: [pong], listen: [tcp/127.0.0.1:%(b)d], connect: [tcp/127.0.0.1:%(a)d],
      lease: 0.5}
links:
  - {from: ping, raises: Go, to: pong, send: Hit}
"""
BARE = "bench/bare"


class Stamps:
    """Per-hop stamps of the link path (``--breakdown``): wrappers around the calls."""

    def __init__(self) -> None:
        self.at: dict[str, list[int]] = {}

    def wrap(self, name: str, fn: Any) -> Any:
        times = self.at.setdefault(name, [])
        clock = time.monotonic_ns

        def stamped(*args: Any, **kwargs: Any) -> Any:
            times.append(clock())
            return fn(*args, **kwargs)

        return stamped

    def after(self, name: str, fn: Any) -> Any:
        times = self.at.setdefault(name, [])
        clock = time.monotonic_ns

        def stamped(*args: Any, **kwargs: Any) -> Any:
            try:
                return fn(*args, **kwargs)
            finally:
                times.append(clock())

        return stamped


class _Pub:
    """A publisher whose puts are stamped on entry and return."""

    def __init__(self, pub: Any, stamps: Stamps) -> None:
        self.put = stamps.after("put-return", stamps.wrap("put", pub.put))


class Calls:
    """An observer that notes when it is called (CLOCK_MONOTONIC, nanoseconds)."""

    def __init__(self) -> None:
        self.times: list[int] = []

    def update(self, notification: Any) -> None:
        self.times.append(time.monotonic_ns())


def node(cell_path: Path, name: str) -> tuple[NodeSystem, Wire]:
    cell, diags = load_cell(cell_path)
    assert cell is not None and cell.nodes is not None, diags
    mine = cell.nodes.node(name).devices
    setups = tuple(s for s in cell_setups(cell, journalled=False) if s.name in mine)
    system = NodeSystem(setups, WallClock(), None, cell)
    wire = Wire(cell, name, system, out=io.StringIO())
    return system, wire


def stamp_a(system: NodeSystem, wire: Wire) -> Stamps:
    """--breakdown on node a: the wire's send, the link publisher's put (after open())."""
    stamps = Stamps()
    wire.send = stamps.wrap("send", wire.send)  # type: ignore[method-assign]
    wire._pubs["pong"] = _Pub(wire._pubs["pong"], stamps)
    return stamps


def stamp_b(system: NodeSystem, wire: Wire) -> Stamps:
    """--breakdown on node b: the link callback, the device's step (before listen())."""
    stamps = Stamps()
    receiver = wire._receiver  # each stream's link callback, made in listen()

    def stamped(node: str, device: str, *rest: Any) -> Any:
        return stamps.wrap("on_link", receiver(node, device, *rest))

    wire._receiver = stamped  # type: ignore[method-assign]
    system.submit = stamps.wrap("submit", system.submit)  # type: ignore[method-assign]
    return stamps


def child(cell_path: Path, breakdown: bool) -> None:
    """Node b: pong's observer calls, a bare subscriber; reports on 'report' lines."""
    system, wire = node(cell_path, "b")
    calls = Calls()
    system.subjects["pong"].attach(calls)
    wire.open()
    system.start()
    stamps = stamp_b(system, wire) if breakdown else Stamps()
    wire.listen()
    halt = system.start_owner(paced=False)
    session = wire.session
    bare: list[int] = []

    def on_bare(sample: Any) -> None:
        bare.append(time.monotonic_ns())
        pong.put(b"x")

    pong = session.declare_publisher(
        f"{BARE}/pong", congestion_control=zenoh.CongestionControl.BLOCK
    )
    sub = session.declare_subscriber(f"{BARE}/ping", on_bare)
    print("ready", flush=True)
    hit_from = bare_from = 0
    stamp_from = dict.fromkeys(stamps.at, 0)
    for line in sys.stdin:
        if line.strip() == "report":  # what is new since the last report (appends race on)
            hits = calls.times[hit_from:]
            hit_from += len(hits)
            news = bare[bare_from:]
            bare_from += len(news)
            hops = {}
            for name, times in stamps.at.items():
                hops[name] = times[stamp_from[name] :]
                stamp_from[name] += len(hops[name])
            print(json.dumps({"hits": hits, "bare": news, "hops": hops}), flush=True)
    del sub
    halt()


def pct(values: list[float], p: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(p * len(ordered)))]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=int, default=2000, help="paced events for the latency")
    ap.add_argument("--burst", type=int, default=50_000, help="events posted at once")
    ap.add_argument("--breakdown", action="store_true", help="print each hop's median too")
    ap.add_argument("--role", default="a", help=argparse.SUPPRESS)
    ap.add_argument("--cell", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role == "b":
        child(Path(args.cell), args.breakdown)
        return 0
    return run(args.events, args.burst, args.breakdown)


def free_ports(n: int) -> list[int]:
    """Ports the OS hands out now (held open together so they differ)."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def hop_medians(sent: list[int], a: Stamps, b: dict[str, list[int]], hits: list[int]) -> str:
    """--breakdown: the median of each hop of the paced link events, in microseconds."""
    n = len(sent)
    at = {k: v[-n:] for k, v in a.at.items()}  # the warm-up's stamps come first
    path = [("post", sent), ("send", at["send"]), ("put", at["put"])]
    path += [("put-return", at["put-return"]), ("on_link", b["on_link"][-n:])]
    path += [("submit", b["submit"][-n:]), ("observer", hits)]
    lines = []
    for (x, xs), (y, ys) in itertools.pairwise(path):
        gaps = [(t - s) / 1000 for s, t in zip(xs, ys, strict=True)]
        lines.append(f"  {x} -> {y}: {statistics.median(gaps):.1f} us")
    wire = [(t - s) / 1000 for s, t in zip(at["put"], b["on_link"][-n:], strict=True)]
    lines.append(f"  (put -> on_link, Zenoh's part: {statistics.median(wire):.1f} us)")
    return "\n".join(lines)


def run(events: int, burst: int, breakdown: bool = False) -> int:
    tmp = Path(tempfile.mkdtemp(prefix="statectl-bench-"))
    (tmp / "ping.yaml").write_text(PING)
    (tmp / "pong.yaml").write_text(PONG)
    a, b = free_ports(2)
    cell_path = tmp / "cell.yaml"
    cell_path.write_text(CELL % {"a": a, "b": b})
    system, wire = node(cell_path, "a")
    wire.open()
    stamps = stamp_a(system, wire) if breakdown else Stamps()
    system.start()
    wire.listen()
    role = ["--role", "b", "--cell", str(cell_path)] + (["--breakdown"] if breakdown else [])
    proc = subprocess.Popen(
        [sys.executable, __file__, *role],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdin is not None and proc.stdout is not None
    try:
        assert proc.stdout.readline().strip() == "ready"
        while "b" not in wire.up:
            time.sleep(0.01)
        time.sleep(0.5)

        def report() -> dict[str, Any]:
            assert proc.stdin is not None and proc.stdout is not None
            proc.stdin.write("report\n")
            proc.stdin.flush()
            result: dict[str, Any] = json.loads(proc.stdout.readline())
            return result

        def go() -> None:
            """The producer owns node a's devices: post, then run what is queued."""
            system.post("ping", "Go")
            system.drain()

        session = wire.session
        back = threading.Event()
        sub = session.declare_subscriber(f"{BARE}/pong", lambda s: back.set())
        pub = session.declare_publisher(  # as the link's
            f"{BARE}/ping", congestion_control=zenoh.CongestionControl.BLOCK
        )
        # warm up both paths
        for _ in range(200):
            go()
            back.clear()
            pub.put(b"x")
            back.wait(1)
        time.sleep(0.3)
        report()
        link_sent: list[int] = []
        bare_sent: list[int] = []
        bare_put: list[float] = []
        round_trip: list[float] = []
        for _ in range(events):
            link_sent.append(time.monotonic_ns())
            go()
            time.sleep(0.002)
            back.clear()
            t = time.monotonic_ns()
            bare_sent.append(t)
            pub.put(b"x")
            if breakdown:  # how long the bare put itself takes, against the link's
                bare_put.append((time.monotonic_ns() - t) / 1000)
            back.wait(1)
            round_trip.append((time.monotonic_ns() - t) / 1000)
            time.sleep(0.001)
        time.sleep(0.3)
        got = report()
        assert len(got["hits"]) == events, (len(got["hits"]), events)
        link = [(h - s) / 1000 for h, s in zip(got["hits"], link_sent, strict=True)]
        hops = hop_medians(link_sent, stamps, got["hops"], got["hits"]) if breakdown else ""
        bare = [(h - s) / 1000 for h, s in zip(got["bare"], bare_sent, strict=True)]
        del sub
        # sustained
        start = time.monotonic_ns()
        for _ in range(burst):
            go()
        hits: list[int] = []
        deadline = time.monotonic() + 120
        while len(hits) < burst and time.monotonic() < deadline:
            time.sleep(0.2)
            hits += report()["hits"]
        time.sleep(0.3)  # a link event applied twice would come now
        hits += report()["hits"]
        rate = burst / ((hits[-1] - start) / 1e9) if len(hits) == burst else 0.0
        # peer loss: cut off (SIGSTOP: the connection stays open, nothing comes), then dead
        stopped = time.monotonic()
        os.kill(proc.pid, signal.SIGSTOP)
        while "b" not in wire.lost_at and time.monotonic() < stopped + 30:
            time.sleep(0.0005)
        cut_off = (wire.lost_at.pop("b", float("nan")) - stopped) * 1000
        os.kill(proc.pid, signal.SIGCONT)
        while "b" not in wire.up and time.monotonic() < stopped + 60:
            time.sleep(0.01)
        time.sleep(0.5)
        killed = time.monotonic()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        while "b" not in wire.lost_at and time.monotonic() < killed + 10:
            time.sleep(0.0005)
        noticed = (wire.lost_at.get("b", float("nan")) - killed) * 1000
        p50_link, p50_bare = statistics.median(link), statistics.median(bare)
        print(f"events: {events} paced, burst {burst}; eclipse-zenoh, two processes, loopback")
        print(
            f"bare Zenoh put -> subscriber (one way): p50 {p50_bare:.0f} us, "
            f"p99 {pct(bare, 0.99):.0f} us; round trip p50 {statistics.median(round_trip):.0f} us"
        )
        print(
            f"link event post -> observer call on the other node: p50 {p50_link:.0f} us, "
            f"p99 {pct(link, 0.99):.0f} us"
        )
        print(f"p50 ratio link / bare (one way): {p50_link / p50_bare:.2f}x")
        if hops:
            print("link hops (median, --breakdown):\n" + hops)
            print(f"  (the bare put itself: {statistics.median(bare_put):.1f} us)")
        print(
            f"sustained: {len(hits)} observer calls for {burst} link events (none lost or "
            "doubled when equal): "
            f"{rate:,.0f} link events/s"
        )
        print(f"peer loss (SIGKILL) noticed after {noticed:.1f} ms")
        print(f"peer cut off (SIGSTOP, lease 500 ms) noticed after {cut_off:.0f} ms")
        return 0
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(10)
        wire.close()
        system.close()


if __name__ == "__main__":
    sys.exit(main())
