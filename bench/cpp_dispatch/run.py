"""Build and run the dispatch benchmark: generated Motor vs a hand-written switch.

Usage: python bench/cpp_dispatch/run.py [--cxx g++] [--runs 3] [--count 160000]

Generates the Motor from examples/motor/motor.yaml with statectl's own codegen into a
temporary directory, builds bench.cpp as a release build (``-O2 -DNDEBUG``; the generated
contract checks stay on, they do not depend on NDEBUG), runs it ``--runs`` times (each
run times both implementations, alternating, after warm-up) and prints one table:
per-dispatch p50/p99/max in ns (median of the runs' p50 and p99, largest max), sizeof
the device and the code size of each implementation's inlined dispatch loop.

Wall-clock figures on a shared machine move by tens of percent between runs, so when
valgrind is installed the script also counts instructions: ``bench --count N`` under
``valgrind --tool=callgrind --toggle-collect=<entry point>``, once per implementation,
gives the instructions per dispatch (the same loop and observer work included in both),
which repeat exactly from run to run.
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
FLAGS = [
    "-std=c++17",
    "-O2",
    "-DNDEBUG",
    "-Wall",
    "-Wextra",
    "-Wpedantic",
    "-Werror",
    "-fno-exceptions",
    "-fno-rtti",
]
LINE = re.compile(r"^(\w+) p50=([\d.]+) p99=([\d.]+) max=([\d.]+)")
SIZES = re.compile(r"^sizeof generated=(\d+) handwritten=(\d+)")
TOTALS = re.compile(r"^totals:\s*(\d+)", re.MULTILINE)
NAMES = ("generated", "handwritten")


def _instructions(binary: Path, count: int) -> dict[str, float]:
    """Instructions per dispatch of each implementation, counted by callgrind."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        return {}
    result: dict[str, float] = {}
    for name in NAMES:
        out = binary.parent / f"callgrind.{name}"
        subprocess.run(
            [
                valgrind,
                "--tool=callgrind",
                f"--callgrind-out-file={out}",
                f"--toggle-collect=*run_{name}*",
                str(binary),
                "--count",
                str(count),
            ],
            capture_output=True,
            text=True,
            check=True,
        )
        found = TOTALS.search(out.read_text())
        if found is None:
            return {}
        result[name] = int(found[1]) / count
    return result


def _symbol_sizes(binary: Path) -> dict[str, int]:
    """Sizes of the two batch loops (each inlines one implementation's dispatch)."""
    try:
        out = subprocess.run(
            ["nm", "-C", "-S", str(binary)], capture_output=True, text=True, check=True
        ).stdout
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
    parser.add_argument(
        "--count", type=int, default=160_000, help="dispatches per implementation under callgrind"
    )
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT / "src"))
    from statectl.front.builder.build import load_chart
    from statectl.out.codegen import generate

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        written, diags = generate(load_chart(ROOT / "examples" / "motor" / "motor.yaml"), out)
        if not written:
            print("\n".join(str(d) for d in diags), file=sys.stderr)
            return 1
        binary = out / "bench"
        subprocess.run(
            [args.cxx, *FLAGS, "-I", str(out), str(HERE / "bench.cpp"), "-o", str(binary)],
            check=True,
        )
        rows: dict[str, list[tuple[float, float, float]]] = {name: [] for name in NAMES}
        sizeof: tuple[int, int] = (0, 0)
        for _ in range(args.runs):
            text = subprocess.run([str(binary)], capture_output=True, text=True, check=True).stdout
            for line in text.splitlines():
                if m := LINE.match(line):
                    rows[m[1]].append((float(m[2]), float(m[3]), float(m[4])))
                elif m := SIZES.match(line):
                    sizeof = (int(m[1]), int(m[2]))
        code = _symbol_sizes(binary)
        size = binary.stat().st_size
        instructions = _instructions(binary, args.count)
    print(
        f"{'implementation':<14} {'p50 ns':>8} {'p99 ns':>8} {'max ns':>9} {'Ir/dispatch':>12} "
        f"{'sizeof':>7} {'loop code B':>12}"
    )
    for i, (name, samples) in enumerate(rows.items()):
        p50 = statistics.median(s[0] for s in samples)
        p99 = statistics.median(s[1] for s in samples)
        mx = max(s[2] for s in samples)
        ir = f"{instructions[name]:.2f}" if name in instructions else "-"
        print(
            f"{name:<14} {p50:>8.2f} {p99:>8.2f} {mx:>9.1f} {ir:>12} {sizeof[i]:>7} "
            f"{code.get(name, 0):>12}"
        )
    ratios = [g[0] / h[0] for g, h in zip(rows["generated"], rows["handwritten"], strict=True)]
    gen = statistics.median(s[0] for s in rows["generated"])
    hand = statistics.median(s[0] for s in rows["handwritten"])
    print(
        f"ratio p50 generated/handwritten: {gen / hand:.2f} (per run: "
        + ", ".join(f"{r:.2f}" for r in ratios)
        + ")"
    )
    if instructions:
        print(
            f"ratio instructions generated/handwritten: "
            f"{instructions['generated'] / instructions['handwritten']:.3f} "
            f"(callgrind, {args.count} dispatches each)"
        )
    else:
        print("instructions: valgrind not found, not counted")
    print(
        f"binary {size} bytes; {args.cxx} {' '.join(FLAGS[:3])}, contracts on; {args.runs} runs "
        "x 5 repeats x 2000 batches of 1024 dispatches"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
