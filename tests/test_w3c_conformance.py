"""The W3C SCXML 1.0 conformance pack, run in place (never copied into the repo).

The pack's runner starts ``statectl scxml run FILE --timeout T`` once per
document, the runner contract other tools rely on; the pass counts below are what
statectl reached, so a regression fails the test. The pack is read from
``$STATECTL_W3C_DIR``, else ``../shared/conformance/w3c-scxml`` beside the clone;
when it is absent the summary at the end of the run says the claim was not tested.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from support import W3C_PACK, W3C_SKIPPED

ROOT = Path(__file__).resolve().parents[1]
PACK = W3C_PACK

#: Tests that pass, per datamodel (the whole pack: python 119/119, null 25/25).
REACHED = {"python": 119, "null": 25}


@pytest.mark.skipif(not (PACK / "run.py").is_file(), reason=W3C_SKIPPED)
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


def test_summary_says_when_the_pack_was_not_tested(tmp_path: Path) -> None:
    """A run without the pack ends with a line saying the claim was not tested, and how to."""
    absent = tmp_path / "no-pack"
    env = dict(os.environ, STATECTL_W3C_DIR=str(absent), PYTHONPATH=os.pathsep.join(sys.path))
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", __file__, "-k", "regress"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stdout[-2000:]
    assert f"W3C conformance pack NOT tested (2 test(s) skipped): no pack at {absent}" in (
        done.stdout
    ), done.stdout[-2000:]
    assert "set STATECTL_W3C_DIR" in done.stdout
