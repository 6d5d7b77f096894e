"""`statectl profiles` and `statectl new`, and the table features profiles rely on: the
optional `number` column and the `profile` declaration, in every format."""

from __future__ import annotations

import io
import json
from dataclasses import replace
from pathlib import Path

import pytest

from statectl.channels.cli import main
from statectl.front.builder.build import build
from statectl.front.profiles import PROFILES, find, profile_tables
from statectl.front.rules import check_chart, check_paths
from statectl.front.tables import load, save, strip_locations
from statectl.kernel.errors import Severity


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), out, err)
    return code, out.getvalue(), err.getvalue()


def test_profiles_lists_every_shipped_profile() -> None:
    """`statectl profiles --json` lists each profile with its standard and state count."""
    code, out, _ = run("profiles", "--json")
    assert code == 0
    rows = json.loads(out)["profiles"]
    assert [r["name"] for r in rows] == [p.name for p in PROFILES]
    assert {r["name"]: r["states"] for r in rows} == {
        "cia402": 8,
        "packml": 17,
        "plcopen-axis": 8,
        "motor": 3,
    }
    code, text, _ = run("profiles")
    assert code == 0 and all(p.name in text and p.standard in text for p in PROFILES)


FORMATS = {
    "yaml": ["Cell 1.yaml"],
    "md": ["Cell 1.md"],
    "xlsx": ["Cell 1.xlsx"],
    "csv": ["Cell 1.events.csv", "Cell 1.states.csv"],
}


@pytest.mark.parametrize("profile", [p.name for p in PROFILES])
@pytest.mark.parametrize("fmt", list(FORMATS))
def test_new_writes_a_device_that_checks_clean(tmp_path: Path, profile: str, fmt: str) -> None:
    """`statectl new` writes the profile under the new name in the format asked for, and
    the file loads as the profile's tables (renamed) and checks clean."""
    code, _, err = run(
        "new", "Cell 1", "--profile", profile, "--format", fmt, "--out", str(tmp_path / "d")
    )
    assert code == 0, err
    names = sorted(p.name for p in (tmp_path / "d").iterdir())
    expected = list(FORMATS[fmt])
    shipped = profile_tables(find(profile))  # type: ignore[arg-type]
    if fmt == "csv":  # a data and a recovery file beside the pair when there are rows
        extra = [f"Cell 1.{t}.csv" for t in ("data", "recovery") if getattr(shipped, t)]
        expected = sorted([*expected, *extra])
    assert names == expected
    first = tmp_path / "d" / ("Cell 1.states.csv" if fmt == "csv" else expected[0])
    tables, diags = load(first)
    assert tables is not None, diags
    wanted = replace(profile_tables(find(profile)), device="Cell 1")  # type: ignore[arg-type]
    assert strip_locations(tables) == strip_locations(wanted)
    problems = [d for d in check_paths([str(first)]) if d.severity is not Severity.INFO]
    assert problems == []


def test_new_keeps_the_comments_in_yaml(tmp_path: Path) -> None:
    """A YAML device started from a profile keeps the profile's explanatory comments."""
    assert run("new", "Drive", "--profile", "cia402", "--out", str(tmp_path))[0] == 0
    text = (tmp_path / "Drive.yaml").read_text(encoding="utf-8")
    assert text.startswith("# CiA 402") and "\ndevice: Drive\n" in text


def test_new_never_overwrites(tmp_path: Path) -> None:
    """`statectl new` refuses (exit 1) to write over an existing file and leaves it as it was."""
    target = tmp_path / "Unit.yaml"
    target.write_text("mine\n", encoding="utf-8")
    code, _, err = run("new", "Unit", "--profile", "packml", "--out", str(tmp_path))
    assert code == 1 and "already exists" in err and "Traceback" not in err
    assert target.read_text(encoding="utf-8") == "mine\n"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["new", "U", "--profile", "nope"], "unknown profile 'nope'"),
        (["new", "a/b", "--profile", "packml"], "not a usable device name"),
        (["new", ".hidden", "--profile", "packml"], "not a usable device name"),
        (["new", "U", "--profile", "packml", "--format", "json"], "invalid choice"),
        (["new", "U"], "--profile"),
    ],
)
def test_new_usage_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    """A bad profile, name or format is a usage error (exit 2) that says what is wrong, and
    nothing is written."""
    code, _, err = run(*argv, "--out", str(tmp_path / "out"))
    assert code == 2 and message in err + capsys.readouterr().err  # argparse's own stderr
    assert not (tmp_path / "out").exists()


def test_new_out_must_be_a_directory(tmp_path: Path) -> None:
    """`--out` naming a file is a usage error (exit 2)."""
    afile = tmp_path / "f"
    afile.write_text("x", encoding="utf-8")
    code, _, err = run("new", "U", "--profile", "motor", "--out", str(afile))
    assert code == 2 and "not a directory" in err


# -- the number column and the profile declaration ---------------------------------------


