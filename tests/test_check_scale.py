"""statectl check does work in proportion to the rows: counted operations, not wall time.

The figures (100,000 rows under 5 s) are bench/check.py --scale's; these tests hold
the shape of the algorithm: a file is parsed once, a guard repeated on many rows is
analysed once, and the collector does not walk the growing tables during a check.
"""

from __future__ import annotations

import gc
import io
from pathlib import Path

import pytest

import statectl.front.builder.eventdata as eventdata
import statectl.front.rules as rules
from statectl.channels.cli import main
from statectl.front.tables import safeyaml


def _device(path: Path, rows: int, guard: str = "_event.data.x > 1") -> Path:
    lines = ["device: D", "states:", "  - {state: A, control: default}"]
    lines += ["  - {state: B, control: event trigger required}", "events:"]
    for i in range(rows):
        old, new = ("A", "B") if i % 2 == 0 else ("B", "A")
        lines.append(f"  - {{event: E{i % 2}, old: {old}, new: {new}, guard: '{guard}'}}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _check(path: Path) -> int:
    return main(["check", str(path)], out=io.StringIO(), err=io.StringIO())


def test_check_parses_a_device_file_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Telling a cell from a device file reads the parser's events, not a second full load."""
    composed: list[int] = []
    real = safeyaml._compose_with

    def counting(*args: object, **kw: object) -> object:
        composed.append(1)
        return real(*args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(safeyaml, "_compose_with", counting)
    _check(_device(tmp_path / "d.yaml", 40))
    assert len(composed) == 1


@pytest.mark.parametrize("rows", [10, 400])
def test_a_repeated_guard_is_analysed_once_per_event(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rows: int
) -> None:
    """400 rows with one guard over two events walk two trees, as 10 rows do."""
    eventdata._reads_once.cache_clear()
    walks: list[str] = []
    real = eventdata._parents

    def counting(tree: object) -> object:
        walks.append("walk")
        return real(tree)  # type: ignore[arg-type]

    monkeypatch.setattr(eventdata, "_parents", counting)
    _check(_device(tmp_path / f"d{rows}.yaml", rows, guard=f"_event.data.x > {rows}"))
    assert len(walks) == 2


def test_a_guard_that_reads_no_event_data_is_not_walked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A guard over the chart's own data cannot read the event: nothing to analyse."""
    walks: list[str] = []
    monkeypatch.setattr(eventdata, "_parents", lambda tree: walks.append("walk") or {})
    path = tmp_path / "d.yaml"
    _device(path, 20, guard="mode > 1")
    path.write_text(path.read_text().replace("states:", "data:\n  mode: 0\nstates:", 1))
    assert _check(path) == 0
    assert walks == []


def test_the_collector_is_paused_while_a_file_is_checked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Loading, building and checking run with the cyclic collector off, and it is on after."""
    seen: list[bool] = []
    real = rules.build

    def watching(*args: object, **kw: object) -> object:
        seen.append(gc.isenabled())
        return real(*args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(rules, "build", watching)
    assert gc.isenabled()
    _check(_device(tmp_path / "d.yaml", 10, guard="True"))
    assert seen == [False]
    assert gc.isenabled()


def test_each_rows_entry_set_is_asked_of_the_kernel_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """C401 and the timing rules share one entry set per transition (and one for the start)."""
    import statectl.front.rules.timing as timing

    asked: list[int] = []
    real = rules.entry_set

    def counting(m: object, transitions: list[object]) -> object:
        asked.append(len(transitions))
        return real(m, transitions)  # type: ignore[arg-type]

    monkeypatch.setattr(rules, "entry_set", counting)
    monkeypatch.setattr(timing, "entry_set", counting, raising=False)
    lines = ["device: R", "states:", "  - {state: S0, control: default}"]
    lines += [f"  - {{state: S{i}, control: event trigger required}}" for i in range(1, 30)]
    lines.append("events:")
    lines += [
        f"  - {{event: e{i}, old: S{i}, new: S{(i + 1) % 30}, kind: command, api: Go}}"
        for i in range(30)
    ]
    path = tmp_path / "ring.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    assert _check(path) == 0
    assert asked.count(1) == 30 and asked.count(0) == 1


def _wide(path: Path, states: int) -> Path:
    """``states`` states, each entered by its own command of one API with its own completion."""
    lines = ["device: W", "states:", "  - {state: S0, control: default}"]
    lines += [f"  - {{state: S{i}, control: event trigger required}}" for i in range(1, states)]
    lines.append("events:")
    for i in range(1, states):
        lines.append(f"  - {{event: Go{i}, old: S0, new: S{i}, kind: command, api: Run}}")
        lines.append(f"  - {{event: Done{i}, old: S{i}, new: S0, kind: completion, api: Run}}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_completions_of_a_call_are_found_without_scanning_every_row(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """C422's call model asks about each event a bounded number of times, not once per call."""
    from statectl.kernel.model import Chart

    asked: list[int] = []
    real = Chart.event

    def counting(self: Chart, name: str) -> object:
        asked.append(1)
        return real(self, name)

    monkeypatch.setattr(Chart, "event", counting)
    counts = []
    for states in (50, 200):
        asked.clear()
        _check(_wide(tmp_path / f"w{states}.yaml", states))
        counts.append(len(asked))
    # linear: 4x the rows asks at most ~4x as often (a scan per call made it 16x)
    assert counts[1] <= 5 * counts[0], counts


def test_a_repeated_guard_is_read_for_names_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """C420/C421 read a guard repeated on 400 rows once, not once per row."""
    import statectl.front.rules.names as names

    names._names_in.cache_clear()
    reads: list[int] = []
    real = names._named

    def counting(tree: object) -> object:
        reads.append(1)
        return real(tree)  # type: ignore[arg-type]

    monkeypatch.setattr(names, "_named", counting)
    _check(_device(tmp_path / "d.yaml", 400, guard='previous == "A"'))
    assert len(reads) == 1


def _ring(path: Path, rows: int) -> Path:
    """bench/check.py's ring: ``rows / 4`` states, each with ``e2`` twice under exclusive
    guards that cover every case (``mode <= 1`` / ``mode > 1``)."""
    states = rows // 4
    lines = ["device: Big", "data:", "  mode: 0", "states:", "  - {state: S0, control: default}"]
    lines += [f"  - {{state: S{s}, control: event trigger required}}" for s in range(1, states)]
    lines.append("events:")
    for i in range(rows):
        s, k = divmod(i, 4)
        guard = ", guard: mode <= 1" if k == 2 else ", guard: mode > 1" if k == 3 else ""
        lines.append(f"  - {{event: e{min(k, 2)}, old: S{s}, new: S{(s + 1 + k) % states}{guard}}}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_a_pair_of_guards_repeated_on_every_state_is_compared_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """C403 (exclusive) and C419 (covering) prove a pair of guard texts once, however many
    states repeat it: the proofs of 400 rows are the proofs of 40 (one per state made
    them grow with the rows)."""
    import statectl.front.rules.guards as guards

    proofs: list[int] = []
    real = guards._contradictory

    def counting(conj: object) -> bool:
        proofs.append(1)
        return real(conj)  # type: ignore[arg-type]

    monkeypatch.setattr(guards, "_contradictory", counting)
    counts = []
    for rows in (40, 400):
        guards._exclusive.cache_clear()
        proofs.clear()
        assert _check(_ring(tmp_path / f"ring{rows}.yaml", rows)) == 0
        counts.append(len(proofs))
    assert counts[0] == counts[1] <= 8, counts


def test_a_checked_chart_is_not_kept_by_the_process(tmp_path: Path) -> None:
    """statectl check frees the chart it checked (and its compiled machine) before the
    collector is on again: no 100,000-row chart stays for it to walk, or in memory."""
    from statectl.kernel.semantics import machine

    before = dict(machine._COMPILED)
    assert _check(_ring(tmp_path / "ring.yaml", 40)) == 0
    assert before == machine._COMPILED


class _CountingRows(tuple):  # type: ignore[type-arg]  # a chart's transitions, walks counted
    walks = 0

    def __iter__(self):  # type: ignore[no-untyped-def]
        type(self).walks += 1
        return super().__iter__()


def test_a_charts_event_names_walk_its_transitions_once(tmp_path: Path) -> None:
    """Five rules ask a chart's event names; the transitions are walked for the first only."""
    import dataclasses

    from statectl.front.builder.build import build
    from statectl.front.tables import load

    tables, _ = load(_device(tmp_path / "d.yaml", 40))
    assert tables is not None
    built, _ = build(tables)
    assert built is not None
    chart = dataclasses.replace(built, transitions=_CountingRows(built.transitions))
    first = chart.event_names
    walked = _CountingRows.walks
    assert first == ("E0", "E1") and walked >= 1
    assert all(chart.event_names == first for _ in range(5))
    assert _CountingRows.walks == walked


@pytest.mark.parametrize(
    "cells",
    [
        {"event": " go ", "old": "A", "new": "B"},
        {"event": "go", "old": "A", "new": "B", "kind": " Fault ", "guard": "x > 1", "api": "m"},
        {"event": "go", "old": "A", "new": "B", "kind": "", "condition": "c", "invoke": "i"},
        {"event": "go", "old": "A", "new": "B", "kind": "sometimes"},  # T107: the slow way
        {"event": "a,b", "old": "A", "new": "B"},  # T111
        {"event": "go", "old": "", "new": "B"},  # T104
        {"event": "go", "old": "A", "new": "B", "colour": "red"},  # T103
        {"event": "go", "old": "A", "new": ("B",)},  # T108
    ],
)
def test_the_short_way_for_a_plain_event_row_reads_as_the_long_way(
    monkeypatch: pytest.MonkeyPatch, cells: dict[str, object]
) -> None:
    """A row of plain text cells skips the cell-by-cell checks: same row, same diagnostics."""
    _same_both_ways(monkeypatch, "event_row", "_plain_event_row", cells)


def _same_both_ways(
    monkeypatch: pytest.MonkeyPatch, reader: str, short_way: str, cells: dict[str, object]
) -> None:
    """``reader`` gives the same row and diagnostics with its ``short_way`` and without."""
    from statectl.front.tables import cells as checked
    from statectl.front.tables.rows import RawRow
    from statectl.kernel.errors import Location

    at = Location("d.yaml", 3)
    row = RawRow(at, {k: (v, at) for k, v in cells.items()})  # type: ignore[misc]
    read = getattr(checked, reader)
    short: list[object] = []
    got = read(row, short)
    monkeypatch.setattr(checked, short_way, lambda _row: None)
    long: list[object] = []
    assert read(row, long) == got
    assert short == long


@pytest.mark.parametrize(
    "cells",
    [
        {"state": "A", "control": "default"},
        {"state": " A ", "control": " Event_Trigger-Required "},
        {"state": "A"},
        {"state": "A", "control": ""},
        {"state": "A", "parent": "P", "component": "C", "api": "m", "description": " d "},
        {"state": "A", "control": "default, event trigger required"},  # two: the long way
        {"state": "A", "control": "sometimes"},  # T106
        {"state": "", "control": "default"},  # T104
        {"control": "default"},  # T104
        {"state": "A", "colour": "red"},  # T103
        {"state": "A", "control": ("default",)},  # a list: the long way
        {"state": "A", "ignore": "go", "timeout": "1 s -> go"},  # the long way
    ],
)
def test_the_short_way_for_a_plain_state_row_reads_as_the_long_way(
    monkeypatch: pytest.MonkeyPatch, cells: dict[str, object]
) -> None:
    """A state row of plain text cells skips the cell-by-cell checks: same row, same
    diagnostics."""
    _same_both_ways(monkeypatch, "state_row", "_plain_state_row", cells)


def test_check_does_not_load_the_explorer(tmp_path: Path) -> None:
    """A device file's check pays for what it uses: the cell explorer is imported by a
    cell's commands only (it was pulled in by every command through the run's problem
    count, a third of check's start-up)."""
    import subprocess
    import sys

    path = _device(tmp_path / "d.yaml", 4)
    probe = (
        "import sys\nfrom statectl.channels.cli import main\n"
        f"code = main(['check', {str(path)!r}])\n"
        "print(code, sorted(m for m in sys.modules if m.startswith('statectl.cell.explore')))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.split("\n")[-2] == "0 []", done.stdout + done.stderr


def test_check_does_not_work_out_every_transitions_domain(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A check asks what rows enter, never steps: the kernel's table of transition domains
    (a fifth of the rules' time on 100,000 rows) is made by the first step, not the check."""
    from statectl.kernel.semantics import machine

    asked: list[int] = []
    real = machine.Machine.static_domains

    def counting(self: machine.Machine) -> dict[int, str | None]:
        asked.append(1)
        return real(self)

    monkeypatch.setattr(machine.Machine, "static_domains", counting)
    assert _check(_device(tmp_path / "d.yaml", 40)) == 0
    assert asked == []


def test_the_domains_are_worked_out_once_when_first_asked(tmp_path: Path) -> None:
    """The table a step reads holds every transition's domain, made on the first ask only."""
    from statectl.front.builder.build import load_chart
    from statectl.kernel.semantics import Machine, initial

    chart = load_chart(_device(tmp_path / "d.yaml", 4))
    m = Machine(chart)
    initial(m)  # starting enters the default state: no transition is taken
    assert m._static_domains is None
    domains = m.static_domains()
    assert domains == {id(t): m._domain(t, t.targets) for t in chart.transitions}
    assert m.static_domains() is domains


def test_check_does_not_import_the_schemas_or_the_run_counters(tmp_path: Path) -> None:
    """The start of every command builds the whole parser: ``statectl schema``'s choices
    and ``statectl node``'s problem counter were imported with it (the schemas import
    every reader they are made from: 0.14 s of each start)."""
    import subprocess
    import sys

    path = _device(tmp_path / "d.yaml", 4)
    probe = (
        "import sys\nfrom statectl.channels.cli import main\n"
        f"code = main(['check', {str(path)!r}])\n"
        "print(code, sorted(m for m in sys.modules if m in "
        "('statectl.out.schema', 'statectl.channels.cli.problems')))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.split("\n")[-2] == "0 []", done.stdout + done.stderr


def test_the_schema_commands_choices_are_the_schemas_kinds() -> None:
    """``statectl schema KIND`` offers the kinds out/schema.py makes, no more, no fewer."""
    from statectl.channels.cli.editors import SCHEMA_KINDS
    from statectl.out.schema import KINDS

    assert SCHEMA_KINDS == KINDS


@pytest.mark.parametrize(("guard", "bad"), [("1 < 2", False), ("speed > 1", True)])
def test_a_clean_guard_is_checked_once_per_event_a_bad_one_on_every_row(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, guard: str, bad: bool
) -> None:
    """400 rows sharing a clean guard over two events check it twice; a guard that reads
    an undefined name is reported on each of its rows, at each row's line."""
    import statectl.front.builder.chart as chart

    checked: list[str] = []
    real = chart.check_guard

    def counting(*args: object) -> object:
        checked.append("guard")
        return real(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(chart, "check_guard", counting)
    path = _device(tmp_path / "d.yaml", 400, guard)
    found = rules.check_paths([str(path)])
    x303 = [d.where.line for d in found if d.code == "X303"]
    assert len(checked) == (400 if bad else 2)
    assert x303 == (list(range(6, 406)) if bad else [])
