"""statectl testgen, its pytest plugin and statectl coverage (docs/testing.md)."""

from __future__ import annotations

import ast
import io
import json
import math
import os
import re
import subprocess
import sys
import textwrap
import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

import statectl
from statectl.channels.cli import main
from statectl.kernel.model import Chart, Notify, StateKind
from statectl.out.testgen import Expect, Suite, generate
from support import MOTOR, ROOT

EXAMPLES = ROOT / "examples"
GANTRY = EXAMPLES / "gantry" / "gantry.yaml"
PICK = [EXAMPLES / "pick-and-place" / f"{n}.yaml" for n in ("arm", "conveyor", "gripper", "sensor")]
SRC = Path(statectl.__file__).resolve().parents[1]

#: A device whose guard reads the datamodel: testgen must find data for both outcomes.
GUARDED = """\
device: Press
data:
  limit: 3
states:
  - {state: Idle, control: default, ignore: [Done]}
  - {state: Pressing, control: event trigger required, api: Press(), ignore: [Press]}
events:
  - {event: Press, condition: the limit allows a stroke, guard: limit > 2, old: Idle,
     new: Pressing, kind: command, api: Press}
  - {event: Done, condition: the stroke is done, old: Pressing, new: Idle, kind: completion,
     api: Press}
"""


PLUGIN = ("-p", "statectl.out.testgen.plugin", "-p", "no:cacheprovider")


def run_pytest(directory: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """The generated tests in a fresh interpreter, with the plugin named explicitly.

    ``-p`` is a no-op once ``pip install`` has registered the plugin's entry point
    (which has the module's name), so this works installed or not.
    """
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", *PLUGIN, *args, str(directory)],
        cwd=directory,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def counts(result: subprocess.CompletedProcess[str]) -> dict[str, int]:
    found = re.findall(r"(\d+) (passed|failed|error|skipped)", result.stdout)
    return {kind: int(n) for n, kind in found}


def functions(path: Path) -> dict[str, str]:
    """Test function name -> docstring, read from a generated module."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {
        f.name: ast.get_docstring(f) or ""
        for f in tree.body
        if isinstance(f, ast.FunctionDef) and f.name.startswith("test_")
    }


def test_generated_modules_pass_against_the_twin(tmp_path: Path) -> None:
    """Every criterion's module for the Motor, the gantry and pick-and-place passes on the twin."""
    total = 0
    for file in (MOTOR, GANTRY, *PICK):
        for criterion in ("rows", "transitions", "states", "pairs"):
            made = generate(file, criterion, tmp_path)
            assert made.tests > 0, (file, criterion)
            total += made.tests + made.probes
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert counts(result) == {"passed": total}


def test_a_module_generated_from_name_csv_finds_its_pair(tmp_path: Path) -> None:
    """Generated from ``motor.csv`` (the CSV pair's name, no such file), the module's
    ``STATECTL_TABLES`` names it and the plugin loads the pair: every test passes."""
    pair = MOTOR.parent / "motor.csv"
    assert not pair.exists()
    made = generate(pair, "rows", tmp_path)
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result) == {"passed": made.tests + made.probes}


@pytest.mark.parametrize(
    ("name", "where"),
    [
        ("test_row_01_movement_blocked_to_moving", "Row 1, motor.yaml:35: Movement ["),
        ("test_row_02_movement_completion_moving_to_blocked", "motor.yaml:41"),
        ("test_row_03_initialization_blocked_to_returning", "Blocked -> Returning"),
        ("test_row_03_initialization_blocked_to_returning_guard_false", "is false here"),
        ("test_row_04_initialization_completion_returning_to_blocked", "motor.yaml:54"),
        ("test_row_05_error_moving_to_returning", "Error [error during Moving]"),
        ("test_row_06_error_completion_returning_to_blocked", "motor.yaml:66"),
        ("test_unhandled_in_moving", "In Moving, each event"),
    ],
)
def test_rows_module_names_each_row_in_the_papers_words(
    tmp_path: Path, name: str, where: str
) -> None:
    """The rows module has a test per Event Definition row whose docstring cites file:line."""
    made = generate(MOTOR, "rows", tmp_path)
    found = functions(made.path)
    assert name in found, sorted(found)
    assert where in " ".join(found[name].split())


