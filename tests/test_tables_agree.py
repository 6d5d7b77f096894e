"""The three flat readers (CSV, Markdown, XLSX) answer the same logical table the same way.

Each case below is one logical device (tables as rows of cells, ``None`` for a blank
row) written in all three formats; every format must give the same tables, or the
same diagnostic at the same kind of place (the row's line, and the cell's column when
there is one). The rules are docs/tables.md, "What every flat format accepts".
"""

from __future__ import annotations

import csv
import datetime
import io
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import openpyxl
import pytest

from statectl.channels.cli import main
from statectl.front.tables import DeviceTables, load, strip_locations
from statectl.kernel.errors import Diagnostic, Severity

#: A logical table: its rows of cells, the header first; ``None`` is a blank row.
Table = list[list[str] | None]
Device = dict[str, Table]
#: Where each logical row of each table landed: table -> row index -> line (or sheet row).
Lines = dict[str, dict[int, int]]

FORMATS = ("csv", "md", "xlsx")
SHEETS = {"states": "States", "events": "Events", "data": "Data"}


def base() -> Device:
    """The device every case starts from (a fresh copy, so a case may change it)."""
    return {
        "states": [
            ["state", "control", "description"],
            ["Idle", "default", "waits"],
            ["Busy", "event trigger required", ""],
        ],
        "events": [
            ["event", "old", "new", "kind"],
            ["Go", "Idle", "Busy", "command"],
            ["Done", "Busy", "Idle", "completion"],
        ],
        "data": [["name", "value"], ["limit", "3"], ["home", "[0, 1]"]],
    }


def _csv(device: Device, folder: Path) -> tuple[Path, Lines]:
    lines: Lines = {}
    for table, rows in device.items():
        out = io.StringIO()
        out.write("# device: Odd\n")
        writer = csv.writer(out, lineterminator="\n")
        lines[table] = {}
        for n, row in enumerate(rows):
            lines[table][n] = n + 2  # after the comment line
            if row is None:
                out.write("\n")
            else:
                writer.writerow(row)
        (folder / f"odd.{table}.csv").write_text(out.getvalue(), encoding="utf-8")
    return folder / "odd.states.csv", lines


def _md(device: Device, folder: Path) -> tuple[Path, Lines]:
    text = ["# Device: Odd"]
    lines: Lines = {}
    for table, rows in device.items():
        text += ["", f"## {table.title()}", ""]
        lines[table] = {}
        header = next(n for n, r in enumerate(rows) if r is not None)
        for n, row in enumerate(rows):
            text.append("" if row is None else "| " + " | ".join(row) + " |")
            lines[table][n] = len(text)
            if n == header:
                text.append("|" + "|".join("---" for _ in rows[header] or ()) + "|")
    path = folder / "odd.md"
    path.write_text("\n".join(text) + "\n", encoding="utf-8")
    return path, lines


def _xlsx(device: Device, folder: Path) -> tuple[Path, Lines]:
    wb = openpyxl.Workbook()
    wb.remove(wb.active)
    lines: Lines = {}
    for table, rows in device.items():
        ws = wb.create_sheet(SHEETS[table])
        lines[table] = {}
        for n, row in enumerate(rows):
            lines[table][n] = n + 1
            for col, text in enumerate(row or [], start=1):
                ws.cell(row=n + 1, column=col, value=text)
    device_sheet = wb.create_sheet("Device")
    device_sheet.append(["device", "Odd"])
    path = folder / "odd.xlsx"
    wb.save(path)
    return path, lines


WRITERS: dict[str, Callable[[Device, Path], tuple[Path, Lines]]] = {
    "csv": _csv,
    "md": _md,
    "xlsx": _xlsx,
}


def write(fmt: str, device: Device, tmp_path: Path) -> tuple[Path, Lines]:
    folder = tmp_path / fmt
    folder.mkdir()
    return WRITERS[fmt](device, folder)


@dataclass(frozen=True)
class Where:
    """The diagnostic a case expects: its code, and the table, row and column it names
    (row ``0`` is the header; column ``None``: the whole row)."""

    code: str
    table: str
    row: int
    column: str | None = None


@dataclass(frozen=True)
class Case:
    name: str
    change: Callable[[Device], None]
    expect: Where | None = None  # None: the very tables of the unchanged device


def _rows(device: Device, table: str) -> list[list[str]]:
    return [r for r in device[table] if r is not None]


def trailing_empty(d: Device) -> None:
    _rows(d, "states")[1].extend(["", " "])


