"""Benchmark ``statectl verify`` against SPIN on generated cells of N devices.

Usage: python bench/verify.py [--devices 10] [--independent] [--no-por] [--no-spin]
                               [--max-states N] [--keep DIR]

Each generated device is a station: Idle -> Busy (Begin, a command) -> Done (Begin
completion) -> Idle (Reset); a Jam in the monitored Busy state makes it Faulted
until Reset. Station i entering Faulted sends Hold to station i+1, which takes Busy
back to Idle and ignores it elsewhere. With 10 stations the cell has about a million
reachable global states. The same composed model is exported to Promela and checked
by SPIN in the same run (breadth-first, safety only), so the times are comparable.
``--independent`` drops the links: N stations that do not interact at all. Both
tools use their reductions (SPIN's partial-order reduction is its default) unless
``--no-por``, which turns them off in both (``statectl verify --no-por --no-symmetry``:
identical stations without links would otherwise be reduced by symmetry; pan built
with ``-DNOREDUCE``): the full searches, the worst row.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from statectl.cell.explore import Composed, explore, export_promela
from statectl.cell.model import load_cell
from statectl.channels.cli.progress import ProgressPrinter

STATION = """\
device: Station
states:
  - {state: Idle, control: default, ignore: [Hold, Reset, Begin completion, Jam]}
  - {state: Busy, control: [event trigger required, monitoring required], ignore: [Begin, Reset]}
  - {state: Done, control: event trigger required, ignore: [Begin, Hold, Begin completion, Jam]}
  - {state: Faulted, control: event trigger required, ignore: [Begin, Hold, Begin completion, Jam]}
events:
  - {event: Begin, old: Idle, new: Busy, kind: command, api: Work}
  - {event: Begin completion, old: Busy, new: Done, kind: completion, api: Work}
  - {event: Reset, old: Done, new: Idle, kind: command, api: Clear}
  - {event: Reset, old: Faulted, new: Idle, kind: command, api: Clear}
  - {event: Jam, old: Busy, new: Faulted, kind: fault, api: Clear}
  - {event: Hold, old: Busy, new: Idle, kind: command, api: Clear}