def test_guard_over_data_gets_data_for_both_outcomes(tmp_path: Path) -> None:
    """A guard over the datamodel is tested true with the defaults and false with set data."""
    tables = tmp_path / "press.yaml"
    tables.write_text(GUARDED, encoding="utf-8")
    out = tmp_path / "gen"
    made = generate(tables, "rows", out)
    text = made.path.read_text(encoding="utf-8")
    false_case = text.split("def test_row_01_press_idle_to_pressing_guard_false")[0]
    assert "@pytest.mark.statectl_data(limit=2)" in false_case.rsplit("\n\n\n", 1)[-1]
    result = run_pytest(out)
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result) == {"passed": made.tests + made.probes}


def test_a_nan_data_value_is_written_as_code(tmp_path: Path) -> None:
    """Data that is nan is written as float('nan') (repr's nan is no literal): it imports."""
    tables = tmp_path / "d.yaml"
    tables.write_text(
        "device: D\ndata:\n  x: .nan\nstates:\n  - {state: A, control: default}\n"
        "  - {state: B, control: event trigger required}\nevents:\n"
        "  - {event: go, old: A, new: B, guard: x == x}\n  - {event: back, old: B, new: A}\n",
        encoding="utf-8",
    )
    made = generate(tables, "rows", tmp_path / "gen")
    text = made.path.read_text(encoding="utf-8")
    assert 'statectl_data(x=float("nan"))' in text
    exec(compile(text, str(made.path), "exec"), {"__name__": "generated"})  # no NameError


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1.5, -0.0])
def test_every_float_is_written_as_code_that_gives_it_back(value: float) -> None:
    """The generated module's float values evaluate to the same float, also nan and inf."""
    from statectl.out.testgen.writer import _lit

    back = eval(_lit(value), {})  # the text the module holds, as Python reads it
    assert repr(back) == repr(value)


#: Seeded driver bugs: (name, conftest body, what a failure must say).
BROKEN = [
    (
        "wrong API method",
        """
        class Broken(SimTwin):
            def log_call(self, function, *args):  # Movement() calls the Error API
                super().log_call("Error" if function == "Movement" else function, *args)
        """,
        "expected the API call Movement(), the driver called ['Broken.Error()']",
    ),
    (
        "a method that calls nothing",
        """
        class Broken(SimTwin):
            def update(self, notification):
                if notification.method != "Initialization":
                    super().update(notification)
        """,
        "Initialization(): the driver made no API call",
    ),
    (
        "a completion reported before the work is done",
        """
        class Broken(SimTwin):
            def update(self, notification):
                super().update(notification)
                if notification.method == "Movement":
                    self.report("Movement completion")  # at once, not on arrival
        """,
        "after Movement: state: expected ['Moving'], device is in ['Blocked']",
    ),
]


@pytest.mark.parametrize(("bug", "body", "message"), BROKEN, ids=[b[0] for b in BROKEN])
def test_generated_tests_fail_against_a_broken_driver(
    tmp_path: Path, bug: str, body: str, message: str
) -> None:
    """The Motor's rows tests, unchanged, fail when a conftest supplies a driver with a bug."""
    generate(MOTOR, "rows", tmp_path)
    conftest = "import pytest\nfrom statectl.run.devices import SimTwin\n"
    conftest += textwrap.dedent(body)
    conftest += (
        "\n\n@pytest.fixture\ndef statectl_driver(statectl_chart):\n"
        "    return Broken(statectl_chart)\n"
    )
    (tmp_path / "conftest.py").write_text(conftest, encoding="utf-8")
    result = run_pytest(tmp_path)
    assert result.returncode == 1, result.stdout[-3000:]
    assert counts(result).get("failed", 0) >= 1
    assert message in result.stdout, result.stdout[-3000:]