def extra_text(d: Device) -> None:
    _rows(d, "events")[2].extend(["", "oops"])


def unnamed_column(d: Device) -> None:
    _rows(d, "states")[0].append("")
    _rows(d, "states")[1].append("stray")


def note_beside(d: Device) -> None:
    d["events"].append(["", "", "", "", "", "ask Ann"])


def spaced_name(d: Device) -> None:
    _rows(d, "data")[1][0] = "  limit  "


def bad_literal(d: Device) -> None:
    _rows(d, "data")[2][1] = "[0, 1"


def blank_inside(d: Device) -> None:
    d["events"].insert(2, None)


def empty_cells_row(d: Device) -> None:
    d["states"].insert(2, ["", "", ""])


def blank_before_header(d: Device) -> None:
    d["states"].insert(0, None)


def short_row(d: Device) -> None:
    _rows(d, "states")[2].pop()  # Busy's empty description left out


def missing_column(d: Device) -> None:
    for row in _rows(d, "events"):
        row.pop(2)  # 'new'


def unknown_column(d: Device) -> None:
    for row, text in zip(_rows(d, "states"), ("colour", "red", "blue"), strict=True):
        row.append(text)


def spaced_cells(d: Device) -> None:
    for row in _rows(d, "events")[1:]:
        row[:] = [f"  {c}  " for c in row]


def header_case(d: Device) -> None:
    _rows(d, "states")[0][:] = ["STATE", " Required State Control ", "Description"]
    _rows(d, "events")[0][:] = ["Event", "OLD STATE", "new_state", "KIND"]


def duplicate_column(d: Device) -> None:
    _rows(d, "states")[0][2] = "state"


CASES = [
    Case("plain", lambda d: None),
    Case("trailing empty cells", trailing_empty),
    Case("extra cell with text", extra_text, Where("T101", "events", 2)),
    Case("text under an unnamed column", unnamed_column, Where("T101", "states", 1)),
    Case("note beside the table", note_beside, Where("T101", "events", 3)),
    Case("data name with spaces", spaced_name),
    Case("bad data literal", bad_literal, Where("T108", "data", 2, "value")),
    Case("blank row inside a table", blank_inside),
    Case("row of empty cells", empty_cells_row),
    Case("blank row before the header", blank_before_header),
    Case("row shorter than the header", short_row),
    Case("missing required column", missing_column, Where("T104", "events", 0)),
    Case("unknown column", unknown_column, Where("T103", "states", 0)),
    Case("spaces around cells", spaced_cells),
    Case("header in another case", header_case),
    Case("column named twice", duplicate_column, Where("T101", "states", 0)),
]


def read(
    fmt: str, case: Case, tmp_path: Path
) -> tuple[DeviceTables | None, list[Diagnostic], Lines]:
    device = base()
    case.change(device)
    path, lines = write(fmt, device, tmp_path)
    tables, diags = load(path)
    return tables, diags, lines


def _reference(tmp_path: Path) -> DeviceTables:
    path, _ = write("csv", base(), tmp_path / "reference")
    tables, diags = load(path)
    assert tables is not None and diags == []
    return strip_locations(tables)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_the_three_formats_agree(case: Case, tmp_path: Path) -> None:
    """The same logical table gives the same tables, or the same diagnostic at the
    same row (and cell), in CSV, Markdown and XLSX."""
    (tmp_path / "reference").mkdir()
    reference = _reference(tmp_path)
    seen: dict[str, object] = {}
    for fmt in FORMATS:
        tables, diags, lines = read(fmt, case, tmp_path)
        errors = [d for d in diags if d.severity is Severity.ERROR]
        if case.expect is None:
            assert errors == [], fmt
            assert tables is not None
            seen[fmt] = strip_locations(tables)
            continue
        want = case.expect
        assert [d.code for d in errors] == [want.code], (fmt, errors)
        where = errors[0].where
        assert (where.line, where.column) == (lines[want.table][want.row], want.column), fmt
        if fmt == "xlsx":
            assert where.sheet == SHEETS[want.table]
        else:
            assert where.file.endswith(f"odd.{want.table}.csv" if fmt == "csv" else "odd.md")
        assert errors[0].hint, f"{fmt}: a diagnostic says what to do"
        seen[fmt] = (errors[0].code, want)
    assert seen["csv"] == seen["md"] == seen["xlsx"]
    if case.expect is None:
        assert seen["csv"] == reference


EXTRA = next(c for c in CASES if c.name == "extra cell with text")


