"""The W3C SCXML 1.0 conformance pack, run from ../shared (never copied into the repo).

The pack's runner starts ``statectl scxml run FILE --timeout T`` once per
document, the runner contract other tools rely on; the pass counts below are what
statectl reached, so a regression fails the test.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACK = ROOT.parent / "shared" / "conformance" / "w3c-scxml"

#: Tests that pass, per datamodel (the whole pack: python 119/119, null 25/25).
REACHED = {"python": 119, "null": 25}


@pytest.mark.skipif(not (PACK / "run.py").is_file(), reason=f"W3C pack not found at {PACK}")
@pytest.mark.parametrize("datamodel", sorted(REACHED))
def test_w3c_pack_pass_count_does_not_regress(datamodel: str) -> None:
    """Every W3C test statectl passed still passes, in both datamodels."""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    command = [
        sys.executable,
        "run.py",
        "--engine",
        f"{sys.executable} -m statectl scxml run {{file}} --timeout {{timeout}}",
        "--datamodel",
        datamodel,
        "--jobs",
        "4",
        "--exit-zero",
    ]
    done = subprocess.run(
        command, cwd=PACK, env=env, capture_output=True, text=True, timeout=600, check=False
    )
    summary = re.search(r"^(\d+) passed, (\d+) failed", done.stdout, re.MULTILINE)
    assert summary is not None, done.stdout[-2000:] + done.stderr[-2000:]
    passed = int(summary.group(1))
    assert passed >= REACHED[datamodel], done.stdout[-4000:]
