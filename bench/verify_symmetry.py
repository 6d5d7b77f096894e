"""Benchmark symmetry reduction: a line of N identical stations under one supervisor.

Usage: python bench/verify_symmetry.py [--stations 12] [--no-symmetry] [--max-states N]
       [--keep DIR]

The supervisor's Start sends Begin to every station; a station that jams (a fault in
its monitored Busy state) halts the supervisor, whose Halted state sends Stop to every
station. Stations finish (Begin completion) and are reset from outside. The stations
are interchangeable, so ``statectl verify`` stores one global state per orbit; with
``--no-symmetry`` it stores every permutation (4**N * 3 and more: keep N small).
Prints states stored, the full search's state count, time and peak RSS.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

from statectl.cell.explore import explore
from statectl.cell.model import load_cell

SUPERVISOR = """\
device: Supervisor
states:
  - {state: Idle, control: default, ignore: [Halt, Finish, Clear]}
  - {state: Running, control: event trigger required, ignore: [Start, Clear]}
  - {state: Halted, control: event trigger required, ignore: [Start, Halt, Finish]}
events:
  - {event: Start, old: Idle, new: Running, kind: command, api: Go}
  - {event: Finish, old: Running, new: Idle, kind: command, api: Go}
  - {event: Halt, old: Running, new: Halted, kind: command, api: Go}
  - {event: Clear, old: Halted, new: Idle, kind: command, api: Go}
"""

STATION = """\
device: Station
states:
  - {state: Idle, control: default, ignore: [Stop, Reset, Begin completion, Jam]}
  - {state: Busy, control: [event trigger required, monitoring required], ignore: [Begin, Reset]}
  - {state: Done, control: event trigger required, ignore: [Begin, Stop, Begin completion, Jam]}
  - {state: Faulted, control: event trigger required, ignore: [Begin, Stop, Begin completion, Jam]}
events:
  - {event: Begin, old: Idle, new: Busy, kind: command, api: Work}
  - {event: Begin completion, old: Busy, new: Done, kind: completion, api: Work}
  - {event: Reset, old: Done, new: Idle, kind: command, api: Clear}
  - {event: Reset, old: Faulted, new: Idle, kind: command, api: Clear}
  - {event: Jam, old: Busy, new: Faulted, kind: fault, api: Clear}
  - {event: Stop, old: Busy, new: Idle, kind: command, api: Clear}
"""


def make_cell(folder: Path, n: int) -> Path:
    """Write the device files and a cell of ``n`` stations; return the cell's path."""
    (folder / "supervisor.yaml").write_text(SUPERVISOR, encoding="utf-8")
    (folder / "station.yaml").write_text(STATION, encoding="utf-8")
    names = [f"s{i}" for i in range(n)]
    lines = [f"cell: line-{n}", "devices:", "  sup: supervisor.yaml"]
    lines += [f"  {s}: station.yaml" for s in names]
    lines.append("links:")
    for s in names:
        lines.append(f"  - {{from: sup, enters: Running, to: {s}, send: Begin}}")
        lines.append(f"  - {{from: sup, enters: Halted, to: {s}, send: Stop}}")
        lines.append(
            f"  - {{from: {s}, enters: Faulted, to: sup, send: Halt, ignore_if_unhandled: true}}"
        )
    lines.append("environment:")
    for e in ("Start", "Finish", "Clear"):
        lines.append(f"  - {{send: {e}, to: sup}}")
    for s in names:
        lines.append(f"  - {{send: Reset, to: {s}}}")
        lines.append(f"  - {{fault: Jam, to: {s}}}")
    busy = " or ".join(f"In('{s}.Busy')" for s in names)
    lines.append("invariants:")
    lines.append("  - name: halted-means-stopped")
    lines.append(f"    holds: \"not (In('sup.Halted') and ({busy}))\"")
    path = folder / f"line-{n}.cell.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stations", type=int, default=12)
    ap.add_argument("--no-symmetry", action="store_true")
    ap.add_argument("--max-states", type=int, default=None)
    ap.add_argument("--keep", type=Path, default=None, help="write the cell files here")
    args = ap.parse_args(argv)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="statectl-bench-sym-"))
    folder.mkdir(parents=True, exist_ok=True)
    cell, diags = load_cell(make_cell(folder, args.stations))
    if cell is None:
        for d in diags:
            print(d, file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    report = explore(cell, max_states=args.max_states, symmetry=not args.no_symmetry)
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    full = f"{report.full_states:,}" if report.full_states is not None else "the same"
    print(
        f"statectl: {args.stations} stations, {report.states:,} states stored "
        f"(full search: {full}), {report.transitions:,} transitions, {seconds:.2f} s, "
        f"peak RSS {peak:,.0f} MiB, verdict {report.verdict}, "
        f"reductions: {'; '.join(report.reductions) or 'none'}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
