"""The docs site builds with ``mkdocs build --strict``: no broken link or anchor, every
page in the nav, and the reference pages generated from the code (tools/mkdocs_hooks.py).

Skipped when MkDocs is not installed (the ``docs`` extra; ``make test`` installs it with
``dev``). One build, into a temporary directory, for the whole module.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NEEDED = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python")
pytestmark = pytest.mark.skipif(
    any(importlib.util.find_spec(m.split(".")[0]) is None for m in NEEDED),
    reason="MkDocs, Material or mkdocstrings is not installed (the docs extra)",
)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONPATH": os.pathsep.join(sys.path)},
        check=False,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    yield out


def test_the_site_builds_strict_with_every_page(site: Path) -> None:
    """--strict passed (no broken link, anchor or page left out of the nav)."""
    pages = {p.relative_to(ROOT / "docs").with_suffix("") for p in (ROOT / "docs").rglob("*.md")}
    built = {p.parent.relative_to(site) for p in site.rglob("index.html")}
    assert {p for p in pages if p.name != "index"} <= built


def test_every_diagnostic_code_is_on_the_codes_page(site: Path) -> None:
    """The codes page is the registry: every code, none missing, none invented."""
    from statectl.kernel.codes import REGISTRY

    html = (site / "reference" / "codes" / "index.html").read_text(encoding="utf-8")
    assert set(re.findall(r"<code>([A-Z]\d{3})</code>", html)) == set(REGISTRY)


def test_every_command_is_on_the_cli_page(site: Path) -> None:
    """The command-line page is the parser: every subcommand has its section."""
    from statectl.channels.cli import build_parser

    html = (site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    parser = build_parser()
    commands = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    assert commands.choices
    assert [c for c in commands.choices if f"<code>statectl {c}" not in html] == []


def test_every_api_name_is_documented_from_its_docstring(site: Path) -> None:
    """Each name of statectl.__all__ has a heading on the Python API reference page."""
    import statectl

    html = (site / "reference" / "python" / "index.html").read_text(encoding="utf-8")
    names = [n for n in statectl.__all__ if not n.startswith("_")]
    assert [n for n in names if not re.search(rf'id="[\w.]*\.{n}"', html)] == []
