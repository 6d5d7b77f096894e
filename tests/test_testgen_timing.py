"""testgen writes a test per state timeout and per deferred event (docs/testing.md)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from statectl.front.builder.build import load_chart
from statectl.out.testgen import generate
from statectl.out.testgen.harness import DeviceUnderTest
from support import ROOT
from test_testgen import counts, functions, run_pytest

CLAMP = ROOT / "examples" / "clamp" / "clamp.yaml"

#: (name of the generated test, its tables edited so that only that test must fail)
MUTATIONS = [
    ("test_timeout_01_closing", ("timeout: 2s -> Close timeout", "timeout: 3s -> Close timeout")),
    ("test_defer_01_release_in_closing", ("defer: [Release]", "defer: []")),
]


def _generated(tmp_path: Path, text: str) -> tuple[Path, Path]:
    tables = tmp_path / "clamp.yaml"
    tables.write_text(text, encoding="utf-8")
    out = tmp_path / "tests"
    generate(tables, "rows", out)
    return tables, out


def test_rows_module_has_a_timeout_and_a_defer_case(tmp_path: Path) -> None:
    """The Clamp's rows module names Closing's timeout and its deferred Release."""
    _, out = _generated(tmp_path, CLAMP.read_text(encoding="utf-8"))
    found = functions(out / "test_clamp_rows.py")
    assert "2 s" in found["test_timeout_01_closing"]
    assert "Release sent in Closing is kept" in found["test_defer_01_release_in_closing"]


def test_generated_timing_tests_pass_on_the_twin(tmp_path: Path) -> None:
    """Every test of the Clamp's rows module passes on the simulated twin."""
    tables, out = _generated(tmp_path, CLAMP.read_text(encoding="utf-8"))
    probes = generate(tables, "rows", out).probes  # faults, completions (test_testgen_adapters)
    result = run_pytest(out)
    assert result.returncode == 0, result.stdout
    assert counts(result) == {"passed": 22 + probes}


@pytest.mark.parametrize(("test", "edit"), MUTATIONS)
def test_timing_test_fails_when_the_tables_change(
    tmp_path: Path, test: str, edit: tuple[str, str]
) -> None:
    """A module generated from the Clamp fails its timing test once the timeout or defer changes."""
    tables, out = _generated(tmp_path, CLAMP.read_text(encoding="utf-8"))
    text = CLAMP.read_text(encoding="utf-8")
    assert edit[0] in text
    tables.write_text(text.replace(edit[0], edit[1]), encoding="utf-8")
    result: subprocess.CompletedProcess[str] = run_pytest(out, "-k", test)
    assert counts(result).get("failed") == 1, result.stdout


def test_stall_drops_the_twins_completions() -> None:
    """After stall(), the twin's completion of Close is dropped, so Closing stays active."""
    d = DeviceUnderTest(load_chart(CLAMP))
    d.given("Close")
    d.stall()
    d.advance(1.5)
    assert d.states == ("Closing",)
    assert d.dropped == ["Closed"]
