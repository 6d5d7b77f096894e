"""Benchmark codegen and testgen on big sparse charts: time and output size against N.

Usage: python bench/codegen_scale.py [--sizes 300,1000,3000]

The chart is a flat ring of N states S0..S(N-1) (S0 the default) and N events, E{i}
from S{i} to S{i+1 mod N}: N*N (configuration, event) cells of which about N are
handled, the shape of a big generated chart. Per N, each in a fresh interpreter
(``python -m statectl``, as a user runs it): ``check`` (the baseline: reading the
tables), ``codegen --out`` and ``testgen --out``, with wall time, the ratio to
``check`` in the same run, and the bytes written. Run on demand; docs/codegen.md and
docs/testing.md quote the figures.
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


def ring(n: int) -> str:
    lines = ["device: Big", "states:"]
    for i in range(n):
        lines.append(f"  - state: S{i}")
        if i == 0:
            lines.append("    control: default")
    lines.append("events:")
    for i in range(n):
        lines += [f"  - event: E{i}", f"    old: S{i}", f"    new: S{(i + 1) % n}"]
    return "\n".join(lines) + "\n"


def timed(args: list[str]) -> float:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "statectl", *args],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    seconds = time.perf_counter() - start
    if done.returncode not in (0,):
        raise SystemExit(f"statectl {' '.join(args)} failed:\n{done.stderr[-2000:]}")
    return seconds


def size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="300,1000,3000")
    opts = parser.parse_args()
    sizes = [int(s) for s in opts.sizes.split(",")]
    print(
        "| N | check s | codegen s (x check) | header bytes | testgen s (x check) | module bytes |"
    )
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            work = Path(tmp) / f"n{n}"
            work.mkdir()
            tables = work / "big.yaml"
            tables.write_text(ring(n), encoding="utf-8")
            check = timed(["check", str(tables)])
            codegen = timed(["codegen", str(tables), "--out", str(work / "cg")])
            testgen = timed(["testgen", str(tables), "--out", str(work / "tg")])
            header = (work / "cg" / "big.hpp").stat().st_size
            print(
                f"| {n} | {check:.2f} | {codegen:.2f} ({codegen / check:.1f}x) | {header:,} "
                f"| {testgen:.2f} ({testgen / check:.1f}x) | {size(work / 'tg'):,} |"
            )


if __name__ == "__main__":
    main()