def doc_block(after: str) -> str:
    """The first fenced Python block of docs/testing.md after the heading ``after``."""
    text = (ROOT / "docs" / "testing.md").read_text(encoding="utf-8")
    return text.split(after, 1)[1].split("```python\n", 1)[1].split("```", 1)[0]


def test_the_docs_conftest_runs_the_tests_on_simmotor(tmp_path: Path) -> None:
    """docs/testing.md's conftest makes the same tests pass on the SimMotor driver."""
    made = generate(MOTOR, "rows", tmp_path)
    (tmp_path / "conftest.py").write_text(doc_block("### The same tests"), encoding="utf-8")
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result) == {"passed": made.tests + made.probes}


#: (device file, observer method served with another method's API)
WRONG_API = [(MOTOR, m) for m in ("Movement", "Initialization", "Error")] + [
    (GANTRY, m) for m in ("Start", "Pause", "EStop", "Reset")
]


@pytest.mark.parametrize(("file", "method"), WRONG_API, ids=[f"{f.stem}-{m}" for f, m in WRONG_API])
def test_rows_tests_catch_a_wrong_api_for_every_method(
    tmp_path: Path, file: Path, method: str
) -> None:
    """A driver serving one observer method with another's API fails the rows module."""
    generate(file, "rows", tmp_path)
    (tmp_path / "conftest.py").write_text(
        "import pytest\nfrom statectl.run.devices import SimTwin\n\n\n"
        "class Broken(SimTwin):\n"
        "    def log_call(self, function, *args):\n"
        f"        super().log_call('Wrong' if function == {method!r} else function, *args)\n"
        "\n\n@pytest.fixture\ndef statectl_driver(statectl_chart):\n"
        "    return Broken(statectl_chart)\n",
        encoding="utf-8",
    )
    result = run_pytest(tmp_path)
    assert result.returncode == 1, result.stdout[-3000:]
    assert f"{method}(): expected the API call {method}(), the driver called" in result.stdout


def test_docs_counts_are_what_testgen_writes(tmp_path: Path) -> None:
    """The table of test and event counts in docs/testing.md is what generate() gives."""
    text = (ROOT / "docs" / "testing.md").read_text(encoding="utf-8")
    groups = [[MOTOR], [GANTRY], PICK]
    for criterion in ("rows", "transitions", "states", "pairs"):
        line = next(x for x in text.splitlines() if x.startswith(f"| `{criterion}`"))
        shown = [tuple(map(int, re.findall(r"\d+", cell))) for cell in line.split("|")[3:6]]
        made = []
        for files in groups:
            runs = [generate(f, criterion, tmp_path) for f in files]
            made.append((sum(r.tests for r in runs), sum(r.steps for r in runs)))
        assert shown == made, criterion


