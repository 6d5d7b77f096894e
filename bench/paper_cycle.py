"""ns/event of the paper's whole Motor cycle through ``Subject.dispatch`` (guard included).

The cycle is the paper's: Movement, Movement completion, Initialization (guarded by
``previous == 'Moving'``), Initialization completion, Movement, Error, Error
completion. Seven events, three of them notifying; no observer attached, nobody
listening (the bare row of ``bench/dispatch.py``). The median of several rounds is
reported, with the same figure for the cycle without Initialization in the same run
as the baseline the ratio is taken against.

Run: ``python bench/paper_cycle.py`` (``--src DIR`` measures another checkout's
``src``, e.g. the code before a change).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

PAPER = (
    "Movement",
    "Movement completion",
    "Initialization",
    "Initialization completion",
    "Movement",
    "Error",
    "Error completion",
)
UNGUARDED = ("Movement", "Movement completion", "Movement", "Error", "Error completion")
ROOT = Path(__file__).resolve().parents[1]


def ns_per_event(cycle: tuple[str, ...], events: int, rounds: int) -> float:
    from statectl.front.builder.build import load_chart
    from statectl.run.runtime import SimClock, Subject

    subject = Subject(load_chart(ROOT / "examples" / "motor" / "motor.yaml"), clock=SimClock())
    subject.start()
    dispatch = subject.dispatch
    loops = max(1, events // len(cycle))
    for name in cycle * 10:  # warm up: every plan is made
        dispatch(name)
    assert subject.configuration == {"Blocked"}
    times = []
    for _ in range(rounds):
        start = time.perf_counter_ns()
        for _ in range(loops):
            for name in cycle:
                dispatch(name)
        times.append((time.perf_counter_ns() - start) / (loops * len(cycle)))
    assert subject.events_processed == len(cycle) * (10 + loops * rounds)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--src", default=str(ROOT / "src"), help="the statectl src to measure")
    parser.add_argument("--events", type=int, default=70_000)
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args(argv)
    sys.path.insert(0, args.src)
    paper = ns_per_event(PAPER, args.events, args.rounds)
    bare = ns_per_event(UNGUARDED, args.events, args.rounds)
    print(f"src: {args.src}")
    print(f"paper cycle (with Initialization): {paper:8.0f} ns/event")
    print(f"cycle without Initialization:      {bare:8.0f} ns/event")
    print(f"ratio paper / without:             {paper / bare:8.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
