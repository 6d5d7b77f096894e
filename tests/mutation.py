"""Mutation check of statectl testgen: mutants a controls engineer makes, per criterion.

Usage: python tests/mutation.py [FILE ...] [--criteria rows,pairs,...] [--no-hypothesis]

Each device file (default: the Motor, the Press, the Modbus clamp) is mutated the
ways a controls engineer gets it wrong, and every criterion's module, generated from
the right file, runs against each mutant in-process (the generated functions called
with the plugin's fixtures made here). A mutant is *killed* when a test of the
module fails.

- Mutated device files (the implementation runs the mutant tables on their twin):
  a guard over ``previous`` widened to another state, a conjunct dropped (``and`` /
  ``or`` operand), a comparison's boundary off by one (``<`` <-> ``<=``, a number
  +-1), a row's target changed, a row dropped, a fault turned into a command, a
  state's ``monitoring required`` dropped.
- Buggy drivers for the right tables (the SimTwin changed): never completes,
  completes late, an extra API call, a wrong argument (the last two in the twin's
  own API log, which the runtime adapter reads per notification).

A mutant of a device file is *equivalent* when the kernel cannot tell it from the
right file: the two charts stepped side by side over every event, with the data
either one's guards are tested with, never differ in states, invokes or reason.
Fault kinds and monitoring are not the kernel's (a monitor raises the fault), so
those mutants are never counted equivalent. docs/testing.md shows the scores.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib.util
import inspect
import io
import sys
import tempfile
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from statectl.front.builder.build import load_chart  # noqa: E402  # src/ first on the path
from statectl.front.tables import RecoveryRow  # noqa: E402
from statectl.front.tables import load as load_tables  # noqa: E402
from statectl.kernel.errors import StatectlError  # noqa: E402
from statectl.kernel.model import Chart, ControlKind, EventKind, StateKind  # noqa: E402
from statectl.kernel.semantics import compiled, initial, step  # noqa: E402
from statectl.out.testgen import DeviceUnderTest, generate  # noqa: E402
from statectl.out.testgen.generator import generate_hypothesis  # noqa: E402
from statectl.out.testgen.oracle import Specification  # noqa: E402
from statectl.out.testgen.paths import (  # noqa: E402
    candidate_data,
    candidate_event_data,
    leaves,
    notifies,
    sendable_events,
)
from statectl.run.devices import SimTwin  # noqa: E402

EXAMPLES = [
    ROOT / "examples/motor/motor.yaml",
    ROOT / "examples/press/press.yaml",
    ROOT / "examples/modbus/clamp.yaml",
]
CRITERIA = ("rows", "transitions", "states", "pairs", "hypothesis")
#: mutant kinds, in the order the table shows them; the last four are drivers
KINDS = (
    "previous widened",
    "conjunct dropped",
    "boundary off by one",
    "target changed",
    "row dropped",
    "fault as command",
    "monitoring dropped",
    "never completes",
    "completes late",
    "extra API call",
    "wrong argument",
)
#: kinds the kernel does not see: never counted equivalent
NOT_KERNEL = {"fault as command", "monitoring dropped"}


@dataclass(frozen=True)
class Mutant:
    kind: str
    name: str
    chart: Chart  # the tables the implementation runs
    driver: Callable[[Chart], Any] | None = None  # None: the twin of ``chart``


# -- mutants of the tables ---------------------------------------------------------------------


def _guard_variants(guard: str, states: list[str]) -> Iterator[tuple[str, str, str]]:
    """(kind, what changed, new guard) for one guard."""
    tree = ast.parse(guard, mode="eval")
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare) and len(node.ops) == 1:
            left, right = node.left, node.comparators[0]
            is_prev = isinstance(left, ast.Name) and left.id == "previous"
            if is_prev and isinstance(node.ops[0], ast.Eq) and isinstance(right, ast.Constant):
                for other in states:
                    if other != right.value:
                        wider = f"previous in ({right.value!r}, {other!r})"
                        yield "previous widened", f"also {other}", _swap(guard, node, wider)
            yield from _boundaries(guard, node)
        if isinstance(node, ast.BoolOp):
            for i, value in enumerate(node.values):
                rest = node.values[:i] + node.values[i + 1 :]
                kept = rest[0] if len(rest) == 1 else ast.BoolOp(node.op, rest)
                text = _swap(guard, node, ast.unparse(kept))
                yield "conjunct dropped", f"without {ast.unparse(value)!r}", text


_FLIP = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt}


def _boundaries(guard: str, node: ast.Compare) -> Iterator[tuple[str, str, str]]:
    flip = _FLIP.get(type(node.ops[0]))
    if flip is not None:
        other = ast.Compare(node.left, [flip()], node.comparators)
        yield "boundary off by one", ast.unparse(other), _swap(guard, node, ast.unparse(other))
    for side in (node.left, node.comparators[0]):
        if isinstance(side, ast.Constant) and type(side.value) in (int, float):
            for delta in (-1, 1):
                moved = ast.Constant(side.value + delta)
                parts = [moved if p is side else p for p in (node.left, node.comparators[0])]
                other = ast.Compare(parts[0], list(node.ops), [parts[1]])
                text = _swap(guard, node, ast.unparse(other))
                yield "boundary off by one", ast.unparse(other), text


def _swap(guard: str, node: ast.AST, text: str) -> str:
    """``guard`` with ``node`` replaced by ``text`` (parenthesised)."""
    tree = ast.parse(guard, mode="eval")
    where = (type(node), getattr(node, "col_offset", -1), getattr(node, "end_col_offset", -1))
    target = next(
        n
        for n in ast.walk(tree)
        if (type(n), getattr(n, "col_offset", -1), getattr(n, "end_col_offset", -1)) == where
    )

    class Swap(ast.NodeTransformer):
        def visit(self, n: ast.AST) -> Any:
            if n is target:
                return ast.parse(text, mode="eval").body
            return super().visit(n)

    return ast.unparse(Swap().visit(tree))


def table_mutants(chart: Chart) -> list[Mutant]:
    """The mutated device files of ``chart`` (the module docstring's first list)."""
    out: list[Mutant] = []
    leaves_ = [s.name for s in chart.states if s.kind is StateKind.ATOMIC]
    rows = chart.transitions
    for i, t in enumerate(rows):
        row = f"row {i + 1}"

        def with_row(new: Any, i: int = i) -> Chart:
            return replace(chart, transitions=(*rows[:i], *new, *rows[i + 1 :]))

        for kind, what, guard in _guard_variants(t.guard or "True", leaves_) if t.guard else ():
            out.append(Mutant(kind, f"{row}: {what}", with_row((replace(t, guard=guard),))))
        for x in leaves_:
            if (x,) != t.targets:
                out.append(
                    Mutant("target changed", f"{row} to {x}", with_row((replace(t, targets=(x,)),)))
                )
        out.append(Mutant("row dropped", row, with_row(())))
    for e in chart.events:
        if e.kind is EventKind.FAULT:
            events = tuple(
                replace(x, kind=EventKind.COMMAND) if x is e else x for x in chart.events
            )
            out.append(Mutant("fault as command", e.name, replace(chart, events=events)))
    for s in chart.states:
        if ControlKind.MONITORING in s.controls:
            changed = replace(s, controls=s.controls - {ControlKind.MONITORING})
            states = tuple(changed if x is s else x for x in chart.states)
            out.append(Mutant("monitoring dropped", s.name, replace(chart, states=states)))
    return out


# -- buggy drivers -----------------------------------------------------------------------------


class NeverCompletes(SimTwin):
    def report(self, event: str, data: Any = None) -> None:
        if not self.chart.event(event) or self.chart.event(event).kind is not EventKind.COMPLETION:
            super().report(event, data)


class ExtraCall(SimTwin):
    def log_call(self, function: str, *args: Any) -> None:
        super().log_call(function, *args)
        super().log_call("Extra")


class WrongArgument(SimTwin):
    def log_call(self, function: str, *args: Any) -> None:
        super().log_call(function, *args, -1)


def driver_mutants(chart: Chart) -> list[Mutant]:
    """The buggy drivers for the right tables (the module docstring's second list)."""
    return [
        Mutant("never completes", "SimTwin reporting no completion", chart, NeverCompletes),
        Mutant(
            "completes late", "SimTwin at 100x its delay", chart, lambda c: SimTwin(c, delay=100.0)
        ),
        Mutant("extra API call", "SimTwin calling Extra() too", chart, ExtraCall),
        Mutant("wrong argument", "SimTwin passing -1 too", chart, WrongArgument),
    ]


# -- equivalence: the two charts stepped side by side ------------------------------------------


def _seen(chart: Chart, s: Any) -> tuple[Any, ...]:
    return (
        leaves(chart, s.target),
        tuple((n.invoke, n.method) for n in notifies(s)),
        s.unhandled,
    )


def equivalent(spec: Chart, mutant: Mutant, bound: int = 5000) -> bool:
    """Whether the kernel cannot tell ``mutant`` from ``spec`` (module docstring)."""
    if mutant.kind in NOT_KERNEL or mutant.driver is not None:
        return False
    a, b = compiled(spec), compiled(mutant.chart)
    datas = {*candidate_data(spec, a), *candidate_data(mutant.chart, b)}
    sent: dict[str, list[Any]] = {}
    for table in (candidate_event_data(spec), candidate_event_data(mutant.chart)):
        for event, values in table.items():
            sent.setdefault(event, [])
            sent[event] += [v for v in values if v not in sent[event]]
    events = sendable_events(spec)
    for data in datas:
        values = dict(data)
        x, y = initial(a, values), initial(b, values)
        if _seen(spec, x) != _seen(spec, y):
            return False
        seen = {(x.target, y.target)}
        queue = deque(seen)
        while queue and len(seen) < bound:
            sa, sb = queue.popleft()
            for event in events:
                for d in sent.get(event, [None]):
                    p, q = step(a, sa, event, values, d), step(b, sb, event, values, d)
                    if _seen(spec, p) != _seen(spec, q):
                        return False
                    if (p.target, q.target) not in seen:
                        seen.add((p.target, q.target))
                        queue.append((p.target, q.target))
    return True


# -- running a generated module in-process -----------------------------------------------------


def _load(path: Path) -> Any:
    spec = importlib.util.spec_from_file_location(f"mutation_{path.stem}_{id(path)}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _calls(func: Any) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
    """(marker data, parameters) per test the function stands for; skipped ones none."""
    marks = getattr(func, "pytestmark", [])
    if any(m.name == "skip" for m in marks):
        return
    data: dict[str, Any] = {}
    for m in marks:
        if m.name == "statectl_data":
            data.update(m.kwargs)
    params = [m for m in marks if m.name == "parametrize"]
    if not params:
        yield data, {}
        return
    argnames = params[0].args[0]
    names = argnames.split(",") if isinstance(argnames, str) else list(argnames)
    names = [n.strip() for n in names]
    for values in params[0].args[1]:
        yield data, dict(zip(names, values, strict=True))


def run_module(
    path: Path, spec: Chart, mutant: Mutant | None, recovery: tuple[RecoveryRow, ...] = ()
) -> tuple[int, int]:
    """(tests failed, tests run) of the generated module at ``path`` on ``mutant``;
    ``recovery``: the file's Recovery rows, which its recovery tests restart with."""
    module = _load(path)
    chart = spec if mutant is None else mutant.chart
    maker = None if mutant is None else mutant.driver  # None: the harness's own twin

    def device(data: dict[str, Any] | None = None) -> DeviceUnderTest:
        driver = maker(chart) if maker is not None else None
        return DeviceUnderTest(
            chart, driver, data=data or None, new_driver=maker, recovery=recovery
        )

    failed = run = 0
    for name, func in vars(module).items():
        if not name.startswith("test_") or not callable(func):
            continue
        wanted = inspect.signature(func).parameters
        for data, params in _calls(func):
            given = {
                "statectl_device": lambda data=data: device(data),
                "statectl_device_factory": lambda: device,
                "statectl_spec": lambda: lambda: Specification(spec),
            }
            args = {k: params[k] if k in params else given[k]() for k in wanted}
            run += 1
            try:
                with contextlib.redirect_stdout(io.StringIO()):
                    func(**args)
            except Exception:  # a failing test: the mutant is killed
                failed += 1
    return failed, run


def modules(file: Path, out: Path, criteria: tuple[str, ...]) -> dict[str, Path]:
    """Each criterion's module generated from the right ``file``."""
    made = {}
    for c in criteria:
        if c == "hypothesis":
            made[c] = generate_hypothesis(file, out)
        else:
            made[c] = generate(file, c, out).path
    return made


def score(
    file: Path, criteria: tuple[str, ...], kinds: tuple[str, ...] = KINDS
) -> list[dict[str, Any]]:
    """One row per mutant: kind, name, equivalent, and killed per criterion."""
    spec = load_chart(file)
    loaded, _ = load_tables(file)
    recovery = tuple(loaded.recovery) if loaded is not None else ()
    mutants = [m for m in table_mutants(spec) + driver_mutants(spec) if m.kind in kinds]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        made = modules(file, Path(tmp), criteria)
        for c, path in made.items():
            failed, _ = run_module(path, spec, None, recovery)
            if failed:
                raise SystemExit(f"{file.name}: the {c} module fails on the right tables")
        for m in mutants:
            row: dict[str, Any] = {
                "kind": m.kind,
                "name": m.name,
                "equivalent": equivalent(spec, m),
            }
            for c, path in made.items():
                row[c] = run_module(path, spec, m, recovery)[0] > 0
            rows.append(row)
    return rows


def table(results: dict[str, list[dict[str, Any]]], criteria: tuple[str, ...]) -> str:
    """The score table: killed of non-equivalent mutants, per kind and criterion."""
    head = "| kind | mutants | equivalent | " + " | ".join(f"`{c}`" for c in criteria) + " |"
    lines = [head, "|---" * (3 + len(criteria)) + "|"]
    everything = [r for rows in results.values() for r in rows]
    for kind in [*KINDS, "all"]:
        rows = [r for r in everything if kind in ("all", r["kind"])]
        if not rows:
            continue
        live = [r for r in rows if not r["equivalent"]]
        cells = [f"{sum(r[c] for r in live)}/{len(live)}" for c in criteria]
        lines.append(
            f"| {kind} | {len(rows)} | {len(rows) - len(live)} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="*", type=Path, default=EXAMPLES)
    parser.add_argument("--criteria", default=",".join(CRITERIA))
    parser.add_argument("--no-hypothesis", action="store_true")
    parser.add_argument("--survivors", action="store_true", help="list what each criterion misses")
    args = parser.parse_args(argv)
    criteria = tuple(c for c in args.criteria.split(",") if c)
    if args.no_hypothesis:
        criteria = tuple(c for c in criteria if c != "hypothesis")
    try:
        results = {f.name: score(f, criteria) for f in args.files}
    except StatectlError as exc:  # a cell file, a broken device file: say so, no traceback
        print(f"mutation.py: {exc}; give device files, a cell's one by one", file=sys.stderr)
        return 2
    print(table(results, criteria))
    if args.survivors:
        for f, rows in results.items():
            for r in rows:
                missed = [c for c in criteria if not r[c]]
                if missed and not r["equivalent"]:
                    print(f"{f}: {r['kind']}: {r['name']}: missed by {', '.join(missed)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
