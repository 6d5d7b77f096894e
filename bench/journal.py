"""Journal benchmarks (not tests): durable events/s, recovery time, added latency.

Run: ``python bench/journal.py [--events N] [--recover N]``. Targets (issue 6):
>= 50,000 durable events/s with group commit at synchronous=NORMAL; <= 2 s to
recover a journal of 1 million events; post -> observer latency with the journal
<= 2x without, for each guarantee (``prompt``, the default, and ``durable-first``).
Every number printed is measured here; nothing is extrapolated.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

from statectl.demo import motor_chart
from statectl.journal import Guarantee, Journal, StepKind, Sync
from statectl.observers import Notification
from statectl.runner import DeviceSetup, System
from statectl.runtime import SimClock, WallClock
from statectl.semantics import Snapshot


def durable_rate(directory: Path, n: int, sync: Sync) -> tuple[float, int]:
    """Accept ``n`` events as fast as one thread can and wait until the last is durable."""
    journal = Journal(directory / f"rate-{sync.value}.db", sync=sync)
    data = {"amount": 1}
    start = time.perf_counter()
    ticket = None
    for _ in range(n):
        ticket = journal.accept("Motor", "Movement", data)
    assert ticket is not None
    ticket.wait()
    elapsed = time.perf_counter() - start
    commits = journal.commits
    journal.close()
    return n / elapsed, commits


def recovery_time(directory: Path, n: int) -> tuple[float, float]:
    """Journal ``n`` accepted events with their steps, then time a full resume.

    The rows are written through :class:`Journal` as a run writes them (inbox row,
    then the step with its snapshot) without running the chart for each, so the
    fill is quick; the resume is the real one.
    """
    path = directory / "recover.db"
    chart = motor_chart()
    first = System((DeviceSetup("Motor", chart),), SimClock(), Journal(path))
    first.start()
    journal = first.journal
    assert journal is not None
    moving = Snapshot(frozenset({"Moving"}), (), "Blocked")
    blocked = Snapshot(frozenset({"Blocked"}), (), "Moving")
    started = time.perf_counter()
    for i in range(n):
        event, snapshot = ("Movement", moving) if i % 2 == 0 else ("Movement completion", blocked)
        seq = journal.accept("Motor", event).seq
        journal.record("Motor", StepKind.EVENT, snapshot, time_=i * 0.5, event=event,
                       inbox=seq, outcome="handled")  # fmt: skip
        if i % 100_000 == 0:
            journal.flush()
    first.close()
    fill = time.perf_counter() - started
    started = time.perf_counter()
    again = System((DeviceSetup("Motor", chart),), SimClock(), Journal(path))
    again.start(resume=True)
    resumed = time.perf_counter() - started
    expected = moving if n % 2 else blocked
    assert again.subjects["Motor"].snapshot == expected
    again.close()
    return resumed, fill


class Stamp:
    """An observer that notes when it was called and wakes the waiting poster."""

    def __init__(self) -> None:
        self.at = 0.0
        self.done = threading.Event()

    def update(self, notification: Notification) -> None:
        self.at = time.perf_counter()
        self.done.set()


def latency(directory: Path, n: int, guarantee: Guarantee | None) -> float:
    """Median seconds from ``System.post`` to the observer call, one event at a time.

    Every run is the same runtime with the same threads: a :class:`System` on a
    wall clock whose owner loop (:meth:`System.serve`) runs on its own thread, and a
    poster (this thread); ``guarantee`` None runs without a journal. Under
    ``prompt`` the post queues the inbox row and wakes the owner, as without a
    journal; under ``durable-first`` the event passes the writer, which commits it
    and, the owner being idle, processes it in the same wake-up.
    """
    chart = motor_chart()
    stamp = Stamp()
    journal = None
    if guarantee is not None:
        journal = Journal(directory / f"latency-{guarantee.value}.db", guarantee=guarantee)
    system = System((DeviceSetup("Motor", chart),), WallClock(), journal)
    system.subjects["Motor"].attach(stamp)
    system.start()
    halt = threading.Event()
    owner = threading.Thread(target=system.serve, args=(halt,), daemon=True)
    owner.start()
    samples = []
    for _ in range(n):
        for event in ("Movement", "Error"):  # each notifies: Movement(), then Error()
            stamp.done.clear()
            t0 = time.perf_counter()
            system.post("Motor", event)
            stamp.done.wait(5)
            samples.append(stamp.at - t0)
        system.post("Motor", "Error completion")  # back to Blocked, no observer call
        time.sleep(0.001)
    halt.set()
    owner.join()
    system.close()
    return statistics.median(samples)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--events", type=int, default=300_000)
    parser.add_argument("--recover", type=int, default=1_000_000)
    parser.add_argument("--latency", type=int, default=2_000)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for sync in (Sync.NORMAL, Sync.FULL):
            rate, commits = durable_rate(d, args.events, sync)
            verdict = (
                ""
                if sync is Sync.FULL
                else ("  (target >= 50,000: " + ("met" if rate >= 50_000 else "MISSED") + ")")
            )
            print(
                f"durable events/s, synchronous={sync.value.upper():6}: {rate:>10,.0f} "
                f"({args.events:,} events in {commits} commits){verdict}"
            )
        resumed, fill = recovery_time(d, args.recover)
        print(
            f"recover a journal of {args.recover:,} events: {resumed:.3f} s "
            f"(target <= 2 s: {'met' if resumed <= 2 else 'MISSED'}; "
            f"writing it took {fill:.1f} s)"
        )
        off = latency(d, args.latency, None)
        print(f"post -> observer call, median, journal off: {off * 1e6:.0f} us")
        for guarantee in Guarantee:
            on = latency(d, args.latency, guarantee)
            print(
                f"post -> observer call, median, journal on, {guarantee.value:13}: "
                f"{on * 1e6:.0f} us = {on / off:.2f}x off (target <= 2x: "
                f"{'met' if on <= 2 * off else 'MISSED'})"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
