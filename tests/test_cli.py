"""The command line: thin wrappers with distinct exit codes (0 ok, 1 problems, 2 usage)."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import pytest

from statectl.channels.cli import main

ROOT = Path(__file__).resolve().parents[1]
MOTOR = str(ROOT / "examples" / "motor" / "motor.yaml")
GRIPPER = str(ROOT / "examples" / "pick-and-place" / "gripper.yaml")


def cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), out, err)
    return code, out.getvalue(), err.getvalue()


BROKEN = """device: Motor
states:
  - {state: Blocked, control: default}
events:
  - {event: Go, old: Blocked, new: Nowhere}
  - {event: Back, old: Blocked, new: Blocked, guard: "__import__('os')"}
"""


@pytest.mark.parametrize(
    ("argv", "code"),
    [
        (["check", MOTOR], 0),
        (["check", "--strict", MOTOR], 0),  # no warnings either
        (["check", "--strict", GRIPPER], 1),  # C404: Open neither handles nor ignores Release
        (["check", "no-such-file.yaml"], 2),
        (["frobnicate"], 2),
        ([], 2),
        (["render", MOTOR, "--format", "gif"], 2),
        (["tables", MOTOR, "--to", "csv"], 2),  # writes files: needs --out
    ],
)
def test_exit_codes(argv: list[str], code: int) -> None:
    """Each command returns 0 on success, 1 on problems found, 2 on usage errors."""
    assert cli(*argv)[0] == code


def test_check_reports_every_problem_with_lines(tmp_path: Path) -> None:
    """check prints all diagnostics as file:line: CODE severity: message, and exits 1."""
    bad = tmp_path / "bad.yaml"
    bad.write_text(BROKEN, encoding="utf-8")
    code, out, _ = cli("check", str(bad))
    assert code == 1
    lines = [ln for ln in out.splitlines() if re.match(r".+:\d+: [A-Z]\d{3} (error|warning)", ln)]
    codes = {ln.split(": ")[1].split()[0] for ln in lines}
    assert {"B201", "X302"} <= codes, out
    assert "Traceback" not in out


def test_check_json_is_machine_readable(tmp_path: Path) -> None:
    """--json prints a list of diagnostics with code, severity, file and line."""
    bad = tmp_path / "bad.yaml"
    bad.write_text(BROKEN, encoding="utf-8")
    code, out, _ = cli("check", "--json", str(bad))
    data = json.loads(out)
    assert code == 1
    assert all({"code", "severity", "file", "line", "message", "hint"} <= d.keys() for d in data)
    assert any(d["code"] == "B201" and d["line"] == 5 for d in data)


def test_observers_prints_the_invoke_enumeration() -> None:
    """observers shows the paper's three invokes mapped to the three observer methods."""
    code, out, _ = cli("observers", MOTOR)
    assert code == 0
    for line in ("Moving = 0", "Returning = 1", "Error = 2"):
        assert line in out
    for method in ("Movement()", "Initialization()", "Error()"):
        assert method in out
    assert "Moving: raises Error" in out


def test_observers_json() -> None:
    """observers --json lists invokes and which events each observer method covers."""
    code, out, _ = cli("observers", "--json", MOTOR)
    data = json.loads(out)
    assert code == 0
    assert [(i["number"], i["name"], i["method"]) for i in data["invokes"]] == [
        (0, "Moving", "Movement"),
        (1, "Returning", "Initialization"),
        (2, "Error", "Error"),
    ]
    covered = sorted(e for o in data["observers"] for e in o["events"])
    assert len(covered) == 6


def test_render_writes_file_atomically(tmp_path: Path) -> None:
    """render --out writes the diagram and nothing else next to it."""
    target = tmp_path / "motor.mmd"
    code, _, _ = cli("render", MOTOR, "--format", "mermaid", "--out", str(target))
    assert code == 0
    assert "stateDiagram" in target.read_text(encoding="utf-8")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["motor.mmd"]


def test_tables_converts_and_reloads(tmp_path: Path) -> None:
    """tables --to md prints Markdown that loads back into an equal chart."""
    from statectl.front.builder.build import load_chart

    code, out, _ = cli("tables", MOTOR, "--to", "md")
    assert code == 0
    md = tmp_path / "motor.md"
    md.write_text(out, encoding="utf-8")
    a, b = load_chart(MOTOR), load_chart(str(md))
    assert [(t.source, t.events, t.targets, t.guard) for t in a.transitions] == [
        (t.source, t.events, t.targets, t.guard) for t in b.transitions
    ]


def test_malformed_file_is_a_clean_failure(tmp_path: Path) -> None:
    """A malformed YAML file gives a diagnostic and exit 1, never a traceback, nothing written."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("device: [unclosed\n", encoding="utf-8")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    code, out, err = cli("tables", str(bad), "--to", "csv", "--out", str(out_dir / "x"))
    assert code == 1
    assert "T101" in err and "Traceback" not in err + out
    assert list(out_dir.iterdir()) == []


def test_build_shows_transitions() -> None:
    """build lists every transition as ``src + event [guard] = dst``."""
    code, out, _ = cli("build", MOTOR)
    assert code == 0
    assert "Blocked + Initialization [previous == 'Moving'] = Returning" in out
    assert out.count(" + ") == 6


def test_demo_ends_blocked() -> None:
    """demo runs the case study and its last state is Blocked."""
    code, out, _ = cli("demo")
    assert code == 0
    assert "Blocked" in out.strip().splitlines()[-1]


def test_readme_quick_start_is_two_make_targets_that_exist() -> None:
    """The README opens with exactly two quick-start commands, both real Makefile targets."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = readme.split("## Quick start", 1)[1].split("```sh", 1)[1].split("```", 1)[0]
    commands = [ln.split("#")[0].strip() for ln in block.strip().splitlines()]
    assert commands == ["make demo", "make test"]
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    for target in ("demo", "test"):
        assert re.search(rf"^{target}:", makefile, re.M)


