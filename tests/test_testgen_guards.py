"""The guard parts of pairs: conditions, candidate values, MC/DC notes (guardcases.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from statectl.front.builder.build import load_chart
from statectl.out.testgen import cases_for, explore
from statectl.out.testgen.conditions import analyse, decides, input_values

JOG = "_event.data.speed <= max_speed and _event.data.enable"


@pytest.mark.parametrize(
    ("guard", "conditions"),
    [
        (JOG, ["_event.data.speed <= max_speed", "_event.data.enable"]),
        ("not (a > 1 or previous == 'Moving')", ["a > 1", "previous == 'Moving'"]),
        ("In('Moving')", ["In('Moving')"]),
    ],
)
def test_a_guard_splits_into_its_conditions(guard: str, conditions: list[str]) -> None:
    """The conditions are the operands of and/or/not, in reading order."""
    info = analyse(guard, frozenset({"a", "max_speed"}))
    assert info is not None
    assert [c.text for c in info.conditions] == conditions


def test_candidate_values_come_from_what_each_input_is_compared_with() -> None:
    """A field compared with a name gets that name's default and neighbours; a bare
    read gets both booleans."""
    found = input_values(JOG, frozenset({"max_speed"}), {"max_speed": 5})
    assert found == {("event", "speed"): [5, 4, 6], ("event", "enable"): [True, False]}


def test_a_condition_decides_only_where_the_others_let_it() -> None:
    """In a and b, a decides where b holds and not where b fails (masking MC/DC)."""
    info = analyse("a > 1 and b", frozenset({"a", "b"}))
    assert info is not None
    first = info.conditions[0]
    assert decides(first, {"a": 0, "b": True}) is True
    assert decides(first, {"a": 0, "b": False}) is False


COVERED = """\
device: Valve
data:
  x: 0
states:
  - {state: Shut, control: default, ignore: [Done]}
  - {state: Open, control: event trigger required, api: Open(), ignore: [Open]}
events:
  - {event: Open, condition: pressure is up, guard: x > 1 or x > 2, old: Shut, new: Open,
     kind: command, api: Open}
  - {event: Done, condition: done, old: Open, new: Shut, kind: completion, api: Open}
"""


def test_a_condition_no_values_show_is_a_note(tmp_path: Path) -> None:
    """In x > 1 or x > 2 the second condition never matters alone: the module says so."""
    tables = tmp_path / "valve.yaml"
    tables.write_text(COVERED, encoding="utf-8")
    suite = cases_for(explore(load_chart(tables)), "pairs")
    assert any("'x > 2'" in n and "MC/DC" in n for n in suite.notes), suite.notes
    assert not any("'x > 1'" in n for n in suite.notes)
    assert dict(suite.parts)["MC/DC"] >= 1
