"""bench/check.py runs: its generated inputs load, build and check clean (no timing asserted)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_small_run_prints_every_row(tmp_path: Path) -> None:
    """A small run prints a row per input and size, and the end-to-end check line."""
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "bench" / "check.py"),
            "--rows",
            "400",
            "--states",
            "300",
            "--keep",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    rows = [line.split("  ")[0] for line in done.stdout.splitlines()]
    for row in (
        "device, 1,000 rows",
        "device, 400 rows",
        "SCXML, 1,000 states",
        "SCXML, 300 states",
    ):
        assert row in rows, done.stdout
    assert "statectl check big400.yaml" in done.stdout
    device_rows = [line for line in done.stdout.splitlines() if line.startswith("device, ")]
    assert [line.split()[-1] for line in device_rows] == ["0", "0"]  # no diagnostics


def test_scale_run_prints_each_input_and_the_verdict(tmp_path: Path) -> None:
    """--scale runs statectl check end to end on the YAML, CSV and wide inputs, all clean."""
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "bench" / "check.py"),
            "--scale",
            "80",
            "--keep",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    for label in ("ring, 80 rows, YAML", "ring, 80 rows, CSV", "wide, 20 rows, YAML"):
        line = next((x for x in lines if x.startswith(label)), None)
        assert line is not None and "0 error(s)" in line and "target < 5 s" in line, done.stdout
