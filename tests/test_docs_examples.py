"""Documentation that runs: every ```python block in docs/ and the README is executed.

A block is run the way its reader would run it, in a scratch directory where
``examples/`` is the repository's (so ``examples/motor/motor.yaml`` and, from a
test module one directory down, ``../examples/...`` resolve as in the docs):

- a block with ``def test_...`` is a test module: pytest runs it (with the
  statectl plugin) and every test in it must pass;
- a block whose first line is ``# conftest.py for: statectl testgen ARGS`` is a
  conftest.py: that command writes its module, the block goes beside it, and
  every generated test must pass;
- any other block is a script: ``python block.py`` must exit 0.

A block that needs a service starts it itself (the OPC UA client starts
``statectl run --opcua``), so no block is a fragment. One that imports an optional
extra which is not installed (``asyncua``, ...) is skipped, as the suite's own tests
of that extra are.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [*sorted((ROOT / "docs").rglob("*.md")), ROOT / "README.md"]  # how-tos in docs/howto/
FENCE = re.compile(r"^```python[^\n]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
CONFTEST = re.compile(r"\A# conftest\.py for: statectl testgen (?P<args>[^\n]+)\n")
#: Optional extras (pyproject.toml) a block may import; without them it is skipped.
EXTRAS = ("asyncua", "aiohttp", "canopen", "can", "pymodbus", "psycopg", "hypothesis", "zenoh")


@dataclass(frozen=True)
class Block:
    """One ```python block: where it is, and its text."""

    doc: Path
    line: int
    code: str

    @property
    def kind(self) -> str:
        if CONFTEST.match(self.code):
            return "conftest"
        if re.search(r"^(async )?def test_", self.code, re.MULTILINE):
            return "pytest"
        return "script"

    @property
    def where(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"


def blocks() -> list[Block]:
    found = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            found.append(Block(doc, text.count("\n", 0, m.start()) + 2, m.group(1)))
    return found


BLOCKS = blocks()


def scratch(tmp: Path) -> Path:
    """A directory where ``examples/`` is the repository's."""
    (tmp / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    return tmp


def python(args: list[str], cwd: Path, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        check=False,
    )


def pytest_args(path: Path) -> list[str]:
    plugin = ["-p", "no:cacheprovider", "-p", "statectl.out.testgen.plugin"]
    return ["-m", "pytest", "-q", *plugin, str(path)]


def run_block(block: Block, tmp: Path) -> subprocess.CompletedProcess[str]:
    """Rule of the module docstring: run ``block`` as its kind says."""
    home = scratch(tmp)
    if block.kind == "script":
        script = home / "example.py"
        script.write_text(block.code, encoding="utf-8")
        return python([str(script)], home)
    if block.kind == "pytest":
        module = home / "docs" / "test_example.py"
        module.parent.mkdir()
        module.write_text(block.code, encoding="utf-8")
        return python(pytest_args(module), home)
    match = CONFTEST.match(block.code)
    assert match is not None
    generated = home / "generated"
    made = python(
        ["-m", "statectl", "testgen", *shlex.split(match["args"]), "--out", str(generated)],
        home,
    )
    assert made.returncode == 0, made.stderr
    (generated / "conftest.py").write_text(block.code, encoding="utf-8")
    return python(pytest_args(generated), home, timeout=600)


def test_the_docs_have_python_examples() -> None:
    """The collector finds the blocks (a changed fence would otherwise test nothing)."""
    assert len(BLOCKS) >= 20
    assert {b.kind for b in BLOCKS} == {"script", "pytest", "conftest"}


@pytest.mark.parametrize("block", BLOCKS, ids=[b.where for b in BLOCKS])
def test_python_example_runs(block: Block, tmp_path: Path) -> None:
    """The block is a complete example: it runs as written and (tests) every test passes."""
    for extra in EXTRAS:
        imports = re.search(rf"^\s*(from|import) {extra}\b", block.code, re.MULTILINE)
        if imports and importlib.util.find_spec(extra) is None:
            pytest.skip(f"{block.where} needs {extra} (an optional extra)")
    done = run_block(block, tmp_path)
    assert done.returncode == 0, f"{block.where}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    if block.kind != "script":
        assert re.search(r"\d+ passed", done.stdout), done.stdout[-2000:]
        assert not re.search(r"\d+ (failed|errors?)\b", done.stdout), done.stdout[-2000:]


def test_every_cell_code_has_its_own_entry() -> None:
    """Each V8xx code has a heading of its own in docs/cells.md with a fix, as C4xx codes do."""
    from statectl.kernel.codes import REGISTRY

    text = (ROOT / "docs" / "cells.md").read_text(encoding="utf-8")
    entries = dict(re.findall(r"^### (V8\d\d) — .*?\n(.*?)(?=^#)", text, re.MULTILINE | re.DOTALL))
    cell_codes = sorted(c for c in REGISTRY if c.startswith("V8"))
    assert cell_codes and sorted(entries) == cell_codes
    assert [c for c in cell_codes if "*Fix:*" not in entries[c]] == []
