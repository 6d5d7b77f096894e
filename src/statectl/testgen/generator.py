"""``statectl testgen``: tables -> explored graph -> cases -> a pytest module on disk."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from statectl.build import load_chart
from statectl.errors import StatectlError
from statectl.testgen.cases import CRITERIA, Suite, cases_for, count_steps
from statectl.testgen.paths import MAX_NODES, explore
from statectl.testgen.writer import module_text

__all__ = ["Generated", "generate"]


@dataclass(frozen=True, slots=True)
class Generated:
    path: Path
    suite: Suite
    tests: int  # test functions plus the rows of the parametrised tables
    steps: int  # events sent by all tests together


def module_name(device: str, criterion: str) -> str:
    slug = re.sub(r"[^0-9a-z]+", "_", device.lower()).strip("_") or "device"
    return f"test_{slug}_{criterion}.py"


def generate(
    file: str | Path, criterion: str, out_dir: str | Path, *, max_nodes: int = MAX_NODES
) -> Generated:
    """Write the ``criterion`` test module of the device file ``file`` into ``out_dir``.

    Written whole or not at all (a temporary file renamed into place).
    """
    if criterion not in CRITERIA:
        raise StatectlError(f"unknown criterion {criterion!r}; choose one of {', '.join(CRITERIA)}")
    source = Path(file)
    chart = load_chart(source)
    suite = cases_for(explore(chart, max_nodes=max_nodes), criterion)
    out = Path(out_dir)
    path = out / module_name(chart.name, criterion)
    text = module_text(suite, chart.name, source, out, str(file))
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        out.mkdir(parents=True, exist_ok=True)
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        if tmp.is_file():
            tmp.unlink()
        raise StatectlError(
            f"cannot write {path}: {exc.strerror or exc}; give --out a writable directory"
        ) from None
    tests = len(suite.cases) + sum(len(t.rows) for t in suite.tables)
    steps = count_steps(suite.cases) + sum((len(t.given) + 1) * len(t.rows) for t in suite.tables)
    return Generated(path, suite, tests, steps)
