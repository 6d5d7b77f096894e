"""Shipping benchmark (not a test): rows/s into one PostgreSQL, and commit-to-visible lag.

Run: ``python bench/ship.py [--rows N] [--rate R] [--seconds S] [--url URL]``.
Without ``--url`` it starts a throwaway PostgreSQL (tests/pgserver.py: Debian's
binaries as the postgres user on 127.0.0.1, fsync on as configured by default).

Targets (issue 13): >= 20,000 rows/s shipped in total from 4 controllers'
journals into one database, and a p99 lag <= 1 s from a row being written on a
controller to it being visible in PostgreSQL, under that load.

1. **Throughput**: 4 journals of ``--rows`` rows each (half accepted events,
   half steps) are shipped at once by 4 processes (one per controller, as
   ``statectl journal ship`` does); rows/s = all rows / (last end - first start).
2. **Lag**: 4 processes each run a journal written at ``--rate`` rows/s (events
   accepted and their steps recorded, group commit as in a run) with a
   :class:`ShipThread` woken by each commit, as a run with ``ship:`` does. The
   main process polls PostgreSQL every 10 ms; a row's lag is the time it was
   first seen minus its ``wall`` (taken when the row was queued, before the
   SQLite commit, so the figure includes the journal's own commit delay).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT / "src"), str(ROOT / "tests")]

import psycopg  # noqa: E402

import pgserver  # noqa: E402
from statectl.kernel.semantics import Snapshot  # noqa: E402
from statectl.run.journal import Journal, StepKind  # noqa: E402
from statectl.run.journal.ship import Shipper, ShipThread  # noqa: E402

IDLE = Snapshot(frozenset({"Idle"}), (), None)
BUSY = Snapshot(frozenset({"Busy"}), (), "Idle")


def write(journal: Journal, device: str, first: int, n: int) -> None:
    """``n`` events of one device: each accepted (inbox row) and processed (step row)."""
    for i in range(first, first + n):
        t = journal.accept(device, "Go", {"n": i})
        journal.record(device, StepKind.EVENT, BUSY if i % 2 else IDLE, time_=float(i),
                       event="Go", inbox=t.seq, outcome="handled")  # fmt: skip


def fill(path: Path, device: str, rows: int) -> None:
    j = Journal(path)
    j.register(device, device, "arm.yaml", None)
    j.record(device, StepKind.START, IDLE, time_=0.0)
    write(j, device, 0, rows // 2)
    j.flush()
    j.close()


def ship_worker(path: str, url: str, source: str, go: Any, out: Any) -> None:
    shipper = Shipper(path, url, source=source)
    shipper._postgres()  # connected and the schema checked before the clock starts
    go.wait()
    start = time.perf_counter()
    r = shipper.ship_all()
    out.put((start, time.perf_counter(), r.inbox + r.steps))
    shipper.close()


def throughput(url: str, rows: int, directory: Path) -> tuple[float, int]:
    paths = [directory / f"t{i}.db" for i in range(4)]
    for i, p in enumerate(paths):
        fill(p, f"Arm{i}", rows)
    go, out = mp.Event(), mp.Queue()
    procs = [
        mp.Process(target=ship_worker, args=(str(p), url, f"t{i}", go, out))
        for i, p in enumerate(paths)
    ]
    for p in procs:
        p.start()
    time.sleep(1.0)  # every worker connected
    go.set()
    results = [out.get(timeout=600) for _ in procs]
    for p in procs:
        p.join()
    total = sum(r[2] for r in results)
    span = max(r[1] for r in results) - min(r[0] for r in results)
    return total / span, total


def node(path: str, url: str, source: str, rate: float, seconds: float) -> None:
    """A controller: a journal written at ``rate`` rows/s, shipped as it commits."""
    device = source
    j = Journal(path)
    ship = ShipThread(Shipper(path, url, source=source), interval=0.5, report=print)
    j.after_commit(ship.wake)
    ship.start()
    j.register(device, device, "arm.yaml", None)
    j.record(device, StepKind.START, IDLE, time_=0.0)
    per_tick = max(1, round(rate / 2 / 100))  # events per 10 ms; each event is 2 rows
    start = time.perf_counter()
    i = 0
    while (now := time.perf_counter()) - start < seconds:
        due = int((now - start) * 100) * per_tick
        if i < due:
            write(j, device, i, due - i)
            i = due
        time.sleep(0.002)
    j.flush()
    ship.stop(drain=10)
    j.close()


def lag(url: str, rate: float, seconds: float, directory: Path) -> tuple[list[float], float]:
    procs = [
        mp.Process(target=node, args=(str(directory / f"l{i}.db"), url, f"l{i}", rate, seconds))
        for i in range(4)
    ]
    for p in procs:
        p.start()
    seen: dict[str, tuple[int, int]] = {}
    lags: list[float] = []
    with psycopg.connect(url, autocommit=True) as conn:
        end = time.time() + seconds + 15
        while time.time() < end and (any(p.is_alive() for p in procs) or not seen):
            try:
                marks = conn.execute(
                    "SELECT source, inbox_upto, steps_upto FROM statectl_sources "
                    "WHERE source LIKE 'l%'"
                ).fetchall()
            except psycopg.errors.UndefinedTable:
                time.sleep(0.01)
                continue
            now = time.time()
            for source, inbox_upto, steps_upto in marks:
                inbox_was, steps_was = seen.get(source, (0, 0))
                for table, key, was, upto in (
                    ("statectl_inbox", "seq", inbox_was, inbox_upto),
                    ("statectl_steps", "id", steps_was, steps_upto),
                ):
                    if upto > was:
                        walls = conn.execute(
                            f"SELECT wall FROM {table} WHERE source = %s AND {key} > %s "
                            f"AND {key} <= %s",
                            (source, was, upto),
                        ).fetchall()
                        lags.extend(now - w for (w,) in walls)
                seen[source] = (inbox_upto, steps_upto)
            time.sleep(0.01)
    for p in procs:
        p.join()
    return lags, sum(a + b for a, b in seen.values()) / seconds


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000, help="rows per journal (throughput)")
    ap.add_argument("--rate", type=float, default=5_000, help="rows/s per controller (lag)")
    ap.add_argument("--seconds", type=float, default=20, help="length of the lag run")
    ap.add_argument("--url", help="an existing database (default: start a throwaway server)")
    args = ap.parse_args()
    mp.set_start_method("fork")
    server = None
    url = args.url
    if url is None:
        why = pgserver.why_not()
        if why is not None:
            print(f"cannot start PostgreSQL: {why}")
            return 2
        server = pgserver.start(durable=True)
        assert server is not None
        url = server.url
    try:
        with tempfile.TemporaryDirectory() as tmp:
            rate, total = throughput(url, args.rows, Path(tmp))
            print(f"throughput: {total} rows from 4 journals in one database: {rate:,.0f} rows/s "
                  f"(target >= 20,000)")  # fmt: skip
            lags, shipped = lag(url, args.rate, args.seconds, Path(tmp))
            lags.sort()
            q = statistics.quantiles(lags, n=100)
            print(f"lag under load: 4 x {args.rate:,.0f} rows/s written for {args.seconds:g} s, "
                  f"{len(lags)} rows shipped ({shipped:,.0f} rows/s): p50 {q[49] * 1000:.0f} ms, "
                  f"p99 {q[98] * 1000:.0f} ms, max {lags[-1] * 1000:.0f} ms "
                  f"(target p99 <= 1000 ms)")  # fmt: skip
    finally:
        if server is not None:
            server.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