def test_readme_observers_block_matches_the_real_output() -> None:
    """The observers output shown in the README is what the command prints."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    shown = readme.split("$ statectl observers examples/motor/motor.yaml\n", 1)[1]
    block = shown.split("```", 1)[0].splitlines()
    shown_lines = [ln[3:] for ln in block if ln.strip() not in ("", "...")]
    _, out, _ = cli("observers", MOTOR)
    assert [ln.rstrip() for ln in out.splitlines()[: len(shown_lines)]] == shown_lines


CELLS = ROOT / "examples" / "pick-and-place"


@pytest.mark.parametrize(
    ("argv", "code", "needle"),
    [
        (["verify", str(CELLS / "cell.yaml")], 0, "verdict: holds"),
        (["verify", str(CELLS / "cell-buggy.yaml")], 1, "FAIL invariant"),
        (["verify", "--max-states", "3", str(CELLS / "cell.yaml")], 1, "incomplete"),
        (["verify", "missing-cell.yaml"], 2, ""),
        (["run", str(CELLS / "cell.yaml"), "--walk", "5"], 0, "conveyor"),
        (["run", str(CELLS / "cell.yaml"), "--walk", "-1"], 2, "0 or more"),
    ],
)
def test_cell_commands(argv: list[str], code: int, needle: str) -> None:
    """verify exits 0 when every property holds, 1 when one fails or the search was cut short;
    a random walk of a negative number of steps is a usage error (it used to pass, exit 0)."""
    got, out, err = cli(*argv)
    assert got == code, out + err
    assert needle in out + err


def test_scxml_export_then_import_gives_the_same_chart(tmp_path: Path) -> None:
    """A device file exported to SCXML and imported back builds the same transitions."""
    from statectl.front.builder.build import load_chart, strip_origins

    doc, back = tmp_path / "motor.scxml", tmp_path / "motor.yaml"
    assert cli("scxml", "export", MOTOR, "--out", str(doc))[0] == 0
    assert cli("scxml", "import", str(doc), "--out", str(back))[0] == 0
    assert strip_origins(load_chart(str(back))) == strip_origins(load_chart(MOTOR))


def test_scxml_run_prints_the_final_state(tmp_path: Path) -> None:
    """scxml run prints 'final: <id>' for the top-level final state it reaches."""
    doc = tmp_path / "t.scxml"
    doc.write_text(
        '<scxml xmlns="http://www.w3.org/2005/07/scxml" version="1.0" initial="a">'
        '<state id="a"><onentry><raise event="go"/></onentry>'
        '<transition event="go" target="done"/></state><final id="done"/></scxml>',
        encoding="utf-8",
    )
    code, out, _ = cli("scxml", "run", str(doc), "--timeout", "5")
    assert (code, out) == (0, "final: done\n")


def test_codegen_writes_a_cpp_device(tmp_path: Path) -> None:
    """codegen --target cpp writes the device header; an unknown target is a usage error."""
    assert cli("codegen", MOTOR, "--target", "cpp", "--out", str(tmp_path))[0] == 0
    assert any(p.suffix == ".hpp" for p in tmp_path.rglob("*"))
    assert cli("codegen", MOTOR, "--target", "rust", "--out", str(tmp_path / "x"))[0] == 2


def test_scxml_run_without_a_final_state_exits_non_zero(tmp_path: Path) -> None:
    """scxml run prints no final line and exits 1 when no top-level final state is reached."""
    doc = tmp_path / "t.scxml"
    doc.write_text(
        '<scxml xmlns="http://www.w3.org/2005/07/scxml" version="1.0" initial="a">'
        '<state id="a"><transition event="never" target="done"/></state>'
        '<final id="done"/></scxml>',
        encoding="utf-8",
    )
    code, out, err = cli("scxml", "run", str(doc), "--timeout", "1")
    assert (code, out) == (1, "")
    assert "no top-level final state within 1 s" in err  # the timeout as given, not 1.0


PAIR = ROOT / "examples" / "motor" / "motor.csv"  # names the shipped CSV pair; no such file


@pytest.mark.parametrize(
    ("argv", "stdin"),
    [
        (["check", str(PAIR)], ""),
        (["build", str(PAIR)], ""),
        (["observers", str(PAIR)], ""),
        (["run", str(PAIR)], "Movement\n"),
    ],
)
def test_name_csv_names_the_pair_in_every_command(
    argv: list[str], stdin: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``NAME.csv`` loads the pair NAME.states.csv + NAME.events.csv (docs/tables.md), in
    check and run too, not only in the commands that take it: no 'no such file'."""
    assert not PAIR.exists()
    monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    code, _, err = cli(*argv)
    assert (code, err) == (0, "")


def test_check_says_where_an_scxml_document_goes(tmp_path: Path) -> None:
    """``statectl check doc.scxml`` (device tables only) names scxml run and scxml import."""
    doc = tmp_path / "doc.scxml"
    doc.write_text(
        '<scxml xmlns="http://www.w3.org/2005/07/scxml" version="1.0" initial="a">'
        '<final id="a"/></scxml>',
        encoding="utf-8",
    )
    code, out, _ = cli("check", str(doc))
    assert code == 1
    assert "T102" in out and f"statectl scxml run {doc} runs it" in out
    assert f"statectl scxml import {doc} writes" in out
