"""Instructions per event of bench/dispatch.py's paper-cycle rows, counted by valgrind.

Rules:
1. A row's cycle runs N times and 2N times, each in a fresh interpreter under
   ``valgrind --tool=callgrind`` after the same warm-up; the difference of the two
   totals over 8N events is the row's instructions per event. Start-up, imports and
   warm-up cancel out, and the machine's load changes nothing: the figures compare
   runs made at different times, where timed rows on a shared machine cannot.
2. The rows are ``bench/dispatch.py``'s own wirings (``statectl_paper``), the paper's
   whole eight-event cycle each, so the two scripts measure the same thing; each is
   also given as a ratio to ``bare``, and the best row is said beside the worst (by
   default the demo wiring with a step listener, the clock moving).
3. valgrind is a Debian package (``apt-get install valgrind``); without it the script
   says so and exits 2.

Run: ``python bench/instructions.py`` (``--rows bare,by-hand,steps-read``, ``--cycles N``).
A run takes about a minute a row (valgrind runs Python some 50 times slower).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: The rows of bench/dispatch.py that dispatch the cycle without a moving clock, and the
#: demo wirings (their clock moves the same in every run, so they count as well).
ROWS = ("bare", "by-hand", "steps", "steps-read", "records", "demo", "demo-steps")
VALGRIND = ("valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null")
#: Run in the child: warm the row up, then fire its cycle N times.
CHILD = """
import sys
sys.argv = ["dispatch"]
sys.path.insert(0, {here!r})
import dispatch
fire, _, _ = dispatch.statectl_paper({row!r})()
for _ in range(200):
    fire()
for _ in range({cycles}):
    fire()
"""


def count(row: str, cycles: int) -> int:
    """The instructions a fresh interpreter runs to warm ``row`` up and fire it ``cycles``
    times (rule 1)."""
    code = CHILD.format(here=str(HERE), row=row, cycles=cycles)
    done = subprocess.run(
        [*VALGRIND, sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONHASHSEED": "0"},  # both runs hash alike
        check=False,
    )
    found = re.search(r"Collected : (\d+)", done.stderr)
    if done.returncode != 0 or found is None:
        raise SystemExit(f"instructions: row {row!r} failed under valgrind:\n{done.stderr[-2000:]}")
    return int(found.group(1))


def per_event(row: str, cycles: int) -> float:
    """Rule 1: instructions per event of ``row``."""
    events = 8 * cycles
    return (count(row, 2 * cycles) - count(row, cycles)) / events


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", default=",".join(ROWS), help=f"comma-separated of {ROWS}")
    parser.add_argument("--cycles", type=int, default=300, help="N of rule 1 (default 300)")
    args = parser.parse_args(argv)
    rows = [r for r in args.rows.split(",") if r]
    unknown = [r for r in rows if r not in ROWS]
    if unknown or args.cycles < 1:
        print(f"instructions: unknown rows {unknown} (rows: {', '.join(ROWS)}), or --cycles < 1")
        return 2
    if shutil.which("valgrind") is None:
        print("instructions: valgrind is not installed (apt-get install valgrind)")
        return 2
    rows = ["bare", *(r for r in rows if r != "bare")]  # the ratios' base, counted first
    print(f"python {sys.version.split()[0]}, {args.cycles} and {2 * args.cycles} cycles a row")
    print("| row (paper cycle) | instructions/event | / bare |")
    print("|---|---:|---:|")
    counted: dict[str, float] = {}
    for row in rows:
        n = counted[row] = per_event(row, args.cycles)
        print(f"| {row} | {n:,.0f} | {n / counted['bare']:.2f} |", flush=True)
    best, worst = min(counted, key=counted.__getitem__), max(counted, key=counted.__getitem__)
    print(f"best: {best} {counted[best]:,.0f}; worst: {worst} {counted[worst]:,.0f} an event")
    return 0


if __name__ == "__main__":
    sys.exit(main())