def test_pyproject_registers_the_plugin() -> None:
    """The pytest11 entry point names the plugin module by its own name (so -p is a no-op)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    points = project["project"]["entry-points"]["pytest11"]
    assert points == {"statectl.out.testgen.plugin": "statectl.out.testgen.plugin"}


# -- the commands ----------------------------------------------------------------------------


def cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), out, err)
    return code, out.getvalue(), err.getvalue()


@pytest.mark.parametrize(
    ("argv", "code", "said"),
    [
        (["testgen", str(MOTOR), "--out", "{tmp}/gen"], 0, "wrote {tmp}/gen/test_motor_rows.py"),
        (["testgen", "{tmp}/nope.yaml", "--out", "{tmp}"], 2, "nope.yaml: no such file"),
        (["testgen", str(MOTOR), "--criterion", "paths", "--out", "{tmp}"], 2, "invalid choice"),
        (["testgen", str(MOTOR), "--out", "{tmp}/file.txt/x"], 1, "cannot write"),
        (["testgen", "{tmp}/bad.yaml", "--out", "{tmp}"], 1, "bad.yaml"),
        (["coverage", "{tmp}/none.db", str(MOTOR)], 2, "none.db: no such file"),
    ],
)
def test_cli_exit_codes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], code: int, said: str
) -> None:
    """testgen and coverage: 0 done, 1 bad input with a message, 2 usage; never a traceback."""
    (tmp_path / "file.txt").write_text("not a directory\n", encoding="utf-8")
    (tmp_path / "bad.yaml").write_text("device: X\nstates: 3\n", encoding="utf-8")
    args = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    got, out, err = cli(*args)
    err += capsys.readouterr().err  # argparse's usage errors go to sys.stderr
    assert got == code, (out, err)
    assert said.replace("{tmp}", str(tmp_path)) in out + err
    assert "Traceback" not in err
    assert not list(tmp_path.rglob(".*.tmp"))


@pytest.fixture(scope="module")
def journal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A Motor run journalled: Movement, completion, Initialization, completion."""
    db = tmp_path_factory.mktemp("cov") / "run.db"
    subprocess.run(
        [sys.executable, "-m", "statectl", "run", str(MOTOR), "--journal", str(db)],
        input="Movement {amount: 5}\n+2\nInitialization\n+2\n",
        env={**os.environ, "PYTHONPATH": str(SRC)},
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    return db


def test_coverage_lists_rows_never_taken(journal: Path) -> None:
    """The table counts rows, states and transitions; rows never taken are named by file:line."""
    code, out, _ = cli("coverage", str(journal), str(MOTOR))
    assert code == 0
    assert "rows 4 of 6 (66%), states 3 of 3 (100%), transitions 4 of 6 (66%)" in out
    never = out.split("rows never taken: 2\n")[1]
    assert never.splitlines() == [
        "  motor.yaml:60: row 5: Error [error during Moving]: Moving -> Returning",
        "  motor.yaml:66: row 6: Error completion [Returning after the error has been dealt "
        "with]: Returning -> Blocked",
    ]


def test_coverage_mermaid_highlights_taken_rows(journal: Path) -> None:
    """In the Mermaid diagram the taken rows are solid green, the others dashed red."""
    code, out, _ = cli("coverage", str(journal), str(MOTOR), "--format", "mermaid")
    assert code == 0
    styles = dict(re.findall(r"linkStyle (\d+) (\S+)", out))
    green = {n for n, s in styles.items() if s.startswith("stroke:#2a2")}
    assert green == {"0", "1", "2", "3"}
    assert '-->|"Error x0"|' in out


def test_coverage_of_a_chart_the_journal_never_ran(journal: Path) -> None:
    """A device file whose chart is not in the journal is bad input naming what is there."""
    code, _, err = cli("coverage", str(journal), str(GANTRY))
    assert code == 1
    assert "no device of chart 'Gantry' in the journal; devices journalled: Motor (Motor)" in err


# -- Hypothesis and GraphWalker ---------------------------------------------------------------


def test_hypothesis_module_passes_on_the_twin(tmp_path: Path) -> None:
    """The Hypothesis state machine of the Motor and the gantry passes on their twins."""
    for file in (MOTOR, GANTRY):
        code, _, err = cli("testgen", str(file), "--hypothesis", "--out", str(tmp_path))
        assert code == 0, err
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result) == {"passed": 2}


