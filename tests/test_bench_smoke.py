"""The dispatch benchmark runs: a short smoke run of statectl and the dict baseline.

No timing is asserted (figures depend on the machine); only that the script runs
and prints a row per scenario for each library asked for.
"""

from __future__ import annotations

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
        capture_output=True, text=True, timeout=300, cwd=ROOT, check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.mark.parametrize(
    "row",
    [
        "| Motor + 1 observer | statectl dispatch() |",
        "| Motor + 1 observer | statectl post()+run_until_idle() |",
        "| Motor + 1 observer | dict baseline |",
        "| 50 states, 2 levels | statectl dispatch() |",
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
