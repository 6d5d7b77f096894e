"""Bad device files give diagnostics with stable codes and lines, never tracebacks."""

from __future__ import annotations

import datetime
import io
from dataclasses import replace
from pathlib import Path

import openpyxl
import pytest

from statectl.front.builder.build import load_and_build
from statectl.front.tables import load, save
from statectl.kernel.errors import DiagnosticError, Severity

GOOD = """\
device: D
states:
  - state: A
    control: default
  - state: B
    control: event trigger required
events:
  - event: go
    old: A
    new: B
"""


def yaml_case(old: str, new: str) -> dict[str, str | bytes]:
    assert old in GOOD
    return {"d.yaml": GOOD.replace(old, new)}


CSV_STATES = "# device: D\nstate,control\nA,default\nB,event trigger required\n"
CSV_EVENTS = "event,old,new\ngo,A,B\n"


def csv_case(
    states: str | bytes = CSV_STATES, events: str | bytes = CSV_EVENTS
) -> dict[str, str | bytes]:
    return {"d.states.csv": states, "d.events.csv": events}


MD_GOOD = """\
# Device: D

## States

| state | control |
|---|---|
| A | default |
| B | event trigger required |

## Events

| event | old | new |
|---|---|---|
| go | A | B |
"""


def md_case(old: str, new: str) -> dict[str, str | bytes]:
    assert old in MD_GOOD
    return {"d.md": MD_GOOD.replace(old, new)}


def workbook(
    states: list[list[object]],
    events: list[list[object]],
    recovery: list[list[object]] | None = None,
) -> dict[str, str | bytes]:
    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = "States"
    for row in states:
        ws.append(row)
    ws = wb.create_sheet("Events")
    for row in events:
        ws.append(row)
    if recovery is not None:
        ws = wb.create_sheet("Recovery")
        for row in recovery:
            ws.append(row)
    out = io.BytesIO()
    wb.save(out)
    return {"d.xlsx": out.getvalue()}


def plain_workbook() -> bytes:
    out = io.BytesIO()
    openpyxl.Workbook().save(out)
    return out.getvalue()


XLSX_STATES: list[list[object]] = [["state", "control"], ["A", "default"], ["B", "trigger"]]
XLSX_EVENTS: list[list[object]] = [["event", "old", "new"], ["go", "A", "B"]]