def test_hypothesis_module_shrinks_to_the_failing_event(tmp_path: Path) -> None:
    """Against a driver with a wrong API for Error, Hypothesis fails with Movement, then
    Error (sent, or raised by the monitor of a fault the device reported)."""
    cli("testgen", str(MOTOR), "--hypothesis", "--out", str(tmp_path))
    (tmp_path / "conftest.py").write_text(
        "import pytest\nfrom statectl.run.devices import SimTwin\n\n\n"
        "class Broken(SimTwin):\n"
        "    def log_call(self, function, *args):\n"
        "        super().log_call('Wrong' if function == 'Error' else function, *args)\n"
        "\n\n@pytest.fixture\ndef statectl_new_driver():\n    return Broken\n",
        encoding="utf-8",
    )
    result = run_pytest(tmp_path)
    assert result.returncode == 1, result.stdout[-3000:]
    said = r"after Movement -> (Error|\(device fault in Moving: Error by 0\.1 s\)): "
    assert re.search(said + r".*expected .*Error\(\).*Broken\.Wrong\(\)", result.stdout)


@pytest.mark.parametrize(("file", "vertices", "edges"), [(MOTOR, 3, 6), (GANTRY, 6, 19)])
def test_graphwalker_model_is_the_state_graph(
    tmp_path: Path, file: Path, vertices: int, edges: int
) -> None:
    """The GraphWalker model has a vertex per configuration and an edge per handled event."""
    code, out, err = cli("testgen", str(file), "--graphwalker", "--out", str(tmp_path))
    assert code == 0, err
    path = Path(out.split("wrote ", 1)[1].strip())
    model = json.loads(path.read_text(encoding="utf-8"))["models"][0]
    ids = {v["id"] for v in model["vertices"]}
    assert len(ids) == vertices
    start, *rest = model["edges"]
    assert model["startElementId"] == start["id"] and "sourceVertexId" not in start
    assert start["name"] == "e__start"  # no event's name reduces to it (leading _ stripped)
    assert len(rest) == edges
    assert all(e["sourceVertexId"] in ids and e["targetVertexId"] in ids for e in rest)
    assert all(e["name"].startswith("e_") and e["properties"]["rows"] for e in rest)


#: A row from a state nothing enters: the search can never take it.
UNREACHABLE = """\
device: Lamp
states:
  - {state: Off, control: default, api: Switch(), ignore: [Reset]}
  - {state: On, control: event trigger required, api: Switch(), ignore: [Switch, Reset]}
  - {state: Broken, control: event trigger required, api: Switch(), ignore: [Switch]}
events:
  - {event: Switch, condition: the operator turns it on, old: Off, new: On, kind: command,
     api: Switch}
  - {event: Reset, condition: the lamp was replaced, old: Broken, new: Off, kind: command,
     api: Switch}
"""


def test_a_row_never_reachable_is_a_skipped_test_saying_so(tmp_path: Path) -> None:
    """A row the search cannot take becomes a skipped test and a note, not a silent gap."""
    tables = tmp_path / "lamp.yaml"
    tables.write_text(UNREACHABLE, encoding="utf-8")
    code, out, err = cli("testgen", str(tables), "--out", str(tmp_path / "gen"))
    assert code == 0, err
    assert "note: row 2 (lamp.yaml:9) is never taken" in out
    result = run_pytest(tmp_path / "gen", "-rs")
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result)["skipped"] == 1
    assert "the search from the default state never takes this row" in result.stdout


def test_coverage_reports_steps_the_tables_disagree_with(journal: Path, tmp_path: Path) -> None:
    """A journal of other tables (Movement now goes to Returning) is listed and exits 1."""
    changed = tmp_path / "motor.yaml"
    text = MOTOR.read_text(encoding="utf-8")
    changed.write_text(
        text.replace("old: Blocked\n    new: Moving", "old: Blocked\n    new: Returning"),
        encoding="utf-8",
    )
    code, out, _ = cli("coverage", str(journal), str(changed))
    assert code == 1
    assert "steps that disagree with the tables: " in out
    assert "(Motor): Movement: the run has ['Moving'], the tables give ['Returning']" in out


