"""statectl testgen for cells, the statectl_cell fixture, coverage as SVG, event-data guards.

docs/testing.md; the device-level parts are in tests/test_testgen.py.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from statectl.cell.model import load_cell_or_raise
from statectl.front.builder.build import load_chart
from statectl.out.testgen import generate
from statectl.out.testgen.cellharness import CellUnderTest
from statectl.out.testgen.harness import DeviceUnderTest
from support import MOTOR
from test_testgen import (  # noqa: F401  # journal: a fixture used below
    cli,
    counts,
    doc_block,
    functions,
    journal,
    run_pytest,
)

HAS_DOT = shutil.which("dot") is not None


# -- coverage as SVG ---------------------------------------------------------------------------


@pytest.mark.skipif(not HAS_DOT, reason="Graphviz dot is not installed")
def test_coverage_svg_colours_taken_and_never_taken_rows(journal: Path) -> None:  # noqa: F811
    """The SVG labels each row with how often it was taken: green if taken, red if never."""
    code, out, err = cli("coverage", str(journal), str(MOTOR), "--format", "svg")
    assert code == 0, err
    assert out.lstrip().startswith("<?xml") and "</svg>" in out
    taken = re.findall(r'fill="#22aa22"[^>]*>([^<]*x\d+)</text>', out)
    never = re.findall(r'fill="#cc3333"[^>]*>([^<]*\(never\))</text>', out)
    assert len(taken) == 4 and len(never) == 2, (taken, never)
    assert any(t.startswith("Error ") for t in never)


def test_coverage_svg_without_dot_says_how_to_install(
    journal: Path,  # noqa: F811
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With no Graphviz dot on PATH, --format svg exits 1 with the install hint, no traceback."""
    monkeypatch.setenv("PATH", "")
    code, out, err = cli("coverage", str(journal), str(MOTOR), "--format", "svg")
    assert (code, out) == (1, "")
    assert "apt-get install graphviz" in err and "Traceback" not in err


# -- cells -------------------------------------------------------------------------------------

CELL_DIR = MOTOR.parents[1] / "pick-and-place"
CELL = CELL_DIR / "cell.yaml"


def copy_cell(into: Path, text: str | None = None) -> Path:
    """The pick-and-place devices copied into ``into``, with ``text`` as the cell file."""
    into.mkdir(parents=True, exist_ok=True)
    for f in CELL_DIR.glob("*.yaml"):
        shutil.copy(f, into / f.name)
    if text is not None:
        (into / "cell.yaml").write_text(text, encoding="utf-8")
    return into / "cell.yaml"


def test_cell_testgen_writes_each_device_and_the_links(tmp_path: Path) -> None:
    """Given a cell, testgen writes each device's module and a links module; all pass on twins."""
    code, out, err = cli("testgen", str(CELL), "--out", str(tmp_path))
    assert code == 0, err
    written = sorted(p.name for p in tmp_path.glob("test_*.py"))
    assert written == [
        "test_armmotor_rows.py",
        "test_conveyor_rows.py",
        "test_gripper_rows.py",
        "test_partsensor_rows.py",
        "test_pickandplace_links.py",
    ]
    links = functions(tmp_path / "test_pickandplace_links.py")
    assert len(links) == 8 and "wrote" in out and "8 link tests" in out
    guarded = links["test_link_06_arm_initialization_completion_row_04_guard_false"]
    assert "Its guard is false here" in guarded
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:]
    said = sum(int(n) for n in re.findall(r": (\d+) (?:link )?tests", out))
    said += sum(int(n) for n in re.findall(r"; (\d+) more through the implementation", out))
    assert counts(result) == {"passed": said}