# (case id, files, expected code, expected line or None, a word the message or hint holds)
CASES: list[tuple[str, dict[str, str | bytes], str, int | None, str]] = [
    ("yaml-malformed", yaml_case("    old: A\n", "    old: [A\n"), "T101", 10, "malformed"),
    (
        "yaml-duplicate-key",
        yaml_case("    old: A\n", "    old: A\n    old: B\n"),
        "T101",
        10,
        "twice",
    ),
    ("yaml-top-level-list", {"d.yaml": "- a\n- b\n"}, "T102", 1, "mapping"),
    ("yaml-empty-file", {"d.yaml": ""}, "T102", 1, "empty"),
    ("yaml-not-a-device", {"d.yaml": "name: x\nsteps: []\n"}, "T102", 1, "device"),
    ("yaml-unknown-column", yaml_case("  - state: B", "  - stat: B"), "T103", 5, "'state'"),
    (
        "yaml-unknown-top-key",
        yaml_case("device: D\n", "device: D\nstate: []\n"),
        "T103",
        2,
        "known",
    ),
    ("yaml-missing-cell", yaml_case("    new: B\n", ""), "T104", 8, "'new'"),
    ("yaml-missing-device", yaml_case("device: D\n", ""), "T104", 1, "device"),
    ("yaml-missing-events", {"d.yaml": GOOD.split("events:")[0]}, "T104", 1, "events"),
    ("yaml-empty-table", yaml_case("events:\n", "events: []\nx:\n"), "T105", 7, "empty"),
    ("yaml-bad-control", yaml_case("control: default", "control: defualt"), "T106", 4, "default"),
    (
        "yaml-bad-kind",
        yaml_case("    new: B\n", "    new: B\n    kind: order\n"),
        "T107",
        11,
        "kind",
    ),
    ("yaml-mapping-cell", yaml_case("    old: A\n", "    old: {x: 1}\n"), "T108", 9, "mapping"),
    (
        "yaml-row-not-mapping",
        yaml_case("  - event: go\n", "  - go\n  - event: go\n"),
        "T108",
        8,
        "row",
    ),
    ("yaml-states-not-list", {"d.yaml": "device: D\nstates: 3\nevents: []\n"}, "T108", 2, "list"),
    (
        "yaml-contradicting-rows",
        yaml_case("  - state: B\n", "  - state: A\n    parent: B\n  - state: B\n"),
        "T109",
        5,
        "parent",
    ),
    ("yaml-comma-in-event", yaml_case("event: go", "event: go, now"), "T111", 8, "comma"),
    (
        "yaml-comma-in-ignore-list",
        yaml_case("control: default\n", "control: default\n    ignore: ['a, b']\n"),
        "T111",
        5,
        "comma",
    ),
    ("yaml-bad-data-name", {"d.yaml": GOOD + "data:\n  2x: 1\n"}, "T112", 12, "name"),
    ("yaml-data-mapping", {"d.yaml": GOOD + "data:\n  x: {a: 1}\n"}, "T108", 12, "literal"),
    ("yaml-data-not-mapping", {"d.yaml": GOOD + "data: [1]\n"}, "T108", 11, "mapping"),
    ("yaml-recovery-not-list", {"d.yaml": GOOD + "recovery: 3\n"}, "T108", 11, "list"),
    (
        "yaml-recovery-row-not-mapping",
        {"d.yaml": GOOD + "recovery:\n  - B\n"},
        "T108",
        12,
        "mapping",
    ),
    (
        "yaml-recovery-unknown-key",
        {"d.yaml": GOOD + "recovery:\n  - state: B\n    event: go\n    when: x\n"},
        "T103",
        14,
        "recovery",
    ),
    (
        "yaml-recovery-missing-event",
        {"d.yaml": GOOD + "recovery:\n  - state: B\n"},
        "T104",
        12,
        "'event'",
    ),
    (
        "yaml-recovery-date-data",
        {"d.yaml": GOOD + "recovery:\n  - state: B\n    event: go\n    data: 2016-01-01\n"},
        "T108",
        14,
        "date",
    ),
    (
        "yaml-recovery-event-and-redo",
        {"d.yaml": GOOD + "recovery:\n  - state: B\n    event: go\n    redo: yes\n"},
        "T114",
        12,
        "both",
    ),
    (
        "yaml-recovery-redo-with-data",
        {"d.yaml": GOOD + "recovery:\n  - state: B\n    redo: yes\n    data: {a: 1}\n"},
        "T114",
        14,
        "no data",
    ),
    (
        "yaml-recovery-redo-no-event",
        {"d.yaml": GOOD + "recovery:\n  - state: B\n    redo: no\n"},
        "T104",
        12,
        "neither",
    ),
    ("csv-unclosed-quote", csv_case(events='event,old,new\n"go,A,B\n'), "T101", 2, "CSV"),
    ("csv-too-many-cells", csv_case(events="event,old,new\ngo,A,B,C\n"), "T101", 2, "cells"),
    ("csv-unknown-column", csv_case(events="event,old,nwe\ngo,A,B\n"), "T103", 1, "'new'"),
    ("csv-missing-column", csv_case(events="event,old\ngo,A\n"), "T104", 1, "'new'"),
    ("csv-empty-cell", csv_case(events="event,old,new\ngo,,B\n"), "T104", 2, "'old'"),
    ("csv-header-only", csv_case(events="event,old,new\n"), "T105", 1, "empty"),
    ("csv-empty-file", csv_case(events=""), "T105", 1, "no header"),
    ("csv-bad-control", csv_case(states="state,control\nA,dflt\n"), "T106", 2, "accepted"),
    ("csv-missing-events", {"d.states.csv": CSV_STATES}, "T110", None, "not found"),
    (
        "csv-recovery-unknown-column",
        {**csv_case(), "d.recovery.csv": "state,evnt\nB,go\n"},
        "T103",
        1,
        "'event'",
    ),
    (
        "csv-recovery-missing-cell",
        {**csv_case(), "d.recovery.csv": "state,event\nB,\n"},
        "T104",
        2,
        "'event'",
    ),
    (
        "csv-recovery-malformed-data",
        {**csv_case(), "d.recovery.csv": 'state,event,data\nB,go,"{a: [1"\n'},
        "T108",
        2,
        "YAML",
    ),
    (
        "csv-recovery-bad-redo",
        {**csv_case(), "d.recovery.csv": "state,event,redo\nB,,maybe\n"},
        "T114",
        2,
        "yes or no",
    ),
    (
        "csv-recovery-event-and-redo",
        {**csv_case(), "d.recovery.csv": "state,event,redo\nB,go,true\n"},
        "T114",
        2,
        "both",
    ),
    ("csv-not-utf8", csv_case(events=b"event,old,new\n\xff,A,B\n"), "T101", None, "UTF-8"),
    ("md-no-tables", {"d.md": "# Device: D\n\nJust prose.\n"}, "T102", 1, "States"),
    ("md-no-separator", md_case("|---|---|---|\n", ""), "T101", 13, "separator"),
    ("md-no-events", {"d.md": MD_GOOD.split("## Events")[0]}, "T104", 1, "Events"),
    ("md-too-many-cells", md_case("| go | A | B |", "| go | A | B | C |"), "T101", 14, "cells"),
    (
        "md-bad-kind",
        md_case(
            "| event | old | new |\n|---|---|---|\n| go | A | B |",
            "| event | old | new | kind |\n|---|---|---|---|\n| go | A | B | x |",
        ),
        "T107",
        14,
        "kind",
    ),
    (
        "md-recovery-missing-cell",
        {"d.md": MD_GOOD + "\n## Recovery\n\n| state | event |\n|---|---|\n| B | |\n"},
        "T104",
        20,
        "'event'",
    ),
    (
        "md-recovery-event-and-redo",
        {
            "d.md": MD_GOOD
            + "\n## Recovery\n\n| state | event | redo |\n|---|---|---|\n| B | go | yes |\n"
        },
        "T114",
        20,
        "both",
    ),
    ("xlsx-garbage", {"d.xlsx": b"not a zip"}, "T101", None, "XLSX"),
    ("xlsx-empty-sheets", workbook([], []), "T105", 1, "header"),
    ("xlsx-not-a-device", {"d.xlsx": plain_workbook()}, "T102", None, "sheet"),
    (
        "xlsx-bad-control",
        workbook([["state", "control"], ["A", "default"], ["B", "sometimes"]], XLSX_EVENTS),
        "T106",
        3,
        "sometimes",
    ),
    (
        "xlsx-date-cell",
        workbook(XLSX_STATES, [["event", "old", "new"], ["go", datetime.date(2016, 1, 1), "B"]]),
        "T108",
        2,
        "date",
    ),
    (
        "xlsx-recovery-unknown-column",
        workbook(XLSX_STATES, XLSX_EVENTS, [["state", "event", "dat"], ["B", "go", "1"]]),
        "T103",
        1,
        "'data'",
    ),
    (
        "xlsx-recovery-mapping-with-number-keys",
        workbook(XLSX_STATES, XLSX_EVENTS, [["state", "event", "data"], ["B", "go", "{1: a}"]]),
        "T108",
        2,
        "text",
    ),
    (
        "xlsx-recovery-neither-event-nor-redo",
        workbook(XLSX_STATES, XLSX_EVENTS, [["state", "event", "redo"], ["B", None, "no"]]),
        "T104",
        2,
        "neither",
    ),
    (
        "xlsx-recovery-redo-and-event",
        workbook(XLSX_STATES, XLSX_EVENTS, [["state", "event", "redo"], ["B", "go", True]]),
        "T114",
        2,
        "both",
    ),
    ("unknown-suffix", {"d.txt": "device: D\n"}, "T102", None, "format"),
]


