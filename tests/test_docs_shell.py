"""The tutorial's and the how-to guides' shell sessions run as written.

Rules (the ```python blocks of the same pages run in tests/test_docs_examples.py):

- every ```sh block of docs/tutorial.md and docs/howto/*.md runs, in page order, in one
  bash session per page (``set -euo pipefail``: a failing command fails the page), in a
  scratch directory where ``examples/`` is the repository's, with ``statectl`` and
  ``python`` on the PATH as a reader who installed statectl has them;
- a block whose first line is ``# shown, not run: REASON`` is not run (it needs root,
  hardware, Docker or runs until Ctrl-C); its reason must be given;
- a page whose blocks need an optional extra, a compiler or a PostgreSQL server that is
  not here is skipped, as the suite's own tests of that extra are. The PostgreSQL guide
  runs against a throwaway server (tests/pgserver.py) whose URL is ``$PG_URL``.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "docs" / "tutorial.md", *sorted((ROOT / "docs" / "howto").glob("*.md"))]
FENCE = re.compile(r"^```sh[^\n]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
SHOWN = "# shown, not run:"

#: What each page's run blocks need beyond statectl: modules, then commands.
NEEDS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "tutorial.md": ((), ("c++",)),
    "cia402.md": (("canopen", "can"), ()),
    "accept.md": (("canopen", "can", "hypothesis"), ()),
    "postgres.md": (("psycopg",), ("psql",)),
}


def blocks(page: Path) -> list[tuple[int, str]]:
    """``(line, code)`` of each ```sh block of ``page``, in order."""
    text = page.read_text(encoding="utf-8")
    return [(text.count("\n", 0, m.start()) + 2, m.group(1)) for m in FENCE.finditer(text)]


def script(page: Path) -> str:
    """The page's run blocks as one bash script; each says where it starts on stderr."""
    parts = ["set -euo pipefail"]
    for line, code in blocks(page):
        if not code.startswith(SHOWN):
            parts += [f"echo '--- {page.name}:{line}' >&2", code]
    return "\n".join(parts) + "\n"


def test_every_page_runs_a_block_and_says_why_a_block_is_not_run() -> None:
    """Each page has blocks that run; a block left out gives its reason."""
    assert PAGES[0].exists() and len(PAGES) >= 6
    for page in PAGES:
        found = blocks(page)
        assert any(not code.startswith(SHOWN) for _, code in found), page.name
        for line, code in found:
            first = code.splitlines()[0]
            assert not first.startswith(SHOWN) or len(first) > len(SHOWN) + 5, (page.name, line)


@pytest.fixture
def pg_url() -> Iterator[str]:
    """A throwaway PostgreSQL server's URL (tests/pgserver.py), or the test is skipped."""
    sys.path.insert(0, str(Path(__file__).parent))
    import pgserver

    why = pgserver.why_not()
    if why is not None:
        pytest.skip(why)
    server = pgserver.start()
    assert server is not None
    try:
        yield server.url
    finally:
        server.stop()


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_the_shell_session_runs(page: Path, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    """The page's shell blocks run in order and every command in them succeeds."""
    modules, tools = NEEDS.get(page.name, ((), ()))
    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    missing += [t for t in tools if shutil.which(t) is None]
    if missing:
        pytest.skip(f"{page.name} needs {', '.join(missing)}")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    if page.name == "postgres.md":
        env["PG_URL"] = request.getfixturevalue("pg_url")
    home = tmp_path / "home"
    home.mkdir()
    (home / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name, run in (("statectl", f"{sys.executable} -m statectl"), ("python", sys.executable)):
        (bin_dir / name).write_text(f'#!/bin/sh\nexec {run} "$@"\n', encoding="utf-8")
        (bin_dir / name).chmod(0o755)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    started = time.monotonic()
    done = subprocess.run(
        ["bash", "-c", script(page)],
        cwd=home,
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
        check=False,
    )
    assert done.returncode == 0, (
        f"{page.name} (after {time.monotonic() - started:.0f} s)\n"
        f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    )
