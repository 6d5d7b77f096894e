"""What the safe expression language's bounds cost a guard, per evaluation.

Rules:
1. Each guard is compiled once by the loader's own compiler and evaluated with
   ``Expression.evaluate`` against a fixed environment, as the kernel does per step.
2. Python's own ``eval`` of the same text, with the same environment as locals and no
   builtins, is the baseline of every row, timed in the same run: the ratio is the
   bounds' cost (guarded calls for ``+``, ``*``, ``%`` and attribute reads).
3. Best of ``--repeat`` runs of ``--number`` evaluations each (``timeit``'s rule: the
   best run is the one least disturbed by other work on the machine).

Run: ``python bench/guards.py`` (``--number`` and ``--repeat`` to change the effort).
"""

from __future__ import annotations

import argparse
import sys
import timeit
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "src"))

from statectl.kernel.errors import Location
from statectl.kernel.expr.compiler import compile_expression

#: (guard, what it shows): the first has no bounded operation, the others do.
GUARDS = (
    ("previous == 'Moving' and speed > 2 and In('Moving')", "no bounded operation"),
    ("a + b * 2 > 10 and p.speed >= 2", "two arithmetic operations and an attribute read"),
    ("len(name % 3) > 0", "a formatting '%'"),
)

ENV: dict[str, Any] = {
    "previous": "Moving",
    "speed": 3,
    "In": lambda state: state == "Moving",
    "a": 4,
    "b": 5,
    "p": SimpleNamespace(speed=3),
    "name": "axis %d",
}

#: The baseline's globals: no builtins but the one function a guard above calls.
BARE: dict[str, Any] = {"__builtins__": {"len": len}}


def per_call(fn: Any, number: int, repeat: int) -> float:
    """Best of ``repeat`` runs of ``number`` calls, in microseconds per call."""
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--number", type=int, default=200_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    print(f"best of {args.repeat} x {args.number:,} evaluations")
    print("| guard | statectl us | Python eval us | ratio |")
    print("|---|---:|---:|---:|")
    for text, _ in GUARDS:
        expression, problems = compile_expression(text, Location())
        if expression is None:
            print(f"refused: {text}: {problems}", file=sys.stderr)
            return 1
        code = compile(text, "<guard>", "eval")

        def ours(e: Any = expression) -> Any:
            return e.evaluate(ENV)

        def python(c: Any = code) -> Any:
            return eval(c, BARE, dict(ENV))  # the baseline: the same text, unbounded

        if ours() != python():
            print(f"the two disagree on {text!r}", file=sys.stderr)
            return 1
        mine = per_call(ours, args.number, args.repeat)
        base = per_call(python, args.number, args.repeat)
        print(f"| `{text}` | {mine:.2f} | {base:.2f} | {mine / base:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