def test_the_docs_hand_written_module_runs(tmp_path: Path) -> None:
    """docs/testing.md's hand-written test passes on the twin, strict marker and all."""
    block = doc_block("### Tests written by hand")
    rel = os.path.relpath(MOTOR, tmp_path)
    (tmp_path / "test_by_hand.py").write_text(
        block.replace('"../examples/motor/motor.yaml"', repr(rel)), encoding="utf-8"
    )
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result) == {"passed": 1}


def test_strict_fails_an_event_the_tables_neither_handle_nor_ignore(tmp_path: Path) -> None:
    """With strict, a missed state x event pair fails naming both; without, it is ignored."""
    from statectl.front.builder.build import load_chart
    from statectl.out.testgen import DeviceUnderTest

    tables = tmp_path / "motor.yaml"
    text = MOTOR.read_text(encoding="utf-8")
    kept = "ignore: [Movement completion, Initialization, Initialization completion, Error"
    assert kept + ", Error completion]\n" in text
    tables.write_text(text.replace(kept + ", Error completion]\n", kept + "]\n"), encoding="utf-8")
    chart = load_chart(tables)
    lenient = DeviceUnderTest(chart)
    lenient.send("Error completion")
    lenient.expect(states=["Blocked"], unhandled="no transition")
    strict = DeviceUnderTest(chart, strict=True)
    with pytest.raises(AssertionError, match=r"Error completion in \['Blocked'\] is a pair"):
        strict.send("Error completion")


# -- the rows set kills every seeded wrong transition ----------------------------------------


def run_suite(suite: Suite, chart: Chart) -> int:
    """How many of the suite's tests fail on a device running ``chart`` (the twin)."""
    from statectl.out.testgen import DeviceUnderTest

    failed = 0

    def sent(given: tuple[str, ...], data: tuple[object, ...]) -> list[object]:
        return [e if i >= len(data) else [e, data[i]] for i, e in enumerate(given)]

    checks = [
        (c.data, sent(c.given, c.given_data), c.event, c.event_data, c.expect)
        for c in suite.cases
        if not c.skip
    ]
    for t in suite.tables:
        given = sent(t.given, t.given_data)
        checks += [(t.data, given, e, None, Expect(t.states, (), r)) for e, r in t.all_rows()]
    for data, steps, event, event_data, expect in checks:
        try:
            d = DeviceUnderTest(chart, data=dict(data) or None)
            d.given(*steps)  # type: ignore[arg-type]  # str or [event, data]
            if event is not None:
                d.send(event, event_data)
            d.expect(states=expect.states, invokes=expect.invokes, unhandled=expect.unhandled)
        except AssertionError:
            failed += 1
    return failed


def mutants(chart: Chart) -> list[tuple[str, Chart]]:
    """Each row retargeted to every other leaf state, deleted, unguarded, or silenced."""
    leaves = [s.name for s in chart.states if s.kind is StateKind.ATOMIC]
    out = []
    for i, t in enumerate(chart.transitions):
        others = chart.transitions[:i], chart.transitions[i + 1 :]
        variants = [(f"row {i + 1} to {x}", replace(t, targets=(x,))) for x in leaves]
        variants = [(n, v) for n, v in variants if v.targets != t.targets]
        if t.guard:
            variants.append((f"row {i + 1} unguarded", replace(t, guard=None)))
        if any(isinstance(a, Notify) for a in t.actions):
            silent = tuple(a for a in t.actions if not isinstance(a, Notify))
            variants.append((f"row {i + 1} silent", replace(t, actions=silent)))
        for name, v in variants:
            out.append((name, replace(chart, transitions=(*others[0], v, *others[1]))))
        out.append((f"row {i + 1} deleted", replace(chart, transitions=others[0] + others[1])))
    return out


