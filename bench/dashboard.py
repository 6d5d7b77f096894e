"""The dashboard under 1,000 event streams: every message delivered, memory and latency.

This process is the server: the Motor on a wall clock, one owner thread stepping it at
``--rate`` events per second (Movement, Movement completion, Movement, Error, Error
completion, ...), and a Dashboard on 127.0.0.1. A second process (this file with
``--client``) opens ``--clients`` SSE streams with asyncio and checks that each one
gets every message, numbered without a gap, and measures the time from a record's
step (its ``time`` on the device's clock, which is monotonic and shared by both
processes) to its arrival. This process samples its own RSS meanwhile.

Bounded: each client process has its own time-outs, and every one still running
``--seconds`` + 120 s after the start is killed by its PID. Loopback only.

    python bench/dashboard.py                  # 1,000 clients, 100 events/s, 10 s
    python bench/dashboard.py --clients 100 --seconds 3   # smoke run
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.util
import json
import math
import re
import resource
import subprocess
import sys
import threading
import time
from array import array
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "src"))

CYCLE = ("Movement", "Movement completion", "Movement", "Error", "Error completion")
FRAME = re.compile(rb'id: (\d+)\ndata: \{"type": "record", "device": "[^"]*", "time": ([-0-9.e]+)')


def raise_file_limit() -> None:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = min(hard, 16384) if hard != resource.RLIM_INFINITY else 16384
    if soft < want:
        resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))


def rss_mb() -> tuple[float, float]:
    """(current RSS, peak RSS) of this process in MB."""
    fields = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            fields[key] = int(value.split()[0]) / 1024
    return fields["VmRSS"], fields["VmHWM"]


def percentile(values: Any, q: float) -> float:
    return float(values[min(len(values) - 1, int(q * len(values)))]) if len(values) else math.nan


#: Latency histogram: 0.1 ms bins below 100 ms, 1 ms bins up to 60 s, one overflow bin.
FINE, COARSE = 1000, 59_900


def bin_of(seconds: float) -> int:
    if seconds < 0.1:
        return max(0, int(seconds * 1e4))
    return min(FINE + COARSE, FINE + int((seconds - 0.1) * 1e3))


def bin_ms(index: int) -> float:
    """The upper edge of a bin in milliseconds."""
    return (index + 1) / 10 if index < FINE else 100.0 + (index - FINE + 1)


def hist_percentile(hist: list[int], q: float) -> float:
    total = sum(hist)
    if not total:
        return math.nan
    want, seen = q * total, 0
    for i, n in enumerate(hist):
        seen += n
        if seen >= want:
            return bin_ms(i)
    return math.inf


# -- the server ----------------------------------------------------------------------------


def serve(args: argparse.Namespace) -> dict[str, Any]:
    from statectl.channels.cli.demo import motor_chart
    from statectl.channels.web.app import Limits
    from statectl.channels.web.server import Dashboard
    from statectl.run.runtime import Subject, WallClock

    raise_file_limit()
    clock = WallClock()
    subject = Subject(motor_chart(), clock=clock, name="Motor")
    dash = Dashboard(
        [subject], limits=Limits(streams=args.clients, backlog=args.clients, heartbeat=5.0)
    )
    written: list[float] = []  # per message after go: from its step to its last stream write
    fan_out = dash.fanout.publish
    go: list[float] = []

    def timed(texts: Any) -> None:
        texts = list(texts)
        fan_out(texts)
        if go:
            done = clock.now()
            written.extend(done - json.loads(t)["time"] for t in texts)

    dash.fanout.publish = timed  # type: ignore[method-assign]
    dash.start("127.0.0.1", 0)
    subject.start()
    origin = time.monotonic() - clock.now()
    rss_idle = rss_mb()[0]
    shares = [
        args.clients // args.procs + (i < args.clients % args.procs) for i in range(args.procs)
    ]
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                __file__,
                "--client",
                "--port",
                str(dash.port),
                "--clients",
                str(n),
                "--origin",
                repr(origin),
                "--seconds",
                str(args.seconds),
                "--loop",
                args.loop,
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
        for n in shares
    ]
    result: dict[str, Any] = {"client_loop": args.loop, "clients": args.clients,
                              "client_processes": args.procs,
                              "rate": args.rate}  # fmt: skip

    def kill_all() -> None:  # the bound on the whole run: every child, by its PID
        for proc in procs:
            if proc.poll() is None:
                proc.kill()

    watchdog = threading.Timer(args.seconds + 120, kill_all)
    watchdog.daemon = True
    watchdog.start()
    try:
        for proc in procs:  # "ready N" once every stream of the process has its snapshot
            assert proc.stdout is not None
            ready = proc.stdout.readline().strip()
            if not ready.startswith("ready"):
                raise RuntimeError(f"a client process said {ready!r}")
        rss_connected = rss_mb()[0]
        samples: list[float] = []
        steps = array("d")
        stop = threading.Event()

        def sample() -> None:
            while not stop.wait(0.25):
                samples.append(rss_mb()[0])

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        cpu = time.process_time()
        go.append(clock.now())
        tell(procs, f"go {go[0]!r}")
        count = int(args.rate * args.seconds)
        start = time.monotonic()
        for i in range(count):  # the owner thread: never waits for a client
            delay = start + i / args.rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            t = time.perf_counter()
            subject.dispatch(CYCLE[i % len(CYCLE)])
            steps.append(time.perf_counter() - t)
        elapsed = time.monotonic() - start
        cpu = time.process_time() - cpu
        time.sleep(0.2)  # let the loop hand the last step over
        tell(procs, f"done {dash.fanout.seq}")
        reports = []
        for proc in procs:
            assert proc.stdout is not None
            line = proc.stdout.readline()
            reports.append(json.loads(line) if line else {"error": "no report"})
        stop.set()
        sampler.join()
        rss_peak = rss_mb()[1]
        hist = [0] * (FINE + COARSE + 1)
        for r in reports:
            for k, n in r.pop("hist", {}).items():
                hist[int(k)] += n
        ordered = sorted(steps)
        out = sorted(written)
        result.update(
            streams_complete=sum(r.get("streams_complete", 0) for r in reports),
            streams_with_gap=sum(r.get("streams_with_gap", 0) for r in reports),
            streams_short=sum(r.get("streams_short", 0) for r in reports),
            messages_per_stream=dash.fanout.seq,
            latency_samples=sum(hist),
            p50_ms=hist_percentile(hist, 0.5),
            p99_ms=hist_percentile(hist, 0.99),
            max_ms=hist_percentile(hist, 1.0),
            events=count,
            seconds=round(elapsed, 2),
            dropped_streams=dash.fanout.dropped,
            server_cpu_share=round(cpu / elapsed, 2),
            client_cpu_shares=[r.get("cpu_share") for r in reports],
            rss_idle_mb=round(rss_idle, 1),
            rss_connected_mb=round(rss_connected, 1),
            rss_max_mb=round(max(samples, default=rss_connected), 1),
            rss_peak_mb=round(rss_peak, 1),
            written_p50_ms=round(percentile(out, 0.5) * 1e3, 2),
            written_p99_ms=round(percentile(out, 0.99) * 1e3, 2),
            step_p50_us=round(percentile(ordered, 0.5) * 1e6, 1),
            step_p99_us=round(percentile(ordered, 0.99) * 1e6, 1),
            errors=[r["error"] for r in reports if "error" in r],
        )
        return result
    finally:
        for proc in procs:
            with contextlib.suppress(OSError):
                assert proc.stdin is not None
                proc.stdin.close()
        deadline = time.monotonic() + args.seconds + 60
        for proc in procs:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()  # by PID: the Popen's own process
                proc.wait()
        watchdog.cancel()
        dash.stop()


def tell(procs: list[subprocess.Popen[str]], line: str) -> None:
    for proc in procs:
        assert proc.stdin is not None
        proc.stdin.write(line + "\n")
        proc.stdin.flush()


# -- the clients (separate processes) ------------------------------------------------------


class Stream(asyncio.Protocol):
    """One SSE client: checks ids, records latencies of records stepped after ``go``."""

    def __init__(self, run: Run) -> None:
        self.run = run
        self.buf = b""
        self.last = 0
        self.broken = False
        self.snapshot = asyncio.get_running_loop().create_future()
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]  # uvloop's is not a subclass
        transport.write(
            f"GET /api/events HTTP/1.1\r\nHost: 127.0.0.1:{self.run.port}\r\n\r\n".encode()
        )

    def data_received(self, data: bytes) -> None:
        now = time.monotonic()
        buf = self.buf + data if self.buf else data
        end = buf.rfind(b"\n\n")
        if end < 0:
            self.buf = buf
            return
        block, self.buf = buf[: end + 2], buf[end + 2 :]
        if not self.snapshot.done() and b'"type": "snapshot"' in block:
            self.snapshot.set_result(None)
        frames = FRAME.findall(block)
        if not frames:
            return
        ids = [int(i) for i, _ in frames]
        first = ids[0] if self.last == 0 else self.last + 1
        if ids != list(range(first, first + len(ids))):
            self.broken = True
        self.last = ids[-1]
        go = self.run.go
        if go is not None:
            base = now - self.run.origin
            hist = self.run.hist
            oldest = float(frames[0][1])
            if oldest >= go:  # one figure per read: the oldest message's, counted for each
                hist[bin_of(base - oldest)] += len(frames)
                return
            for _, t in frames:
                stepped = float(t)
                if stepped >= go:
                    hist[bin_of(base - stepped)] += 1

    def connection_lost(self, exc: Exception | None) -> None:
        self.run.lost += 1
        if not self.snapshot.done():
            self.snapshot.set_exception(ConnectionError("closed before the snapshot"))


class Run:
    def __init__(self, port: int, origin: float) -> None:
        self.port = port
        self.origin = origin
        self.go: float | None = None
        self.hist = [0] * (FINE + COARSE + 1)
        self.lost = 0


async def clients(args: argparse.Namespace) -> dict[str, Any]:
    loop = asyncio.get_running_loop()
    run = Run(args.port, args.origin)
    streams: list[Stream] = []
    for i in range(0, args.clients, 100):  # connect in groups, each waits for its snapshots
        group = [Stream(run) for _ in range(min(100, args.clients - i))]
        await asyncio.wait_for(
            asyncio.gather(
                *(loop.create_connection(lambda s=s: s, "127.0.0.1", args.port) for s in group)
            ),
            30,
        )
        await asyncio.wait_for(asyncio.gather(*(s.snapshot for s in group)), 30)
        streams.extend(group)
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    print(f"ready {len(streams)}", flush=True)
    line = (await asyncio.wait_for(reader.readline(), 30)).decode().split()
    run.go = float(line[1])
    cpu, wall = time.process_time(), loop.time()
    line = (await asyncio.wait_for(reader.readline(), args.seconds + 30)).decode().split()
    last = int(line[1])
    cpu, wall = time.process_time() - cpu, loop.time() - wall
    deadline = loop.time() + 30
    while any(s.last < last for s in streams) and loop.time() < deadline:
        await asyncio.sleep(0.05)
    for s in streams:
        if s.transport is not None:
            s.transport.close()
    return {
        "streams_complete": sum(1 for s in streams if s.last >= last and not s.broken),
        "streams_with_gap": sum(1 for s in streams if s.broken),
        "streams_short": sum(1 for s in streams if s.last < last),
        "cpu_share": round(cpu / wall, 2),
        "hist": {i: n for i, n in enumerate(run.hist) if n},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--clients", type=int, default=1000)
    parser.add_argument("--rate", type=float, default=100.0, help="device events per second")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--procs", type=int, default=2, help="client processes")
    parser.add_argument(
        "--loop",
        choices=("uvloop", "asyncio"),
        default="uvloop" if importlib.util.find_spec("uvloop") else "asyncio",
        help="the clients' event loop (uvloop, from the bench extra, when installed)",
    )
    parser.add_argument("--client", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--port", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--origin", type=float, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        raise_file_limit()
        run = asyncio.run
        if args.loop == "uvloop":  # the clients' own cost is not what is measured
            import uvloop

            run = uvloop.run
        print(json.dumps(run(clients(args))), flush=True)
        return
    try:
        result = serve(args)
    except RuntimeError as exc:
        sys.exit(f"bench/dashboard.py: {exc}")
    print(json.dumps(result, indent=2))
    ok = (
        result.get("streams_complete") == args.clients
        and result.get("rss_max_mb", 1e9) <= 150
        and result.get("p99_ms", 1e9) <= 50
    )
    print("targets (every event to every client, RSS <= 150 MB, p99 <= 50 ms):",
          "met" if ok else "NOT met")  # fmt: skip


if __name__ == "__main__":
    main()
