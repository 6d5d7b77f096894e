"""``statectl testgen``: tables -> explored graph -> cases -> a pytest module on disk."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from statectl.front.builder.build import load_chart
from statectl.front.tables import RecoveryRow, write_files
from statectl.front.tables import load as load_tables
from statectl.kernel.errors import DiagnosticError, StatectlError
from statectl.out.escape.python import NAME_LIMIT, identifier
from statectl.out.testgen.cases import CRITERIA, Suite, cases_for, count_steps
from statectl.out.testgen.compact import is_big
from statectl.out.testgen.graphwalker import graphwalker_model
from statectl.out.testgen.paths import MAX_NODES, explore
from statectl.out.testgen.probes import probes_for
from statectl.out.testgen.writer import hypothesis_text, module_text, tests_in
from statectl.out.testgen.xstate import xstate_config

__all__ = [
    "Generated",
    "export_graphwalker",
    "export_xstate",
    "generate",
    "generate_hypothesis",
    "write_atomic",
]


@dataclass(frozen=True, slots=True)
class Generated:
    path: Path
    suite: Suite
    tests: int  # test functions plus the rows of the parametrised tables
    steps: int  # events sent by all tests together
    #: tests through the implementation (faults, monitors, completions, recovery): the same
    #: for every criterion, so not in ``tests`` nor ``steps``
    probes: int = 0


def module_name(device: str, criterion: str) -> str:
    return f"test_{identifier(device, 'device', NAME_LIMIT)}_{criterion}.py"


def write_atomic(path: Path, text: str) -> None:
    """Write ``path`` whole or not at all, as every command writes (tables.write_files)."""
    try:
        write_files({path: text}, make_dirs=True)
    except DiagnosticError as exc:
        why = "; ".join(d.message.removeprefix("cannot write: ") for d in exc.diagnostics)
        raise StatectlError(
            f"cannot write {path}: {why}; give --out a writable directory"
        ) from None


def export_graphwalker(file: str | Path, out_dir: str | Path) -> Path:
    """Write ``DEVICE.graphwalker.json``: the state graph as a GraphWalker model."""
    chart = load_chart(Path(file))
    path = Path(out_dir) / f"{identifier(chart.name, 'device', NAME_LIMIT)}.graphwalker.json"
    write_atomic(path, graphwalker_model(explore(chart)))
    return path


def export_xstate(file: str | Path, out_dir: str | Path) -> Path:
    """Write ``DEVICE.xstate.json``: the chart as an XState machine config."""
    chart = load_chart(Path(file))
    path = Path(out_dir) / f"{identifier(chart.name, 'device', NAME_LIMIT)}.xstate.json"
    write_atomic(path, xstate_config(chart))
    return path


def generate_hypothesis(file: str | Path, out_dir: str | Path) -> Path:
    """Write ``test_DEVICE_hypothesis.py``: a RuleBasedStateMachine over the chart's events."""
    source = Path(file)
    chart = load_chart(source)
    out = Path(out_dir)
    path = out / module_name(chart.name, "hypothesis")
    write_atomic(path, hypothesis_text(chart, source, out, str(file)))
    return path


def generate(
    file: str | Path,
    criterion: str,
    out_dir: str | Path,
    *,
    max_nodes: int = MAX_NODES,
    progress: Callable[[int, int], None] | None = None,
) -> Generated:
    """Write the ``criterion`` test module of the device file ``file`` into ``out_dir``.

    Written whole or not at all (:func:`write_atomic`).
    """
    if criterion not in CRITERIA:
        raise StatectlError(f"unknown criterion {criterion!r}; choose one of {', '.join(CRITERIA)}")
    source = Path(file)
    chart = load_chart(source)
    graph = explore(chart, max_nodes=max_nodes, progress=progress)
    suite = cases_for(graph, criterion)
    probes, notes = probes_for(graph, _recovery_rows(source), _unused(suite))
    suite = replace(suite, notes=(*suite.notes, *notes))
    out = Path(out_dir)
    path = out / module_name(chart.name, criterion)
    text = module_text(suite, chart.name, source, out, str(file), probes=tuple(probes))
    write_atomic(path, text)
    big = is_big(suite)
    tests = tests_in(suite, big)
    steps = count_steps(suite.cases) + sum(
        len(t.given) + t.count if big else (len(t.given) + 1) * t.count for t in suite.tables
    )
    return Generated(path, suite, tests, steps, len(probes))


def _recovery_rows(source: Path) -> tuple[RecoveryRow, ...]:
    """The device file's Recovery rows (its chart loaded already, so the file loads)."""
    tables, _ = load_tables(source)
    return tuple(tables.recovery) if tables is not None else ()


def _unused(suite: Suite) -> Callable[[str], str]:
    """Names for the probes that no case of ``suite`` has taken."""
    used = {c.name for c in suite.cases} | {t.name for t in suite.tables}

    def name(base: str) -> str:
        found, n = base[:90], 2
        while found in used:
            found, n = f"{base[:86]}_{n}", n + 1
        used.add(found)
        return found

    return name