def test_links_module_fails_for_every_deleted_link(tmp_path: Path) -> None:
    """The links tests generated from the right cell fail on a cell missing any one link."""
    gen = tmp_path / "gen"
    cell = copy_cell(tmp_path / "cell")
    code, _, err = cli("testgen", str(cell), "--out", str(gen))
    assert code == 0, err
    for f in gen.glob("test_*.py"):
        if not f.name.endswith("_links.py"):
            f.unlink()
    text = CELL.read_text(encoding="utf-8")
    lines = [ln for ln in text.splitlines() if ln.startswith("  - {from:")]
    assert len(lines) == 7
    survived = []
    for line in lines:
        cell.write_text(text.replace(line + "\n", ""), encoding="utf-8")
        result = run_pytest(gen)
        if result.returncode == 0 or "failed" not in counts(result):
            survived.append(line)
    assert survived == []


def test_cell_hypothesis_passes_on_the_cell_and_finds_the_interlock_bug(tmp_path: Path) -> None:
    """The cell's Hypothesis machine passes on cell.yaml; on cell-buggy.yaml an invariant breaks."""
    for name, ok in (("cell.yaml", True), ("cell-buggy.yaml", False)):
        out = tmp_path / name.split(".")[0]
        code, said, err = cli("testgen", str(CELL_DIR / name), "--hypothesis", "--out", str(out))
        assert code == 0 and "_hypothesis.py" in said, err
        result = run_pytest(out)
        if ok:
            assert counts(result) == {"passed": 1}, result.stdout[-3000:]
        else:
            assert counts(result) == {"failed": 1}, result.stdout[-3000:]
            assert "invariant belt-still-while-arm-reaches broken" in result.stdout


def test_the_docs_cell_example_runs(tmp_path: Path) -> None:
    """docs/testing.md's hand-written statectl_cell test passes on the twins."""
    block = doc_block("The `statectl_cell` fixture serves hand-written tests too")
    rel = os.path.relpath(CELL, tmp_path)
    (tmp_path / "test_cell_by_hand.py").write_text(
        block.replace('"../examples/pick-and-place/cell.yaml"', repr(rel)), encoding="utf-8"
    )
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result) == {"passed": 1}


@pytest.mark.parametrize("flag", ["--xstate", "--graphwalker"])
def test_one_device_exports_refuse_a_cell(tmp_path: Path, flag: str) -> None:
    """--xstate and --graphwalker given a cell are a usage error naming what to give."""
    code, out, err = cli("testgen", str(CELL), flag, "--out", str(tmp_path))
    assert (code, out) == (2, "")
    assert "is a cell" in err and list(tmp_path.iterdir()) == []


def test_the_harness_asks_the_cells_model_whether_its_expressions_hold() -> None:
    """An input's `when` and an invariant are the compiled model's answer over the devices'
    states now (what the System enforces and verify explores), not an evaluator of its own."""
    c = CellUnderTest(load_cell_or_raise(CELL))
    assert ("sensor", "Part in") not in c.allowed()  # when: In('conveyor.Running')
    assert ("conveyor", "Start") in c.allowed()  # when: In('arm.Blocked') and In('gripper.Open')
    assert c.broken_invariants() == []
    c.step("conveyor", "Start")
    assert ("sensor", "Part in") in c.allowed()
    c.system.subjects["arm"].dispatch("Movement")  # the arm reaches while the belt runs
    assert c.broken_invariants() == ["belt-still-while-arm-reaches"]


def test_cell_step_fails_when_a_device_leaves_the_kernels_path() -> None:
    """CellUnderTest.step fails, naming the device, when a device is not where the kernel says."""
    c = CellUnderTest(load_cell_or_raise(CELL))
    c.step("conveyor", "Start")
    c.system.subjects["gripper"].post("Grip")  # behind the test's back: the gripper moves
    with pytest.raises(AssertionError, match=r"gripper: expected \['Open'\], it is in"):
        c.step("conveyor", "Stop")


# -- helpers of the device fixture ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("check", "fails"),
    [
        (lambda d: d.assert_state("Moving"), None),
        (lambda d: d.assert_state("Blocked"), r"expected the state \['Blocked'\]"),
        (lambda d: d.assert_called("Movement"), None),
        (lambda d: d.assert_called("Initialization"), r"call Initialization\(\)"),
    ],
)
def test_device_assert_helpers(check: Callable[[DeviceUnderTest], None], fails: str | None) -> None:
    """assert_state and assert_called pass on what the Motor did after Movement, fail otherwise."""
    d = DeviceUnderTest(load_chart(MOTOR))
    d.send("Movement")
    if fails is None:
        check(d)
    else:
        with pytest.raises(AssertionError, match=fails):
            check(d)