"""


def make_cell(folder: Path, n: int, *, links: bool = True) -> Path:
    """Write the station file and a cell of ``n`` stations; return the cell's path.

    Without ``links`` the stations do not interact at all (the non-interacting row)."""
    (folder / "station.yaml").write_text(STATION, encoding="utf-8")
    lines = [f"cell: stations-{n}", "devices:"]
    lines += [f"  s{i}: station.yaml" for i in range(n)]
    if links:
        lines.append("links:")
    for i in range(n - 1 if links else 0):
        lines.append(f"  - {{from: s{i}, enters: Faulted, to: s{i + 1}, send: Hold}}")
    lines.append("environment:")
    for i in range(n):
        lines.append(f"  - {{send: Begin, to: s{i}}}")
        lines.append(f"  - {{send: Reset, to: s{i}}}")
        lines.append(f"  - {{fault: Jam, to: s{i}}}")
    lines.append("invariants:")
    lines.append("  - name: one-state-each")
    lines.append("    holds: \"not (In('s0.Idle') and In('s0.Busy'))\"")
    path = folder / f"stations-{n}.cell.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _unfinished(returncode: int, output: str, stored: int) -> str:
    """Why pan's search did not run to its end, or "" when it did.

    A search cut short by its memory bound or a hash table that filled up counts
    fewer states than there are, so its time would flatter SPIN: such a run is an
    error of the benchmark, never a figure.
    """
    if returncode != 0:
        return f"pan exited {returncode}"
    for sign in ("out of memory", "MEMLIM", "search not completed", "max search depth too small"):
        if sign.lower() in output.lower():
            return f"pan says {sign!r}"
    if stored == 0:
        return "pan reported no stored states"
    return ""


def run_spin(pml: Path, max_states: int, *, reduce: bool = True) -> dict[str, float | int | str]:
    """spin -a, gcc and pan (BFS, safety; its partial-order reduction unless not
    ``reduce``); wall times and pan's state count."""
    if shutil.which("spin") is None or shutil.which("gcc") is None:
        return {"skipped": "spin or gcc not installed"}
    folder = pml.parent
    t0 = time.perf_counter()
    subprocess.run(["spin", "-a", pml.name], cwd=folder, check=True, capture_output=True)
    t1 = time.perf_counter()
    memlim = 2048
    subprocess.run(
        [
            "gcc",
            "-O2",
            "-DBFS",
            "-DSAFETY",
            *(() if reduce else ("-DNOREDUCE",)),
            f"-DMEMLIM={memlim}",
            "-o",
            "pan",
            "pan.c",
        ],
        cwd=folder,
        check=True,
        capture_output=True,
    )
    t2 = time.perf_counter()
    pan = subprocess.run(["./pan", "-E", "-w24"], cwd=folder, capture_output=True, text=True)
    t3 = time.perf_counter()
    stored = 0
    memory = ""
    for line in pan.stdout.splitlines():
        if "states, stored" in line and "nominal" not in line:
            stored = int(float(line.split()[0]))
        if "total actual memory usage" in line:
            memory = line.split()[0]
    errors = "errors: 0" not in pan.stdout
    unfinished = _unfinished(pan.returncode, pan.stdout + pan.stderr, stored)
    if unfinished:
        return {"failed": unfinished, "pan_s": t3 - t2, "total_s": t3 - t0}
    return {
        "generate_s": t1 - t0,
        "compile_s": t2 - t1,
        "pan_s": t3 - t2,
        "total_s": t3 - t0,
        "stored": stored,
        "memory_mb": memory,
        "errors": int(errors),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", type=int, default=10)
    ap.add_argument("--max-states", type=int, default=None)
    ap.add_argument("--no-spin", action="store_true")
    ap.add_argument("--independent", action="store_true", help="stations without links")
    ap.add_argument("--no-por", action="store_true", help="no partial-order reduction")
    ap.add_argument("--keep", type=Path, default=None, help="write the cell and model here")
    args = ap.parse_args(argv)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="statectl-bench-"))
    folder.mkdir(parents=True, exist_ok=True)
    cell_path = make_cell(folder, args.devices, links=not args.independent)
    cell, diags = load_cell(cell_path)
    if cell is None:
        for d in diags:
            print(d, file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    model = Composed(cell)
    printer = ProgressPrinter(sys.stderr) if sys.stderr.isatty() else None
    reduce = not args.no_por  # --no-por: the full search (no symmetry either), as pan's NOREDUCE
    report = explore(
        cell, max_states=args.max_states, progress=printer, model=model, por=reduce, symmetry=reduce
    )
    if printer is not None:
        printer.done()
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"statectl: {args.devices} devices, {report.states:,} global states, "
        f"{report.transitions:,} transitions, {seconds:.1f} s, "
        f"{report.states / seconds:,.0f} states/s, peak RSS {peak:,.0f} MiB, "
        f"verdict {report.verdict}"
    )
    for line in report.reductions:
        print(f"statectl: {line}")
    if args.no_spin:
        return 0
    pml = folder / "cell.pml"
    pml.write_text(export_promela(model), encoding="utf-8")
    spin = run_spin(pml, report.states, reduce=not args.no_por)
    if "skipped" in spin:
        print(f"spin: skipped ({spin['skipped']})")
        return 0
    if "failed" in spin:
        print(
            f"spin: DID NOT FINISH ({spin['failed']}) after {float(spin['pan_s']):.1f} s: "
            "no comparison; raise --max-states or the memory bound",
            file=sys.stderr,
        )
        return 1
    if args.no_por:
        print(
            f"note: SPIN stored {int(spin['stored']):,} states, statectl found "
            f"{report.states:,} (the models count the same cell; a difference means one "
            "of them explored another space)"
        )
    else:
        print(
            f"note: with partial-order reduction SPIN stored {int(spin['stored']):,} states, "
            f"statectl {report.states:,} (each reduces in its own way; the verdicts must agree)"
        )
    print(
        f"spin:     {spin['stored']:,} states stored, search (pan) {spin['pan_s']:.1f} s, "
        f"total with spin -a and gcc {spin['total_s']:.1f} s, memory {spin['memory_mb']} MB, "
        f"errors {spin['errors']}, partial-order reduction {'off' if args.no_por else 'on'}"
    )
    print(
        f"ratio:    statectl / spin total = {seconds / float(spin['total_s']):.2f}, "
        f"statectl / pan only = {seconds / float(spin['pan_s']):.2f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