def behaviour(chart: Chart) -> set[tuple[object, ...]]:
    """What a device running ``chart`` shows: every explored edge's states, invokes, reason.

    A mutant with the same behaviour as the original is equivalent (entering Traversing
    enters the whole parallel Cycle, as entering Cycle does): no test can tell them apart.
    """
    from statectl.out.testgen.paths import explore, leaves, notifies

    g = explore(chart)
    return {
        (
            leaves(chart, e.source.snapshot),
            e.event,
            leaves(chart, e.step.target),
            tuple((n.invoke, n.method) for n in notifies(e.step)),
            e.step.unhandled,
        )
        for e in g.edges
    }


#: (device, criterion, the seeded bugs its set cannot see). The rows set takes row 6
#: (Continue: Paused -> the deep history Resume) once per configuration the history
#: resumes, so a Continue that always goes to Idle fails it too.
KILLS = [
    (MOTOR, "rows", []),
    (GANTRY, "rows", []),
    (GANTRY, "transitions", []),
]


@pytest.mark.parametrize(
    ("file", "criterion", "missed"), KILLS, ids=[f"{f.stem}-{c}" for f, c, _ in KILLS]
)
def test_generated_set_fails_for_every_seeded_wrong_transition(
    file: Path, criterion: str, missed: list[str]
) -> None:
    """Generated from the right tables, the set fails on every non-equivalent mutant."""
    from statectl.front.builder.build import load_chart
    from statectl.out.testgen import cases_for, explore

    chart = load_chart(file)
    suite = cases_for(explore(chart), criterion)
    assert run_suite(suite, chart) == 0
    seeded = mutants(chart)
    assert len(seeded) >= 3 * len(chart.transitions)
    distinct = [(n, m) for n, m in seeded if behaviour(m) != behaviour(chart)]
    assert len(seeded) - len(distinct) <= 3  # the gantry's Start/Reset into a default child
    survivors = [name for name, mutant in distinct if run_suite(suite, mutant) == 0]
    assert survivors == missed


def test_tables_that_no_longer_load_fail_the_module_with_their_diagnostics(
    tmp_path: Path,
) -> None:
    """Generated tests whose tables were broken since fail with the diagnostics, no traceback."""
    tables = tmp_path / "motor.yaml"
    tables.write_text(MOTOR.read_text(encoding="utf-8"), encoding="utf-8")
    generate(tables, "states", tmp_path / "gen")
    tables.write_text("device: Motor\nstates: 3\n", encoding="utf-8")
    result = run_pytest(tmp_path / "gen")
    assert result.returncode == 1, result.stdout[-3000:]
    assert "does not load:" in result.stdout and "motor.yaml:2: T108" in result.stdout
    assert "Traceback" not in result.stdout and "During handling" not in result.stdout


def test_xstate_config_keeps_the_gantry_structure(tmp_path: Path) -> None:
    """The XState config has the gantry's hierarchy, parallel, final, history and rows."""
    code, out, err = cli("testgen", str(GANTRY), "--xstate", "--out", str(tmp_path))
    assert code == 0, err
    config = json.loads(Path(out.split("wrote ", 1)[1].strip()).read_text(encoding="utf-8"))
    running = config["states"]["Running"]
    cycle = running["states"]["Cycle"]
    cases = [
        (config["initial"], "Running"),
        (running["initial"], "Idle"),
        (cycle["type"], "parallel"),
        (cycle["states"]["Axis"]["states"]["AtTarget"]["type"], "final"),
        (running["states"]["Resume"], {"id": "Resume", "type": "history", "history": "deep",
                                       "target": "#Idle"}),
        (cycle["onDone"][0]["target"], "#Idle"),
        (running["states"]["Idle"]["on"]["Start"][0]["target"], "#Cycle"),
        (running["states"]["Idle"]["on"]["Start"][0]["actions"], ["Start"]),
        (config["states"]["Paused"]["on"]["Continue"][0]["target"], "#Resume"),
        ([t["meta"]["row"] for t in running["on"]["EStop"]], ["gantry.yaml:115"]),
    ]  # fmt: skip
    for got, expected in cases:
        assert got == expected