# -- guards over the event's own data -----------------------------------------------------------

#: A device whose guard reads the event's data (the kernel's spelling: ``_event['data']``).
JOG = """\
device: Jog
states:
  - {state: Idle, control: default, ignore: [Done]}
  - {state: Jogging, control: event trigger required, api: Jog(), ignore: [Jog]}
events:
  - {event: Jog, condition: the step is small enough, guard: "_event['data']['step'] <= 5",
     old: Idle, new: Jogging, kind: command, api: Jog}
  - {event: Done, condition: the step is done, old: Jogging, new: Idle, kind: completion,
     api: Jog}
"""


def test_guard_over_event_data_gets_data_for_both_outcomes(tmp_path: Path) -> None:
    """A guard on _event['data'] is taken with data that makes it true, and tested false."""
    tables = tmp_path / "jog.yaml"
    tables.write_text(JOG, encoding="utf-8")
    made = generate(tables, "rows", tmp_path / "gen")
    text = made.path.read_text(encoding="utf-8")
    true_case = next(c for c in made.suite.cases if c.name == "test_row_01_jog_idle_to_jogging")
    false_case = next(c for c in made.suite.cases if c.name.endswith("_guard_false"))
    assert (true_case.event_data, true_case.expect.unhandled) == ({"step": 5}, None)
    assert (false_case.event_data, false_case.expect.unhandled) == ({"step": 6}, "guard false")
    assert 'd.given(["Jog", {"step": 5}])' in text
    result = run_pytest(made.path.parent)
    assert result.returncode == 0, result.stdout[-3000:]
    # the same tests against tables whose guard is off by one: the row's true case fails
    tables.write_text(JOG.replace("<= 5", "< 5"), encoding="utf-8")
    result = run_pytest(made.path.parent)
    assert counts(result).get("failed", 0) >= 1, result.stdout[-3000:]
    assert "FAILED test_jog_rows.py::test_row_01_jog_idle_to_jogging " in result.stdout


# -- statectl_device("file", driver=...) and statectl_cell("file") --------------------------------


def test_the_docs_callable_fixtures_run(tmp_path: Path) -> None:
    """Without STATECTL_TABLES/CELL the fixtures are callables: the docs' example passes."""
    block = doc_block("### A device of any file, on any driver")
    module = block.replace('"../examples/motor/motor.yaml"', repr(os.path.relpath(MOTOR, tmp_path)))
    module = module.replace(
        '"../examples/pick-and-place/cell.yaml"', repr(os.path.relpath(CELL, tmp_path))
    )
    (tmp_path / "test_callables.py").write_text(module, encoding="utf-8")
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result) == {"passed": 2}


def test_a_device_used_without_tables_says_what_to_do(tmp_path: Path) -> None:
    """statectl_device.send in a module naming no tables fails saying how to name them."""
    (tmp_path / "test_no_tables.py").write_text(
        "def test_it(statectl_device):\n    statectl_device.send('Movement')\n", encoding="utf-8"
    )
    result = run_pytest(tmp_path)
    assert counts(result) == {"failed": 1}
    assert "names no STATECTL_TABLES" in result.stdout and "Traceback" not in result.stdout


def test_a_cell_that_does_not_load_is_exit_1_with_its_diagnostics(tmp_path: Path) -> None:
    """A cell naming a missing device file: exit 1, the cell file's line, nothing written."""
    cell = copy_cell(tmp_path / "cell", CELL.read_text(encoding="utf-8"))
    (cell.parent / "arm.yaml").unlink()
    code, out, err = cli("testgen", str(cell), "--out", str(tmp_path / "gen"))
    assert (code, out) == (1, "")
    assert "cell.yaml:" in err and "arm.yaml" in err and "Traceback" not in err
    assert not (tmp_path / "gen").exists()
