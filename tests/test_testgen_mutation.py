"""The mutation check (tests/mutation.py): pairs kills the history, MC/DC and boundary mutants.

A small subset of ``python tests/mutation.py`` (docs/testing.md, "What the sets can
see"): each mutant of the issue's kinds, run against the ``pairs`` module generated
from the right tables, and against that module without the guard parts (the
``pairs`` set as it was before them), which passes on it.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest

import mutation
from statectl.front.builder.build import load_chart
from statectl.out.testgen import cases_for, explore
from statectl.out.testgen.writer import module_text
from support import MOTOR, ROOT

PRESS = ROOT / "examples" / "press" / "press.yaml"

#: A jog the operator enables, no faster than the limit: a two-field guard over event data.
JOG = """\
device: Jog
data:
  max_speed: 5
states:
  - {state: Idle, control: default, api: Jog(), ignore: [Done]}
  - {state: Jogging, control: event trigger required, api: Jog(), ignore: [Jog]}
events:
  - {event: Jog, condition: a slow jog the operator enabled,
     guard: _event.data.speed <= max_speed and _event.data.enable, old: Idle, new: Jogging,
     kind: command, api: Jog, data: {speed: int, enable: bool}}
  - {event: Done, condition: the jog is done, old: Jogging, new: Idle, kind: completion,
     api: Jog}
"""

GUARD_PARTS = ("test_guard_", "test_mcdc_", "test_boundary_")


def modules(file: Path, out: Path) -> tuple[Path, Path]:
    """The pairs module of ``file``, and the same without its guard parts (before)."""
    chart = load_chart(file)
    suite = cases_for(explore(chart), "pairs")
    before = replace(
        suite, cases=tuple(c for c in suite.cases if not c.name.startswith(GUARD_PARTS))
    )
    assert len(before.cases) < len(suite.cases)
    paths = []
    for name, s in (("after", suite), ("before", before)):
        path = out / name / f"test_{chart.name.lower()}_pairs.py"
        path.parent.mkdir(parents=True)
        path.write_text(module_text(s, chart.name, file, path.parent, str(file)), "utf-8")
        paths.append(path)
    return paths[0], paths[1]


#: (device file or inline tables, mutant kind, mutant name as tests/mutation.py names it,
#: whether pairs without its guard parts passes on it: the issue's two did)
ISSUE = [
    (MOTOR, "previous widened", "row 3: also Returning", True),
    (JOG, "conjunct dropped", "row 1: without '_event.data.enable'", True),
    (JOG, "conjunct dropped", "row 1: without '_event.data.speed <= max_speed'", True),
    (JOG, "boundary off by one", "row 1: _event.data.speed < max_speed", False),
    (PRESS, "conjunct dropped", "row 1: without 'strokes < limit'", True),
    (PRESS, "boundary off by one", "row 1: strokes <= limit", True),
]


@pytest.mark.parametrize(("tables", "kind", "name", "missed"), ISSUE, ids=[i[2] for i in ISSUE])
def test_pairs_kills_the_mutants_the_fixed_suites_missed(
    tmp_path: Path, tables: Path | str, kind: str, name: str, missed: bool
) -> None:
    """The pairs module fails on the mutant; without its guard parts it passed on the
    issue's (a guard over previous widened, a conjunct over event data dropped)."""
    file = tables if isinstance(tables, Path) else tmp_path / "jog.yaml"
    if isinstance(tables, str):
        file.write_text(tables, encoding="utf-8")
    spec = load_chart(file)
    found = [m for m in mutation.table_mutants(spec) if (m.kind, m.name) == (kind, name)]
    assert len(found) == 1, [m.name for m in mutation.table_mutants(spec)]
    mutant = found[0]
    assert not mutation.equivalent(spec, mutant)
    after, before = modules(file, tmp_path / "gen")
    assert mutation.run_module(after, spec, None)[0] == 0  # passes on the right tables
    assert (mutation.run_module(before, spec, mutant)[0] == 0) is missed
    assert mutation.run_module(after, spec, mutant)[0] > 0


def test_a_widening_to_a_state_previous_never_holds_is_equivalent() -> None:
    """Blocked is never the previous state in Blocked: that widening changes nothing seen."""
    spec = load_chart(MOTOR)
    widened = {m.name: m for m in mutation.table_mutants(spec) if m.kind == "previous widened"}
    assert sorted(widened) == ["row 3: also Blocked", "row 3: also Returning"]
    assert mutation.equivalent(spec, widened["row 3: also Blocked"])
    assert not mutation.equivalent(spec, widened["row 3: also Returning"])


def test_the_hypothesis_module_compares_with_the_specification(tmp_path: Path) -> None:
    """The Hypothesis module passes on the Motor and fails on the widened-previous Motor."""
    spec = load_chart(MOTOR)
    made = mutation.modules(MOTOR, tmp_path, ("hypothesis",))["hypothesis"]
    widened = next(m for m in mutation.table_mutants(spec) if m.name == "row 3: also Returning")
    assert mutation.run_module(made, spec, None) == (0, 1)
    assert mutation.run_module(made, spec, widened) == (1, 1)


def test_the_pairs_docstring_counts_each_part(tmp_path: Path) -> None:
    """The pairs module says how many cases each part adds, and they add up."""
    after, _ = modules(MOTOR, tmp_path)
    text = after.read_text(encoding="utf-8")
    line = re.search(r"Cases each part adds: (.*)\.", text)
    assert line is not None
    parts = dict(re.findall(r"([\w /]+?) (\d+)(?:, |$)", line.group(1)))
    assert parts == {
        "pairs": "10",
        "guards over previous": "2",
        "MC/DC": "0",
        "boundaries": "0",
    }
    cases = int(re.search(r"(\d+) cases and", text).group(1))  # type: ignore[union-attr]
    assert sum(map(int, parts.values())) == cases  # the Motor has no timeout or defer cases
