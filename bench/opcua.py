"""OPC UA: a method call to the subscribed state change, statectl against bare asyncua.

Two servers in this process, each on its own thread and loop, on 127.0.0.1 with
``None`` security (so the figure is the servers', not the cipher's):

- **statectl**: ``statectl run --opcua`` as a library (:class:`OpcuaServer`) on a
  two-state device (``Go``: A -> B, ``Back``: B -> A; the methods ``Go`` and
  ``Back``), the System's owner on its own thread, a user for the calls.
- **bare asyncua**: an asyncua server with one String variable and the methods
  ``Go`` and ``Back``, which write ``B`` or ``A`` to it and return.

The client is a separate process (this file with ``--client``, one per round and
contender, stopped by its PID if it overruns): it subscribes to the state
(``CurrentState`` / the variable) with a 0 ms publishing interval and, per sample,
calls ``Go`` or ``Back`` and waits for the notification of the new value. Rounds are
interleaved (each round runs both, the order alternating), the first is warm-up;
the figure is the median latency over every kept sample, and the ratio of the two.
Target: statectl <= 1.3x bare.

    python bench/opcua.py                       # 7 rounds of 200 calls
    python bench/opcua.py --rounds 3 --calls 50 # smoke run
"""

from __future__ import annotations

import argparse
import asyncio
import json
import socket
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "src"))

from asyncua import Client, Server, ua  # noqa: E402

from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings  # noqa: E402
from statectl.kernel.model import Chart, EventDef, State, Transition  # noqa: E402
from statectl.run.runtime import WallClock  # noqa: E402
from statectl.run.system import DeviceSetup, System  # noqa: E402

USER, PASSWORD = "bench", "bench-password-long"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def toggle_chart() -> Chart:
    return Chart(
        "Toggle",
        states=(State("A"), State("B")),
        transitions=(Transition("A", ("Go",), ("B",)), Transition("B", ("Back",), ("A",))),
        initial=("A",),
        events=(EventDef("Go"), EventDef("Back")),
    )


def start_statectl() -> tuple[str, Callable[[], None]]:
    chart = toggle_chart()
    system = System((DeviceSetup(chart.name, chart),), WallClock())
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    server = OpcuaServer(
        system, OpcuaSettings(endpoint=url, user=USER, password=PASSWORD, security=("None",))
    )
    server.start()
    system.start()
    server.refresh()
    halt = system.start_owner(paced=False)

    def stop() -> None:
        halt()
        server.stop()
        system.close()

    return url, stop


def start_bare() -> tuple[str, Callable[[], None]]:
    """A plain asyncua server doing the same: a method writes the state variable."""
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    ready, done = threading.Event(), threading.Event()
    loop_box: list[asyncio.AbstractEventLoop] = []
    stop_box: list[asyncio.Event] = []

    async def serve() -> None:
        server = Server()
        await server.init()
        server.set_endpoint(url)
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        idx = await server.register_namespace("urn:bench:bare")
        device = await server.nodes.objects.add_object(idx, "Toggle")
        state = await device.add_variable(idx, "State", ua.LocalizedText("A"))

        def method(value: str) -> Callable[..., Awaitable[list[ua.Variant]]]:
            async def call(_parent: Any) -> list[ua.Variant]:
                await state.write_value(ua.LocalizedText(value))
                return [
                    ua.Variant(True, ua.VariantType.Boolean),
                    ua.Variant("", ua.VariantType.String),
                ]

            return call

        for name, value in (("Go", "B"), ("Back", "A")):
            await device.add_method(
                idx, name, method(value), [], [ua.VariantType.Boolean, ua.VariantType.String]
            )
        loop_box.append(asyncio.get_running_loop())
        stop_box.append(asyncio.Event())
        async with server:
            ready.set()
            await stop_box[0].wait()
        done.set()

    thread = threading.Thread(target=lambda: asyncio.run(serve()), daemon=True)
    thread.start()
    ready.wait(30)

    def stop() -> None:
        loop_box[0].call_soon_threadsafe(stop_box[0].set)
        thread.join(30)

    return url, stop


class Waiter:
    def __init__(self) -> None:
        self.value: str | None = None
        self.changed = asyncio.Event()

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        self.value = val.Text
        self.changed.set()


async def measure(url: str, path: list[str], calls: int, user: bool) -> list[float]:
    client = Client(url, timeout=10)
    if user:
        client.set_user(USER)
        client.set_password(PASSWORD)
    async with client:
        device = await client.nodes.objects.get_child(["2:Toggle"])
        node = await device.get_child(path)
        waiter = Waiter()
        sub = await client.create_subscription(0, waiter)
        await sub.subscribe_data_change(node)
        while waiter.value is None:
            await asyncio.wait_for(waiter.changed.wait(), 10)
            waiter.changed.clear()
        go = await device.get_child("2:Go")
        back = await device.get_child("2:Back")
        samples = []
        for i in range(calls):
            want, method = ("B", go) if waiter.value == "A" else ("A", back)
            waiter.changed.clear()
            start = time.perf_counter()
            result = await device.call_method(method)
            assert result[0] is True, result
            while waiter.value != want:
                await asyncio.wait_for(waiter.changed.wait(), 10)
                waiter.changed.clear()
            samples.append(time.perf_counter() - start)
            del i
        await sub.delete()
    return samples


def client_process(url: str, path: list[str], calls: int, user: bool) -> list[float]:
    """One round's samples, measured by a client in its own process."""
    command = [sys.executable, __file__, "--client", json.dumps([url, path, calls, user])]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    try:
        out, _ = process.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
        raise
    if process.returncode != 0:
        raise RuntimeError(f"the client failed (exit {process.returncode})")
    samples: list[float] = json.loads(out)
    return samples


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--client", help=argparse.SUPPRESS)
    args = parser.parse_args()
    import logging

    logging.disable(logging.WARNING)
    if args.client is not None:
        url, path, calls, user = json.loads(args.client)
        print(json.dumps(asyncio.run(measure(url, path, calls, user))))
        return 0
    ours_url, ours_stop = start_statectl()
    bare_url, bare_stop = start_bare()
    contenders = {
        "statectl": (ours_url, ["2:StateMachine", "0:CurrentState"], True),
        "bare asyncua": (bare_url, ["2:State"], False),
    }
    kept: dict[str, list[float]] = {name: [] for name in contenders}
    try:
        for r in range(args.rounds):
            order = list(contenders) if r % 2 == 0 else list(reversed(contenders))
            for name in order:
                url, path, user = contenders[name]
                samples = client_process(url, path, args.calls, user)
                if r > 0:
                    kept[name].extend(samples)
    finally:
        ours_stop()
        bare_stop()
    medians = {n: statistics.median(s) for n, s in kept.items()}
    for name, m in medians.items():
        p90 = statistics.quantiles(kept[name], n=10)[-1]
        print(
            f"{name:<14} median {m * 1e3:6.3f} ms   p90 {p90 * 1e3:6.3f} ms   n={len(kept[name])}"
        )
    ratio = medians["statectl"] / medians["bare asyncua"]
    print(f"ratio statectl / bare: {ratio:.2f}x (target <= 1.3x)")
    return 0 if ratio <= 1.3 else 1


if __name__ == "__main__":
    raise SystemExit(main())
