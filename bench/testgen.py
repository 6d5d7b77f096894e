"""Benchmark ``statectl testgen``: generating every criterion, and running what it wrote.

Usage: python bench/testgen.py [--states 50] [--no-run]

- A generated device with ``--states`` states in a ring: each handles ``next`` (to
  the next state), ``home`` (back to S0) and ``jog`` twice under exclusive guards over
  data (``mode == 1`` stays, ``mode == 2`` goes to the next state), so the search has
  data to try. Timed: generating each criterion (the ``pairs`` set is the largest),
  beside a 10-state baseline of the same shape in the same run.
- The shipped examples (Motor, gantry, pick-and-place's four devices): tests and
  events per criterion, time to generate, and (unless ``--no-run``) time to run the
  four modules of each with pytest on the simulated twin, in one subprocess per example.
- The pick-and-place cell: time to generate its links module (the search over the
  kernel's cell) and, unless ``--no-run``, to run it and the cell's Hypothesis module.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from statectl.out.testgen import CRITERIA, generate  # noqa: E402  # src/ first on the path
from statectl.out.testgen.cellgen import (  # noqa: E402
    generate_cell,
    generate_cell_hypothesis,
)

CELL = ROOT / "examples/pick-and-place/cell.yaml"

EXAMPLES = {
    "Motor": [ROOT / "examples/motor/motor.yaml"],
    "gantry": [ROOT / "examples/gantry/gantry.yaml"],
    "pick-and-place": [
        ROOT / f"examples/pick-and-place/{n}.yaml" for n in ("arm", "conveyor", "gripper", "sensor")
    ],
}


PLUGIN = ("-p", "statectl.out.testgen.plugin", "-p", "no:cacheprovider")


def ring(states: int) -> str:
    out = ["device: Ring", "data:", "  mode: 0", "states:"]
    for s in range(states):
        out.append(f"  - state: S{s}")
        out.append("    control: default" if s == 0 else "    control: event trigger required")
    out.append("events:")
    for s in range(states):
        nxt = (s + 1) % states
        out += [
            f"  - {{event: next, old: S{s}, new: S{nxt}}}",
            f"  - {{event: home, old: S{s}, new: S0}}",
            f"  - {{event: jog, guard: mode == 1, old: S{s}, new: S{s}}}",
            f"  - {{event: jog, guard: mode == 2, old: S{s}, new: S{nxt}}}",
        ]
    return "\n".join(out) + "\n"


def timed(file: Path, criterion: str, out: Path) -> tuple[float, int, int]:
    start = time.perf_counter()
    made = generate(file, criterion, out)
    return time.perf_counter() - start, made.tests, made.steps


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--states", type=int, default=50)
    p.add_argument("--no-run", action="store_true")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        print(f"ring of N states (next, home, jog under two data guards), {sys.version.split()[0]}")
        print("| states | criterion | tests | events | seconds | vs 10 states |")
        print("|---:|---|---:|---:|---:|---:|")
        for criterion in CRITERIA:
            figures = []
            for n in (10, args.states):
                file = base / f"ring{n}.yaml"
                file.write_text(ring(n), encoding="utf-8")
                figures.append((n, *timed(file, criterion, base / f"out{n}")))
            t0 = figures[0][1]
            for n, t, tests, steps in figures:
                print(f"| {n} | {criterion} | {tests} | {steps} | {t:.3f} | {t / t0:.1f} |")
        print()
        print("| example | criterion | tests | events | generate s |")
        print("|---|---|---:|---:|---:|")
        env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
        runs = []
        for name, files in EXAMPLES.items():
            out = base / name
            for criterion in CRITERIA:
                t = tests = steps = 0
                for f in files:
                    dt, n, s = timed(f, criterion, out)
                    t, tests, steps = t + dt, tests + n, steps + s
                print(f"| {name} | {criterion} | {tests} | {steps} | {t:.3f} |")
            if not args.no_run:
                start = time.perf_counter()
                result = subprocess.run(
                    [sys.executable, "-m", "pytest", "-q", *PLUGIN, str(out)],
                    cwd=out,
                    env=env,
                    capture_output=True,
                    text=True,
                )
                last = result.stdout.strip().splitlines()[-1]
                runs.append((name, time.perf_counter() - start, last))
        start = time.perf_counter()
        cell_out = base / "cell"
        made = generate_cell(CELL, "rows", cell_out)
        t_cell = time.perf_counter() - start
        for f in made.devices:
            f.path.unlink()
        generate_cell_hypothesis(CELL, cell_out)
        print()
        print(f"pick-and-place cell: {len(made.cases)} link tests, generated in {t_cell:.2f} s")
        if not args.no_run:
            start = time.perf_counter()
            result = subprocess.run(
                [sys.executable, "-m", "pytest", "-q", *PLUGIN, str(cell_out)],
                cwd=cell_out,
                env=env,
                capture_output=True,
                text=True,
            )
            last = result.stdout.strip().splitlines()[-1]
            took = time.perf_counter() - start
            runs.append(("pick-and-place cell (links + Hypothesis)", took, last))
        if runs:
            print()
            print("| example | pytest on the twin, all four criteria (s, with start-up) | result |")
            print("|---|---:|---|")
            for name, t, last in runs:
                print(f"| {name} | {t:.2f} | {last} |")


if __name__ == "__main__":
    main()
