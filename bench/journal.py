"""Journal benchmarks (not tests): durable events/s, recovery time, added latency.

Run: ``python bench/journal.py [--events N] [--recover N]``. Targets: >= 50,000
events/s through a journalled Motor end to end at synchronous=NORMAL (each event
accepted into the inbox, processed by the device, its step journalled, all of it
committed); <= 2 s to recover a journal of 1 million events; post -> observer
latency with the journal <= 2x without, for each guarantee (``prompt``, the
default, and ``durable-first``). Every number printed is measured here; nothing
is extrapolated.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

from statectl.channels.cli.demo import motor_chart
from statectl.front.observers import Notification
from statectl.kernel.semantics import Snapshot
from statectl.run.devices import make_driver
from statectl.run.journal import Guarantee, Journal, JournalReader, StepKind, Sync
from statectl.run.runtime import SimClock, WallClock
from statectl.run.system import DeviceSetup, System

#: The paper's whole cycle, the guarded Initialization included (seven events).
CYCLE = (
    ("Movement", {"amount": 1}),
    ("Movement completion", None),
    ("Initialization", None),
    ("Initialization completion", None),
    ("Movement", {"amount": 1}),
    ("Error", None),
    ("Error completion", None),
)


def durable_rate(directory: Path, n: int, sync: Sync) -> tuple[float, int, int]:
    """Events/s through a journalled Motor, end to end: accepted, processed, committed.

    The Motor is wired as ``statectl demo`` wires it (the simulated motor's API and its
    Moving monitor). One thread posts the paper cycle through :meth:`System.post`
    (inbox rows), the owner loop processes each event (a step row with its snapshot,
    the driver's API calls), and the clock stops when every event was processed and
    the journal has committed everything. Returns (events/s, commits, steps journalled).
    """
    journal = Journal(directory / f"rate-{sync.value}.db", sync=sync)
    chart = motor_chart()
    motor_driver = make_driver("sim-motor", {}, chart=chart)
    system = System((DeviceSetup("Motor", chart, driver=motor_driver),), SimClock(), journal)
    system.start()
    motor = system.subjects["Motor"]
    halt = threading.Event()
    owner = threading.Thread(target=system.serve, args=(halt,), kwargs={"paced": False})
    cycles = max(1, n // len(CYCLE))
    total = cycles * len(CYCLE)
    start = time.perf_counter()
    owner.start()
    for _ in range(cycles):
        for event, data in CYCLE:
            system.post("Motor", event, data)
    while motor.events_processed < total:
        time.sleep(0.0005)
    journal.flush()
    elapsed = time.perf_counter() - start
    halt.set()
    owner.join()
    commits = journal.commits
    system.close()
    with JournalReader(journal.path) as reader:
        steps = sum(1 for _ in reader.steps())
    return total / elapsed, commits, steps


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


class Rig:
    """One runtime to time: a System on a wall clock, its owner loop on its own thread.

    Every contender is the same runtime with the same threads; ``guarantee`` None
    runs without a journal. Under ``prompt`` the post queues the inbox row and wakes
    the owner, as without a journal; under ``durable-first`` the event passes the
    writer, which commits it and, the owner being idle, processes it in the same
    wake-up.
    """

    def __init__(self, directory: Path, guarantee: Guarantee | None) -> None:
        self.label = "off" if guarantee is None else guarantee.value
        journal = None
        if guarantee is not None:
            journal = Journal(directory / f"latency-{guarantee.value}.db", guarantee=guarantee)
        self.system = System((DeviceSetup("Motor", motor_chart()),), WallClock(), journal)
        self.stamp = Stamp()
        self.system.subjects["Motor"].attach(self.stamp)
        self.system.start()
        self.halt = threading.Event()
        self.owner = threading.Thread(target=self.system.serve, args=(self.halt,), daemon=True)
        self.owner.start()
        self.samples: list[float] = []

    def cycles(self, n: int) -> None:
        """``n`` Movement, Error, Error completion cycles: two timed posts each."""
        system, stamp, samples = self.system, self.stamp, self.samples
        for _ in range(n):
            for event in ("Movement", "Error"):  # each notifies: Movement(), then Error()
                stamp.done.clear()
                t0 = time.perf_counter()
                system.post("Motor", event)
                if not stamp.done.wait(5):
                    raise RuntimeError(f"{self.label}: no observer call for {event}")
                samples.append(stamp.at - t0)
            system.post("Motor", "Error completion")  # back to Blocked, no observer call
            time.sleep(0.001)

    def close(self) -> None:
        self.halt.set()
        self.owner.join()
        self.system.close()


def latency(directory: Path, n: int, rounds: int) -> dict[str, list[float]]:
    """Median seconds from ``System.post`` to the observer call per contender, per round.

    The contenders run interleaved (each round runs every one for ``n // rounds``
    cycles, in an order that rotates), so a change in the machine's load reaches all
    of them alike; the ratio of each round's medians is what the target is about.
    """
    rigs = [Rig(directory, None)] + [Rig(directory, g) for g in Guarantee]
    per = max(1, n // rounds)
    medians: dict[str, list[float]] = {rig.label: [] for rig in rigs}
    try:
        for rig in rigs:
            rig.cycles(max(1, per // 4))  # warm-up, not counted
            rig.samples.clear()
        for r in range(rounds):
            order = rigs[r % len(rigs) :] + rigs[: r % len(rigs)]
            for rig in order:
                rig.samples.clear()
                rig.cycles(per)
                medians[rig.label].append(statistics.median(rig.samples))
    finally:
        for rig in rigs:
            rig.close()
    return medians


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--events", type=int, default=300_000)
    parser.add_argument("--recover", type=int, default=1_000_000)
    parser.add_argument("--latency", type=int, default=3_000, help="timed cycles in all")
    parser.add_argument("--rounds", type=int, default=15)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for sync in (Sync.NORMAL, Sync.FULL):
            rate, commits, steps = durable_rate(d, args.events, sync)
            verdict = (
                ""
                if sync is Sync.FULL
                else ("  (target >= 50,000: " + ("met" if rate >= 50_000 else "MISSED") + ")")
            )
            print(
                "journalled Motor wired as the demo, paper cycle, end to end, "
                f"sync={sync.value.upper():6}: "
                f"{rate:>9,.0f} events/s ({steps:,} steps journalled, {commits} commits){verdict}"
            )
        resumed, fill = recovery_time(d, args.recover)
        print(
            f"recover a journal of {args.recover:,} events: {resumed:.3f} s "
            f"(target <= 2 s: {'met' if resumed <= 2 else 'MISSED'}; "
            f"writing it took {fill:.1f} s)"
        )
        medians = latency(d, args.latency, args.rounds)
        off = medians.pop("off")
        print(
            f"post -> observer call, journal off: {statistics.median(off) * 1e6:.0f} us "
            f"(median of {len(off)} interleaved rounds)"
        )
        for label, on in medians.items():
            ratios = sorted(a / b for a, b in zip(on, off, strict=True))
            ratio = statistics.median(ratios)
            print(
                f"post -> observer call, journal on, {label:13}: "
                f"{statistics.median(on) * 1e6:.0f} us = {ratio:.2f}x off "
                f"(rounds {ratios[0]:.2f}-{ratios[-1]:.2f}x; target <= 2x: "
                f"{'met' if ratio <= 2 else 'MISSED'})"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