@pytest.mark.parametrize(
    ("files", "code", "line", "word"),
    [pytest.param(f, c, ln, w, id=i) for i, f, c, ln, w in CASES],
)
def test_bad_file_gives_code_and_line(
    tmp_path: Path, files: dict[str, str | bytes], code: str, line: int | None, word: str
) -> None:
    """Each bad file yields its code at its line, with no chart and no traceback."""
    for name, content in files.items():
        path = tmp_path / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")
    first = tmp_path / next(iter(files))
    chart, diags = load_and_build(first)
    assert chart is None
    found = [d for d in diags if d.code == code]
    assert found, [str(d) for d in diags]
    assert found[0].severity is Severity.ERROR
    assert found[0].where.line == line, str(found[0])
    assert word.lower() in (found[0].message + " " + found[0].hint).lower(), str(found[0])


def test_unknown_column_suggests_the_close_name(tmp_path: Path) -> None:
    """T103's hint carries a did-you-mean and the known columns."""
    (tmp_path / "d.yaml").write_text(GOOD.replace("    old: A", "    olde: A"))
    _, diags = load(tmp_path / "d.yaml")
    hint = next(d.hint for d in diags if d.code == "T103")
    assert hint.startswith("did you mean 'old'?")
    assert "guard" in hint


def test_every_problem_is_reported_not_just_the_first(tmp_path: Path) -> None:
    """Loading collects every problem of a file."""
    text = GOOD.replace("control: default", "control: dflt").replace("    new: B", "    kind: x")
    (tmp_path / "d.yaml").write_text(text)
    _, diags = load(tmp_path / "d.yaml")
    assert sorted(d.code for d in diags) == ["T104", "T106", "T107"]


