"""What the dashboard costs a device's owner thread, and its loop, per step of the paper cycle.

The Motor is wired as ``statectl demo`` wires it (the simulated motor and its monitor)
and runs the paper's whole cycle through ``Subject.dispatch``; beside it, in the same
process and interleaved, the same Motor with a ``Dashboard`` listening (not serving:
its notes wait for a loop, so only the owner's side is timed). Rounds are timed by the
thread's CPU time, the collector off; the median is reported. Then the loop's side:
turning the notes kept into the page's JSON messages, per message.

Run: ``python bench/dashboard_owner.py`` (``--src DIR`` measures another checkout's
``src``, e.g. the code before a change).
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CYCLE = (
    ("Movement", {"amount": 10}),
    ("Movement completion", None),
    ("Initialization", None),
    ("Initialization completion", None),
    ("Movement", {"amount": 10}),
    ("Error", None),
    ("Error completion", None),
)


def motor(dashboard: bool) -> tuple[Any, Any]:
    """A started Motor wired as the demo, with a Dashboard on it or not."""
    from statectl.channels.web.server import Dashboard
    from statectl.front.builder.build import load_chart
    from statectl.run.devices import connect, make_driver
    from statectl.run.runtime import SimClock, Subject

    chart = load_chart(ROOT / "examples" / "motor" / "motor.yaml")
    subject = Subject(chart, clock=SimClock())
    connect(subject, make_driver("sim-motor", {}, chart=chart))
    board = Dashboard([subject]) if dashboard else None
    subject.start()
    return subject, board


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--src", default=str(ROOT / "src"), help="the statectl src to measure")
    parser.add_argument("--rounds", type=int, default=11)
    parser.add_argument("--cycles", type=int, default=300, help="paper cycles per round")
    args = parser.parse_args(argv)
    sys.path.insert(0, args.src)
    rows = {"demo wiring": motor(False), "demo wiring + dashboard": motor(True)}
    samples: dict[str, list[float]] = {name: [] for name in rows}
    gc.disable()
    for r in range(args.rounds + 2):  # the first two rounds warm up
        for name, (subject, _) in rows.items():
            dispatch = subject.dispatch
            t0 = time.thread_time_ns()
            for _ in range(args.cycles):
                for event, data in CYCLE:
                    dispatch(event, data)
            if r >= 2:
                samples[name].append((time.thread_time_ns() - t0) / (args.cycles * len(CYCLE)))
    gc.enable()
    print(f"src {args.src}; CPU time of the owner thread, median of {args.rounds} rounds")
    for name, got in samples.items():
        print(f"{name:26} {statistics.median(got):8,.0f} ns/event")
    board = rows["demo wiring + dashboard"][1]
    items = list(board._pending)
    t0 = time.thread_time_ns()
    messages = 0
    for item in items:  # the loop's side: each note becomes the page's JSON message(s)
        if isinstance(item, str):
            continue
        made = item.messages() if hasattr(item, "messages") else [item.message()]
        messages += len(made)
    per = (time.thread_time_ns() - t0) / max(1, messages)
    print(f"loop side: {per:,.0f} ns per message ({messages:,} messages of the last notes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
