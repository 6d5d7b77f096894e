"""The stable API: every exported name resolves, and docs/api.md's examples run."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import statectl

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "api.md").read_text(), re.S)


@pytest.mark.parametrize("name", statectl.__all__)
def test_every_exported_name_resolves(name: str) -> None:
    """``statectl.NAME`` works for each name in ``__all__`` (lazy names included)."""
    assert getattr(statectl, name) is not None


def test_an_unknown_name_is_an_attribute_error() -> None:
    """A typo gets the usual AttributeError, naming the attribute."""
    with pytest.raises(AttributeError, match="no_such_thing"):
        _ = statectl.no_such_thing  # type: ignore[attr-defined]  # the point of the test


def test_the_docs_have_examples() -> None:
    """docs/api.md keeps its runnable examples (one device, errors, many devices)."""
    assert len(BLOCKS) >= 3


@pytest.mark.parametrize("block", BLOCKS, ids=lambda b: b.splitlines()[2][:40])
def test_docs_example_runs(block: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each python block of docs/api.md runs from the project root, its asserts holding."""
    monkeypatch.chdir(ROOT)
    exec(compile(block, "docs/api.md", "exec"), {})