def test_missing_file_is_t110(tmp_path: Path) -> None:
    """A file that is not there is T110, not an exception."""
    _, diags = load(tmp_path / "none.yaml")
    assert [d.code for d in diags] == ["T110"]


@pytest.mark.parametrize("fmt", ["yaml", "csv", "xlsx", "md"])
def test_failed_save_writes_nothing(tmp_path: Path, fmt: str) -> None:
    """Tables that cannot be written raise T111 and leave the directory empty."""
    tables, _ = load(Path(__file__).resolve().parent.parent / "examples" / "motor" / "motor.yaml")
    assert tables is not None
    bad = replace(tables, events=(replace(tables.events[0], event="a, b"), *tables.events[1:]))
    with pytest.raises(DiagnosticError) as info:
        save(bad, tmp_path / f"m.{fmt}", fmt)
    assert [d.code for d in info.value.diagnostics] == ["T111"]
    assert list(tmp_path.iterdir()) == []


def test_save_into_a_missing_directory_is_t110(tmp_path: Path) -> None:
    """A directory that does not exist is T110, and nothing is created."""
    tables, _ = load(Path(__file__).resolve().parent.parent / "examples" / "motor" / "motor.yaml")
    assert tables is not None
    with pytest.raises(DiagnosticError) as info:
        save(tables, tmp_path / "no" / "m.csv")
    assert [d.code for d in info.value.diagnostics] == ["T110"]
    assert list(tmp_path.iterdir()) == []


def test_failed_write_removes_the_folders_it_made(tmp_path: Path) -> None:
    """An output folder created for files that then cannot be written is removed again."""
    from statectl.front.tables import write_files

    contents: dict[Path, str | bytes] = {
        tmp_path / "out" / "sub" / "a.txt": "a",
        tmp_path / "out" / "sub" / ("b" * 300 + ".txt"): "b",  # longer than a file name may be
    }
    with pytest.raises(DiagnosticError) as info:
        write_files(contents, make_dirs=True)
    assert [d.code for d in info.value.diagnostics] == ["T110"]
    assert list(tmp_path.iterdir()) == []


def test_unwritable_xlsx_text_writes_nothing(tmp_path: Path) -> None:
    """A control character a workbook cannot hold fails the save before any file exists."""
    tables, _ = load(Path(__file__).resolve().parent.parent / "examples" / "motor" / "motor.yaml")
    assert tables is not None
    bad = replace(
        tables, states=(replace(tables.states[0], description="bell\x07"), *tables.states[1:])
    )
    with pytest.raises(DiagnosticError) as info:
        save(bad, tmp_path / "m.xlsx")
    assert [d.code for d in info.value.diagnostics] == ["T108"]
    assert list(tmp_path.iterdir()) == []


def test_load_errors_do_not_hide_build_errors(tmp_path: Path) -> None:
    """One check run reports cell errors (T1xx) and the build's own (B2xx, X30x) together."""
    from statectl.front.builder.build import load_and_build

    path = tmp_path / "dev.yaml"
    path.write_text(
        "device: M\nstates:\n  - {state: A, control: default, colour: red}\n"
        "  - {state: B, control: sometimes}\nevents:\n  - {event: go, old: A, new: C, kind: zap}\n"
        '  - {event: back, old: B, new: A, guard: "x.__class__"}\n',
        encoding="utf-8",
    )
    chart, diags = load_and_build(path)
    assert chart is None
    assert [(d.code, d.where.line) for d in diags] == [
        ("T103", 3),
        ("T106", 4),
        ("T107", 6),
        ("B201", 6),
        ("X302", 7),
    ]
