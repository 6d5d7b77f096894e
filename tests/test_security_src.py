"""A safe or null document reads a ``<script src>`` (read at load) only beside itself."""

from __future__ import annotations

from pathlib import Path

import pytest

from statectl.out.scxml import read_scxml
from statectl.out.scxml.xmltree import SCXML_NS


def _doc(datamodel: str, element: str) -> str:
    return (
        f'<scxml xmlns="{SCXML_NS}" version="1.0" datamodel="{datamodel}" initial="s">'
        f'<state id="s"><onentry>{element}</onentry></state></scxml>'
    )


@pytest.fixture
def layout(tmp_path: Path) -> Path:
    """doc/ with an inside file and a link out; a secret beside doc/."""
    (tmp_path / "secret.txt").write_text("x = 1", encoding="utf-8")
    doc = tmp_path / "doc"
    doc.mkdir()
    (doc / "inside.txt").write_text("x = 1", encoding="utf-8")
    (doc / "link.txt").symlink_to(tmp_path / "secret.txt")
    (doc / "sub").mkdir()
    return doc


def _read(doc: Path, datamodel: str, element: str) -> list[str]:
    _chart, diagnostics = read_scxml(_doc(datamodel, element), "d.scxml", str(doc))
    return [f"{d.code} {d.message}" for d in diagnostics]


@pytest.mark.parametrize("datamodel", ["safe", "null"])
@pytest.mark.parametrize(
    ("src", "why"),
    [
        ("../secret.txt", "steps out with '..'"),
        ("/etc/passwd", "is an absolute path"),
        ("file:///etc/passwd", "names a URL"),
        ("link.txt", "through a link"),
        ("sub", "is not a regular file"),
    ],
)
def test_an_untrusted_document_reads_nothing_outside(
    layout: Path, datamodel: str, src: str, why: str
) -> None:
    """Each way out of the document's directory is S607, naming why; nothing is read."""
    found = _read(layout, datamodel, f'<script src="{src}"/>')
    assert any(f.startswith("S607") and why in f for f in found), found


def test_a_file_beside_the_document_is_read(layout: Path) -> None:
    """Inside the directory, a regular file is read as before (no S607)."""
    found = _read(layout, "null", '<script src="inside.txt"/>')
    assert not [f for f in found if f.startswith("S607")], found


def test_a_trusted_document_reads_where_it_likes(layout: Path) -> None:
    """A python document was trusted by whoever ran it: its script may come from anywhere."""
    chart, diagnostics = read_scxml(
        _doc("python", '<script src="../secret.txt"/>'), "d.scxml", str(layout)
    )
    assert chart is not None, diagnostics
