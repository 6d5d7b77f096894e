"""`statectl tables --out DIR` names the file after the device in every format."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from statectl.channels.cli import main
from statectl.front.tables import load
from support import ROOT

CLAMP = ROOT / "examples" / "clamp" / "clamp.yaml"

WRITTEN = [
    ("yaml", ["Clamp.yaml"]),
    ("xlsx", ["Clamp.xlsx"]),
    ("md", ["Clamp.md"]),
    ("csv", ["Clamp.events.csv", "Clamp.states.csv"]),
]


@pytest.mark.parametrize(("fmt", "names"), WRITTEN)
def test_out_directory_gets_the_device_file(tmp_path: Path, fmt: str, names: list[str]) -> None:
    """--out an existing directory writes DEVICE.<format> there, which loads back whole."""
    out, err = io.StringIO(), io.StringIO()
    code = main(["tables", str(CLAMP), "--to", fmt, "--out", str(tmp_path)], out=out, err=err)
    assert code == 0, err.getvalue()
    assert sorted(p.name for p in tmp_path.iterdir()) == names
    tables, diags = load(tmp_path / names[-1])
    assert tables is not None and tables.device == "Clamp", diags


@pytest.mark.parametrize("extra", [[], ["--hypothesis"], ["--xstate"]])
def test_testgen_out_a_file_is_a_usage_error(tmp_path: Path, extra: list[str]) -> None:
    """testgen --out naming an existing file says it is not a directory (exit 2), file kept."""
    target = tmp_path / "notes.txt"
    target.write_text("mine\n", encoding="utf-8")
    out, err = io.StringIO(), io.StringIO()
    code = main(["testgen", str(CLAMP), "--out", str(target), *extra], out=out, err=err)
    assert code == 2
    assert "not a directory" in err.getvalue()
    assert target.read_text(encoding="utf-8") == "mine\n"


@pytest.mark.parametrize("fmt", ["yaml", "csv", "md", "xlsx"])
def test_a_device_name_cannot_write_outside_out_dir(tmp_path: Path, fmt: str) -> None:
    """A device named '../../evil' is written inside --out DIR, never beside or above it."""
    source = tmp_path / "src.yaml"
    source.write_text(
        CLAMP.read_text(encoding="utf-8").replace("device: Clamp", 'device: "../../evil"'),
        encoding="utf-8",
    )
    target = tmp_path / "a" / "b"
    target.mkdir(parents=True)
    out, err = io.StringIO(), io.StringIO()
    code = main(["tables", str(source), "--to", fmt, "--out", str(target)], out=out, err=err)
    assert code == 0, err.getvalue()
    outside = [p for p in tmp_path.rglob("*evil*") if target not in p.parents]
    assert outside == []
    assert any(target.iterdir())