@pytest.mark.parametrize("suffix", ["yaml", "md", "xlsx", "csv"])
def test_numbers_and_profile_survive_every_format(tmp_path: Path, suffix: str) -> None:
    """State numbers and the profile declaration are written and read back by every format."""
    tables = profile_tables(find("packml"))  # type: ignore[arg-type]
    files = save(tables, tmp_path / f"unit.{suffix}")
    back, diags = load(files[0])
    assert back is not None, diags
    assert strip_locations(back) == strip_locations(tables)
    assert back.profile == "packml" and any(s.number == "6" for s in back.states)


def _numbered(*numbers: str) -> list[object]:
    tables = profile_tables(find("motor"))  # type: ignore[arg-type]
    states = tuple(replace(s, number=n) for s, n in zip(tables.states, numbers, strict=True))
    chart, diags = build(replace(tables, states=states))
    return [chart, [(d.code, d.severity) for d in diags if d.severity is Severity.ERROR]]


@pytest.mark.parametrize(
    ("numbers", "codes"),
    [
        (("0", "1", "2"), []),
        (("5", "", "7"), []),
        (("x", "1", "2"), [("B236", Severity.ERROR)]),
        (("-1", "1", "2"), [("B236", Severity.ERROR)]),
        (("1.5", "1", "2"), [("B236", Severity.ERROR)]),
        (("99999999999", "1", "2"), [("B236", Severity.ERROR)]),
        (("9" * 5000, "1", "2"), [("B236", Severity.ERROR)]),
        (("\u00b2", "1", "2"), [("B236", Severity.ERROR)]),
        (("3", "3", "2"), [("B237", Severity.ERROR)]),
    ],
)
def test_state_number_cells(numbers: tuple[str, ...], codes: list[object]) -> None:
    """A state number is digits from 0 to 2**31 - 1, unique in the device (B236, B237)."""
    chart, errors = _numbered(*numbers)
    assert errors == codes
    if not codes:
        assert chart is not None
        got = [s.number for s in chart.states]  # type: ignore[attr-defined]
        assert got == [int(n) if n else None for n in numbers]


def test_rows_of_one_state_must_agree_on_its_number() -> None:
    """Two rows of one state with different numbers contradict each other (T109)."""
    tables = profile_tables(find("motor"))  # type: ignore[arg-type]
    first = replace(tables.states[0], number="1")
    again = replace(tables.states[0], number="2", ignore=())
    chart, diags = build(replace(tables, states=(first, again, *tables.states[1:])))
    assert chart is None and "T109" in [d.code for d in diags]


@pytest.mark.parametrize(("profile", "warned"), [("packml", False), ("pakml", True), ("", False)])
def test_unknown_profile_warns(profile: str, warned: bool) -> None:
    """A device declaring a profile statectl does not ship gets C418, with a suggestion."""
    tables = replace(profile_tables(find("motor")), profile=profile)  # type: ignore[arg-type]
    chart, _ = build(tables)
    assert chart is not None
    found = [d for d in check_chart(chart) if d.code == "C418"]
    assert bool(found) == warned
    if warned:
        assert "did you mean 'packml'" in found[0].hint


@pytest.mark.parametrize(("digits", "refused"), [(8, False), (1000, False), (1100, True)])
def test_huge_hex_data_is_refused(tmp_path: Path, digits: int, refused: bool) -> None:
    """A hex data literal too large to write back (the CiA 402 masks are hex) is T108, not a
    crash; a large but writable one loads."""
    path = tmp_path / "d.yaml"
    path.write_text(
        "device: D\nstates:\n  - {state: A, control: default}\n"
        "events:\n  - {event: e, old: A, new: A}\n"
        f"data:\n  mask: 0x{'F' * digits}\n",
        encoding="utf-8",
    )
    tables, diags = load(path)
    assert ("T108" in [d.code for d in diags]) == refused
    if not refused:
        assert tables is not None and build(tables)[0] is not None


@pytest.mark.parametrize("name", ["packml", "motor"])  # no spaces in state names: SCXML ids
def test_numbers_and_profile_survive_scxml(tmp_path: Path, name: str) -> None:
    """Exporting a profile to SCXML and importing it back gives the same tables: state
    numbers and the profile travel as statectl:number and statectl:profile."""
    from statectl.out.scxml.tables_io import export_file, import_file

    source = tmp_path / f"{name}.yaml"
    assert main(["new", name, "--profile", name, "--out", str(tmp_path)]) == 0
    scxml = tmp_path / "exported" / f"{name}.scxml"
    scxml.parent.mkdir()
    scxml.write_text(export_file(source), encoding="utf-8")
    assert 'statectl:profile="' + name + '"' in scxml.read_text(encoding="utf-8")
    written, diags = import_file(scxml)
    assert [d.code for d in diags if d.severity is not Severity.INFO] == []
    assert isinstance(written, list) and len(written) == 1
    back, _ = load(written[0])
    tables, _ = load(source)
    assert back is not None and tables is not None
    assert back.profile == name
    numbers = {s.state: s.number for s in tables.states}
    assert {s.state: s.number for s in back.states} == numbers
