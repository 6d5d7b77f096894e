"""statectl testgen for cells, the statectl_cell fixture, coverage as SVG, event-data guards.

docs/testing.md; the device-level parts are in tests/test_testgen.py.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from support import MOTOR
from test_testgen import cli, journal  # noqa: F401  # journal: a fixture used below

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