@pytest.mark.parametrize("fmt", FORMATS)
def test_an_extra_cell_is_named_with_what_to_do(fmt: str, tmp_path: Path) -> None:
    """A cell with text beyond the header's columns is refused by `statectl check` with a
    non-zero exit, the file and line (or sheet and row), the text found and the fix."""
    device = base()
    EXTRA.change(device)
    path, lines = write(fmt, device, tmp_path)
    out, err = io.StringIO(), io.StringIO()
    assert main(["check", str(path)], out, err) == 1
    text = out.getvalue() + err.getvalue()
    line = lines["events"][2]
    place = {"csv": f"odd.events.csv:{line}", "md": f"odd.md:{line}", "xlsx": f"[Events]:{line}"}
    assert place[fmt] in text
    assert "T101" in text and "'oops'" in text
    assert ("column F" if fmt == "xlsx" else "column 6") in text  # as the format counts
    assert "Traceback" not in text


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_row_with_a_stray_cell_is_still_read(fmt: str, tmp_path: Path) -> None:
    """The row whose cell sits past the header still has its own problems reported in
    the same run (diagnostics, not first errors), in every format."""
    device = base()
    row = _rows(device, "events")[2]
    row[3] = "finished"  # no such kind
    row.append("oops")
    path, lines = write(fmt, device, tmp_path)
    _, diags = load(path)
    found = sorted((d.code, d.where.line) for d in diags if d.severity is Severity.ERROR)
    assert found == [("T101", lines["events"][2]), ("T107", lines["events"][2])]


def test_a_workbook_data_cell_of_another_type_is_reported_at_its_cell(tmp_path: Path) -> None:
    """A date typed into a workbook's data value is T108 at that cell, naming the item."""
    wb = openpyxl.Workbook()
    wb.active.title = "States"
    wb.active.append(["state", "control"])
    wb.active.append(["Idle", "default"])
    events = wb.create_sheet("Events")
    events.append(["event", "old", "new"])
    events.append(["Go", "Idle", "Idle"])
    data = wb.create_sheet("Data")
    data.append(["name", "value"])
    data.append(["since", datetime.date(2026, 1, 1)])
    path = tmp_path / "d.xlsx"
    wb.save(path)
    _, diags = load(path)
    assert [(d.code, d.where.sheet, d.where.line, d.where.column) for d in diags] == [
        ("T108", "Data", 2, "value")
    ]
    assert "'since'" in diags[0].message and diags[0].hint


def test_a_second_markdown_table_in_a_section_is_refused(tmp_path: Path) -> None:
    """A blank line no longer ends a Markdown table, so a second table under the same
    heading would read its header and '|---|' rows as rows: it is T101 at its header."""
    device = base()
    path, lines = write("md", device, tmp_path)
    text = path.read_text(encoding="utf-8").replace(
        "| Done | Busy | Idle | completion |",
        "| Done | Busy | Idle | completion |\n\n| note |\n|---|\n| see the manual |",
    )
    path.write_text(text, encoding="utf-8")
    tables, diags = load(path)
    assert [(d.code, d.where.line) for d in diags] == [("T101", lines["events"][2] + 2)]
    assert tables is not None and [e.event for e in tables.events] == ["Go", "Done"]


@pytest.mark.parametrize(
    ("between", "why"),
    [
        ("\nSee the manual for the other events.\n\n", "a table after text in the section"),
        ("\n## Events\n\n", "a table under the section's heading again"),
    ],
)
def test_a_markdown_table_after_the_sections_own_is_refused(
    between: str, why: str, tmp_path: Path
) -> None:
    """Its rows would be dropped without a word: one T101 at its header, saying where the
    section's table is and what to do; the section's own table is still read."""
    device = base()
    path, lines = write("md", device, tmp_path)
    text = path.read_text(encoding="utf-8").replace(
        "| Done | Busy | Idle | completion |",
        "| Done | Busy | Idle | completion |\n"
        + between
        + "| event | old | new |\n|---|---|---|\n| Stop | Busy | Idle |",
    )
    path.write_text(text, encoding="utf-8")
    tables, diags = load(path)
    header = text.split("\n").index("| event | old | new |") + 1
    assert [(d.code, d.where.line) for d in diags] == [("T101", header)], why
    assert f"after the one at line {lines['events'][0]}" in diags[0].message
    assert diags[0].hint and "move its rows" in diags[0].hint
    assert tables is not None and [e.event for e in tables.events] == ["Go", "Done"]
