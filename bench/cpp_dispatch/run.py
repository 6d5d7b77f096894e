"""Build and run the dispatch benchmark: generated Motor vs a hand-written switch.

Usage: python bench/cpp_dispatch/run.py [--cxx g++] [--runs 3]

Generates the Motor from examples/motor/motor.yaml with statectl's own codegen into a
temporary directory, builds bench.cpp with ``-O2``, runs it ``--runs`` times (each run
times both implementations, alternating, after warm-up) and prints one table:
per-dispatch p50/p99/max in ns (median over runs), sizeof the device, the binary size
and the code size of each implementation's inlined dispatch loop.
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
FLAGS = ["-std=c++17", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Werror",
         "-fno-exceptions", "-fno-rtti"]
LINE = re.compile(r"^(\w+) p50=([\d.]+) p99=([\d.]+) max=([\d.]+)")
SIZES = re.compile(r"^sizeof generated=(\d+) handwritten=(\d+)")


def _symbol_sizes(binary: Path) -> dict[str, int]:
    """Sizes of the two batch loops (each inlines one implementation's dispatch)."""
    try:
        out = subprocess.run(["nm", "-C", "-S", str(binary)], capture_output=True, text=True,
                             check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return {}
    sizes: dict[str, int] = {}
    for line in out.splitlines():
        parts = line.split(maxsplit=3)
        if len(parts) == 4 and "batch<" in parts[3]:
            key = "handwritten" if "hand::" in parts[3] else "generated"
            sizes[key] = sizes.get(key, 0) + int(parts[1], 16)
    return sizes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cxx", default="g++")
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT / "src"))
    from statectl.build import load_chart
    from statectl.codegen import generate

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        written, diags = generate(load_chart(ROOT / "examples" / "motor" / "motor.yaml"), out)
        if not written:
            print("\n".join(str(d) for d in diags), file=sys.stderr)
            return 1
        binary = out / "bench"
        subprocess.run([args.cxx, *FLAGS, "-I", str(out), str(HERE / "bench.cpp"), "-o",
                        str(binary)], check=True)
        rows: dict[str, list[tuple[float, float, float]]] = {"generated": [], "handwritten": []}
        sizeof: tuple[int, int] = (0, 0)
        for _ in range(args.runs):
            text = subprocess.run([str(binary)], capture_output=True, text=True,
                                  check=True).stdout
            for line in text.splitlines():
                if m := LINE.match(line):
                    rows[m[1]].append((float(m[2]), float(m[3]), float(m[4])))
                elif m := SIZES.match(line):
                    sizeof = (int(m[1]), int(m[2]))
        code = _symbol_sizes(binary)
        size = binary.stat().st_size
    print(f"{'implementation':<14} {'p50 ns':>8} {'p99 ns':>8} {'max ns':>9} {'sizeof':>7} "
          f"{'loop code B':>12}")
    for i, (name, samples) in enumerate(rows.items()):
        p50 = statistics.median(s[0] for s in samples)
        p99 = statistics.median(s[1] for s in samples)
        mx = max(s[2] for s in samples)
        print(f"{name:<14} {p50:>8.2f} {p99:>8.2f} {mx:>9.1f} {sizeof[i]:>7} "
              f"{code.get(name, 0):>12}")
    gen = statistics.median(s[0] for s in rows["generated"])
    hand = statistics.median(s[0] for s in rows["handwritten"])
    print(f"ratio p50 generated/handwritten: {gen / hand:.2f}; binary {size} bytes "
          f"({args.cxx} -O2, {args.runs} runs x 5 repeats x 2000 batches of 1024 dispatches)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
