"""The dispatch benchmark runs: a short smoke run of statectl and the dict baseline.

No timing is asserted (figures depend on the machine); only that the script runs
and prints a row per scenario for each library asked for.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parent.parent
BENCH = ROOT / "bench" / "dispatch.py"


@pytest.fixture(scope="module")
def output() -> str:
    done = subprocess.run(
        [sys.executable, str(BENCH), "--quick", "--rounds", "1", "--libs", "statectl,dict"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.mark.parametrize(
    "row",
    [
        "| paper cycle | statectl bare dispatch() |",
        "| paper cycle | statectl bare + the same typed records built by hand (no engine) |",
        "| paper cycle | statectl + Moving monitor |",
        "| paper cycle | statectl wired as the demo (driver + monitor) |",
        "| paper cycle | statectl demo wiring + journal |",
        "| paper cycle | statectl demo wiring + trace |",
        "| paper cycle | statectl bare post()+run_until_idle() |",
        "| paper cycle | statectl demo wiring, clock still (no polls; completions dispatched) |",
        "| paper cycle | statectl cold: built from the file, motor connected, first cycle |",
        "| paper cycle | dict baseline |",
        "| 50 states, 2 levels | statectl dispatch() |",
        "| 50 states, 2 levels | statectl post()+run_until_idle() |",
        "| 50 states, 2 levels | dict baseline (flattened by hand) |",
        "| new started instance | statectl |",
        "| new started instance | dict |",
    ],
)
def test_quick_run_prints_the_row(output: str, row: str) -> None:
    """Each scenario of each chosen library has its row in the table."""
    assert any(line.startswith(row) for line in output.splitlines())


def test_quick_run_leaves_out_the_peers_not_asked_for(output: str) -> None:
    """--libs limits the run: no transitions row and no 'not installed' note."""
    assert "transitions" not in output.replace("transitions / this", "")
    assert "not installed" not in output


def test_quick_run_reports_the_worst_row_beside_the_best(output: str) -> None:
    """The summary names statectl's slowest wiring as well as its fastest."""
    lines = output.splitlines()
    assert any(line.startswith("statectl best: ") for line in lines)
    assert any(line.startswith("statectl worst: ") for line in lines)


def test_quick_run_reports_many_devices_on_one_system(output: str) -> None:
    """The System row counts every event it was fed as processed, in each run shown."""
    for line in _system_runs(output):
        fed = re.search(r"([0-9,]+) events processed", line)
        assert fed is not None, line
        assert int(fed[1].replace(",", "")) == 100 * 2 * 8  # devices x cycles x events


def _system_runs(output: str) -> list[str]:
    """The many-devices figure's worst and best runs (the lines under its heading)."""
    lines = output.splitlines()
    at = next(i for i, x in enumerate(lines) if "Motors on one System" in x)
    runs = lines[at + 1 : at + 3]
    assert [x.split(":")[0].strip() for x in runs] == ["worst", "best"], lines[at : at + 3]
    return runs


@pytest.mark.parametrize(
    ("code", "output", "stored", "finished"),
    [
        (0, "State-vector 40 byte\nerrors: 0\n4098 states, stored", 4098, True),
        (0, "pan: reached -DMEMLIM bound\nerrors: 0", 900, False),
        (0, "pan: out of memory", 900, False),
        (1, "", 4098, False),
        (0, "errors: 0", 0, False),
    ],
)
def test_verify_bench_refuses_an_unfinished_spin_search(
    code: int, output: str, stored: int, finished: bool
) -> None:
    """bench/verify.py gives no SPIN figure for a search that did not run to its end."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("verify_bench", ROOT / "bench" / "verify.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert (module._unfinished(code, output, stored) == "") is finished


def test_the_many_devices_line_says_its_threads_and_cpu(output: str) -> None:
    """Issue 26: the many-devices figure names its threads and gives CPU time per event."""
    line = next(x for x in output.splitlines() if "Motors on one System" in x)
    assert "(1 owner thread, 4 posting threads)" in line
    assert "each in a fresh process" in line
    for run in _system_runs(output):
        assert "ns/event of the process's CPU, all threads" in run


def test_the_by_hand_row_builds_the_records_a_step_listener_reads() -> None:
    """Rule 2d's floor is honest only if it builds what the engine gives: the same records,
    field for field, for each event of the cycle (its clock standing still, as in the row)."""
    sys.path.insert(0, str(BENCH.parent))
    try:
        import dispatch as bench
    finally:
        sys.path.remove(str(BENCH.parent))
    subject, _, _ = bench._motor_subject("by-hand")
    by_hand: list[tuple[object, ...]] = []
    bench._by_hand(subject, by_hand.append)()
    listened, _, _ = bench._motor_subject("bare")
    steps: list[object] = []
    listened.listen_steps(steps.append)
    for event in bench.MOTOR_CYCLE:
        listened.dispatch(event, bench.MOTOR_DATA.get(event))
    engine = [tuple(step.records) for step in steps]  # type: ignore[attr-defined]
    assert len(by_hand) == len(bench.MOTOR_CYCLE) == len(engine)
    assert by_hand == engine
    assert sum(map(len, by_hand)) == 24  # three a event: what docs/runtime.md counts


INSTRUCTIONS = ROOT / "bench" / "instructions.py"


def test_the_instruction_count_refuses_an_unknown_row() -> None:
    done = subprocess.run(
        [sys.executable, str(INSTRUCTIONS), "--rows", "bare,fast"],
        capture_output=True, text=True, timeout=60, cwd=ROOT, check=False,
    )  # fmt: skip
    assert done.returncode == 2 and "unknown rows ['fast']" in done.stdout, done


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
def test_the_instruction_count_gives_a_row_per_event() -> None:
    """20 cycles and 40 under valgrind: the bare row counts a positive figure, ratio 1."""
    done = subprocess.run(
        [sys.executable, str(INSTRUCTIONS), "--rows", "bare", "--cycles", "20"],
        capture_output=True, text=True, timeout=600, cwd=ROOT, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    row = re.search(r"^\| bare \| ([\d,]+) \| 1\.00 \|$", done.stdout, re.MULTILINE)
    assert row is not None and int(row.group(1).replace(",", "")) > 1000, done.stdout
