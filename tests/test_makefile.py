"""The quick start's ``make demo`` and ``make test`` install into a virtual environment.

A stock Debian/Ubuntu Python refuses ``pip install`` outside one (PEP 668), so the
Makefile makes the project's ``.venv`` or uses the one already active. Checked with
``make -n`` (what would run), so nothing is installed here.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAKE = shutil.which("make")
pytestmark = pytest.mark.skipif(MAKE is None, reason="make is not installed")


def dry_run(target: str, tmp: Path, **env: str) -> list[str]:
    """The commands ``make -n TARGET`` would run in a copy of the Makefile, without .venv."""
    shutil.copy(ROOT / "Makefile", tmp / "Makefile")
    (tmp / "pyproject.toml").write_text("", encoding="utf-8")
    clean = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    done = subprocess.run(
        [str(MAKE), "-n", target],
        cwd=tmp,
        capture_output=True,
        text=True,
        timeout=30,
        env={**clean, **env},
        check=True,
    )
    return done.stdout.splitlines()


@pytest.mark.parametrize("target", ["demo", "test"])
def test_without_an_active_venv_make_creates_and_uses_dot_venv(target: str, tmp_path: Path) -> None:
    """No active venv: .venv is made with python3 -m venv and every tool runs from it."""
    lines = dry_run(target, tmp_path)
    assert any("python3 -m venv .venv" in line for line in lines), lines
    pythons = [line.split()[0] for line in lines if " -m " in line and "-m venv" not in line]
    assert pythons and set(pythons) == {".venv/bin/python"}, lines


@pytest.mark.parametrize("target", ["demo", "test"])
def test_inside_an_active_venv_make_uses_it(target: str, tmp_path: Path) -> None:
    """An active venv ($VIRTUAL_ENV) is used as it is: no .venv is made, nothing else runs pip."""
    active = tmp_path / "active"
    (active / "bin").mkdir(parents=True)
    (active / "bin" / "python").touch()
    work = tmp_path / "work"
    work.mkdir()
    lines = dry_run(target, work, VIRTUAL_ENV=str(active))
    assert not any("-m venv" in line for line in lines), lines
    pythons = {line.split()[0] for line in lines if " -m " in line}
    assert pythons == {f"{active}/bin/python"}, lines


def test_make_docs_builds_the_site_strict_in_the_venv(tmp_path: Path) -> None:
    """`make docs` installs the dev tools (MkDocs among them) and builds with --strict."""
    lines = dry_run("docs", tmp_path)
    builds = [line for line in lines if "-m mkdocs build" in line]
    assert len(builds) == 1 and "--strict" in builds[0], lines
    assert ".venv/bin/python -m mkdocs" in builds[0], lines
