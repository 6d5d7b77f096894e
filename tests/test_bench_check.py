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
