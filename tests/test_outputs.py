"""One rule for every output path (src/statectl/channels/cli/outputs.py).

Every writer makes missing parent directories, takes a path ending in a slash as a
directory (its file named as the command names it), and says ``wrote PATH`` for each
file; nothing is left behind when the write fails.
"""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from statectl.channels.cli import main
from statectl.channels.cli.outputs import output

ROOT = Path(__file__).resolve().parents[1]
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"
CELL = ROOT / "examples" / "pick-and-place" / "cell.yaml"
BUGGY = ROOT / "examples" / "pick-and-place" / "cell-buggy.yaml"

#: (argv with {tmp}, the files it must write under {tmp}, relative)
WRITERS = [
    (["render", str(MOTOR), "--out", "{tmp}/a/b/m.mmd"], ["a/b/m.mmd"]),
    (["render", str(MOTOR), "--format", "dot", "--out", "{tmp}/d/"], ["d/Motor.dot"]),
    (["tables", str(MOTOR), "--to", "md", "--out", "{tmp}/t/x.md"], ["t/x.md"]),
    (["tables", str(MOTOR), "--to", "yaml", "--out", "{tmp}/y/"], ["y/Motor.yaml"]),
    (
        ["tables", str(MOTOR), "--to", "csv", "--out", "{tmp}/newdir/"],
        ["newdir/Motor.events.csv", "newdir/Motor.recovery.csv", "newdir/Motor.states.csv"],
    ),
    (["scxml", "export", str(MOTOR), "--out", "{tmp}/s/m.scxml"], ["s/m.scxml"]),
    (["scxml", "export", str(MOTOR), "--out", "{tmp}/s/"], ["s/motor.scxml"]),
    (["verify", str(CELL), "--export", "promela", "-o", "{tmp}/p/c.pml"], ["p/c.pml"]),
    (["verify", str(CELL), "--export", "promela", "-o", "{tmp}/p/"], ["p/cell.pml"]),
    (["new", "Axis", "--profile", "motor", "--out", "{tmp}/n/e/w"], ["n/e/w/Axis.yaml"]),
    (["schema", "cell", "--out", "{tmp}/schemas/"], ["schemas/cell.schema.json"]),
]


@pytest.mark.parametrize(("argv", "files"), WRITERS, ids=[" ".join(w[0][:2]) for w in WRITERS])
def test_every_writer_makes_its_directories_and_says_wrote(
    argv: list[str], files: list[str], tmp_path: Path
) -> None:
    """Missing parents are made, a trailing slash is a directory, each file said once."""
    out, err = io.StringIO(), io.StringIO()
    code = main([a.format(tmp=tmp_path) for a in argv], out, err)
    assert code == 0, err.getvalue()
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*") if p.is_file())
    assert written == files
    said = sorted(
        str(Path(line.removeprefix("wrote ")).relative_to(tmp_path))
        for line in out.getvalue().splitlines()
        if line.startswith("wrote ")
    )
    assert said == files, out.getvalue()


def test_codegen_says_wrote_for_each_file(tmp_path: Path) -> None:
    """codegen printed bare paths; now ``wrote PATH`` as every other writer, dirs made."""
    out, err = io.StringIO(), io.StringIO()
    assert main(["codegen", str(MOTOR), "--out", str(tmp_path / "a" / "cpp")], out, err) == 0
    lines = out.getvalue().splitlines()
    assert lines and all(line.startswith("wrote ") for line in lines), lines
    assert (tmp_path / "a" / "cpp" / "motor.hpp").is_file()


def test_journal_export_makes_the_directory_and_says_wrote(tmp_path: Path) -> None:
    """journal export --out DIR/ writes DIR/NAME.jsonl; it said 'X is not a directory'."""
    db = tmp_path / "run.db"
    main(["run", str(MOTOR), "--journal", str(db)], io.StringIO(), io.StringIO())
    out, err = io.StringIO(), io.StringIO()
    code = main(["journal", "export", str(db), "--out", f"{tmp_path}/x/y/"], out, err)
    assert code == 0, err.getvalue()
    target = tmp_path / "x" / "y" / "run.jsonl"
    assert target.is_file() and out.getvalue().startswith(f"wrote {target}: "), out.getvalue()


def test_verify_traces_say_wrote_into_a_new_directory(tmp_path: Path) -> None:
    """verify --traces DIR makes DIR (and its parents) and says each file on stderr."""
    out, err = io.StringIO(), io.StringIO()
    main(["verify", str(BUGGY), "--traces", str(tmp_path / "t" / "r")], out, err)
    made = sorted(p.name for p in (tmp_path / "t" / "r").iterdir())
    said = [line for line in err.getvalue().splitlines() if line.startswith("wrote ")]
    assert made and len(said) == len(made), err.getvalue()


def test_a_failed_write_leaves_no_directory_behind(tmp_path: Path) -> None:
    """The directories made for a write that then fails are removed again (rule 3)."""
    with pytest.raises(OSError), output(str(tmp_path / "a" / "b" / "x.txt")) as target:
        assert target.parent.is_dir()
        raise OSError("the write failed")
    assert list(tmp_path.iterdir()) == []


def test_a_file_in_the_way_is_t110_and_nothing_is_made(tmp_path: Path) -> None:
    """A parent that is a file: T110 naming it, exit 1, nothing made beside it."""
    (tmp_path / "f").write_text("keep\n", encoding="utf-8")
    out, err = io.StringIO(), io.StringIO()
    code = main(["render", str(MOTOR), "--out", str(tmp_path / "f" / "sub" / "m.mmd")], out, err)
    assert (code, "T110" in err.getvalue()) == (1, True), err.getvalue()
    assert [p.name for p in tmp_path.iterdir()] == ["f"]
