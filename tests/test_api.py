"""The stable API: every exported name resolves, and the docs' Python examples run."""

from __future__ import annotations

import contextlib
import inspect
import io
import json
import pydoc
import re
import typing
from pathlib import Path

import pytest

import statectl

ROOT = Path(__file__).resolve().parents[1]
#: pages whose ```python blocks are runnable examples
PAGES = ("api.md", "runtime.md")
BLOCKS = [
    (page, block)
    for page in PAGES
    for block in re.findall(r"```python\n(.*?)```", (ROOT / "docs" / page).read_text(), re.S)
]


@pytest.mark.parametrize("name", statectl.__all__)
def test_every_exported_name_resolves(name: str) -> None:
    """``statectl.NAME`` works for each name in ``__all__`` (lazy names included)."""
    assert getattr(statectl, name) is not None


@pytest.mark.parametrize(
    "name", [n for n in statectl.__all__ if isinstance(getattr(statectl, n), type)]
)
def test_every_exported_class_shows_its_signature(name: str) -> None:
    """``help()`` and ``inspect.signature`` work on each exported class: the types its
    fields are annotated with resolve at run time (a forward reference once did not)."""
    cls = getattr(statectl, name)
    with contextlib.suppress(ValueError):  # a class with no Python-visible signature
        inspect.signature(cls)
    typing.get_type_hints(cls)
    assert name in pydoc.render_doc(cls)


def test_every_exported_name_is_documented() -> None:
    """docs/api.md names each exported name: the stable API is "the names below"."""
    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    named = set(re.findall(r"`([A-Za-z_]\w*)", text))
    assert [n for n in statectl.__all__ if n != "__version__" and n not in named] == []


def test_an_unknown_name_is_an_attribute_error() -> None:
    """A typo gets the usual AttributeError, naming the attribute."""
    with pytest.raises(AttributeError, match="no_such_thing"):
        _ = statectl.no_such_thing  # type: ignore[attr-defined]  # the point of the test


def test_the_docs_have_examples() -> None:
    """docs/api.md keeps its runnable examples (one device, errors, many devices)."""
    assert len([b for page, b in BLOCKS if page == "api.md"]) >= 3


@pytest.mark.parametrize(
    ("page", "block"), BLOCKS, ids=[f"{p}:{i}" for i, (p, _) in enumerate(BLOCKS)]
)
def test_docs_example_runs(page: str, block: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each python block of the pages runs from the project root, its asserts holding."""
    monkeypatch.chdir(ROOT)
    exec(compile(block, f"docs/{page}", "exec"), {})


@pytest.mark.parametrize(
    ("path", "codes"),
    [
        ("examples/motor/motor.yaml", []),
        ("examples/clamp/cell.yaml", ["C415"]),  # a cell: use verify
        ("examples/motor/drivers.yaml", ["C415"]),  # a run config: use run --config
    ],
)
def test_check_reports_what_statectl_check_prints(path: str, codes: list[str]) -> None:
    """``statectl.check`` gives the command's diagnostics: C415 for a cell or run config."""
    from statectl.channels.cli import main

    out = io.StringIO()
    main(["check", "--json", "-v", str(ROOT / path)], out, io.StringIO())
    printed = [d["code"] for d in json.loads(out.getvalue())]
    assert [d.code for d in statectl.check(ROOT / path)] == printed == codes