@pytest.mark.parametrize(
    ("criterion", "summary", "never"),
    [
        ("rows", "rows 6 of 6 (100%), states 3 of 3 (100%), transitions 6 of 6 (100%)", 0),
        ("states", "rows 2 of 6 (33%), states 3 of 3 (100%), transitions 2 of 6 (33%)", 4),
    ],
)
def test_coverage_of_a_test_run(tmp_path: Path, criterion: str, summary: str, never: int) -> None:
    """pytest --statectl-coverage writes what the tests exercised; coverage reads it (the
    criterion's own tests: the probes through the implementation take every row)."""
    generate(MOTOR, criterion, tmp_path)
    probes = "not (test_fault or test_monitor or test_completion_ or test_recovery)"
    result = run_pytest(tmp_path, "--statectl-coverage", str(tmp_path / "cov.json"), "-k", probes)
    assert result.returncode == 0, result.stdout[-3000:]
    code, out, err = cli("coverage", str(tmp_path / "cov.json"), str(MOTOR))
    assert code == 0, err
    assert summary in out
    assert f"rows never taken: {never or 'none'}\n" in out


def test_coverage_file_of_other_tables_is_refused(tmp_path: Path) -> None:
    """A test run's coverage of another chart is bad input naming what the file has."""
    (tmp_path / "cov.json").write_text('{"statectl_coverage": 1, "charts": {}}', encoding="utf-8")
    (tmp_path / "junk.json").write_text("[1, 2]", encoding="utf-8")
    code, _, err = cli("coverage", str(tmp_path / "cov.json"), str(MOTOR))
    assert code == 1
    assert "no chart 'Motor' in this test run's coverage; it has: none" in err
    code, _, err = cli("coverage", str(tmp_path / "junk.json"), str(MOTOR))
    assert code == 1
    assert "not a coverage file written by pytest --statectl-coverage" in err


def test_public_names_resolve() -> None:
    """Every name in statectl.out.testgen.__all__ is importable through the lazy package."""
    import statectl.out.testgen as tg

    assert [n for n in tg.__all__ if getattr(tg, n, None) is None] == []
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = tg.nope  # type: ignore[attr-defined]


CIA402_CONFTEST = '''
import pytest

from statectl.run.devices import make_driver


@pytest.fixture
def statectl_driver(statectl_chart):
    """The Motor's tests on a CiA 402 drive: the simulated one, on python-can's virtual bus."""
    return make_driver("cia402-sim", {}, chart=statectl_chart)


@pytest.fixture
def statectl_event_data():
    return {"Movement": {"amount": 5.0}}
'''


def test_generated_tests_run_on_the_cia402_simulated_drive(tmp_path: Path) -> None:
    """The Motor's row tests, unchanged, pass against a drive that speaks real CANopen."""
    pytest.importorskip("canopen")
    pytest.importorskip("can")
    main(["testgen", str(MOTOR), "--criterion", "rows", "--out", str(tmp_path)])
    (tmp_path / "conftest.py").write_text(CIA402_CONFTEST, encoding="utf-8")
    result = run_pytest(tmp_path)
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result).get("passed", 0) >= 20


def test_a_generated_modules_notes_are_lines_of_its_docstring(tmp_path: Path) -> None:
    """A note (the clamp's completion taken only with the device's data) reads as a line
    of the module's docstring, not as an escaped ``\\n\\nNote:`` in one long line."""
    made = generate(ROOT / "examples" / "modbus" / "clamp.yaml", "rows", tmp_path)
    text = made.path.read_text(encoding="utf-8")
    docstring = ast.get_docstring(ast.parse(text)) or ""
    assert "\nNote: Clamp() called by Clamp: Clamp completion is taken only" in docstring
    assert "\\n" not in text.split('"""')[1]
