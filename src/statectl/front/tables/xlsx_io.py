"""Device tables as an Excel workbook (openpyxl).

Rules:
1. Sheets ``States`` and ``Events`` (and optional ``Data`` with ``name, value``
   and ``Recovery`` with ``state, event, data, redo``) each have a header row (the
   first row that is not blank) and rows under it; sheet names are matched without
   regard to case. Blank rows, short rows and cells past the header follow the rules
   every flat format shares (:mod:`statectl.front.tables.grid`).
2. The device name is cell B1 of a sheet ``Device`` whose A1 reads ``device``;
   without that sheet it is the file's name without ``.xlsx``.
3. Cells are read as text: numbers as written, booleans as ``true``/``false``;
   a date or time where text is expected is T108. Data values are YAML literal
   text (a number cell is taken as that number).
4. Locations name the sheet and the spreadsheet row (1-based, as Excel shows it).
5. The writer stores every cell as a string, so text like ``=x`` never turns
   into a formula.
"""

from __future__ import annotations

import datetime
import io
import zipfile
from collections.abc import Iterable
from typing import Any

from statectl.front.tables.grid import FlatSource, data_entries, read_grid
from statectl.front.tables.rows import Bad, Cell, DeviceTables, RawTable, diag
from statectl.front.tables.schema import flat_tables, make_tables
from statectl.front.tables.xlsx_formulas import uncached_formulas
from statectl.kernel.errors import Diagnostic, Location

__all__ = ["dump_xlsx", "read_xlsx"]

SHEETS = {
    "states": "States",
    "events": "Events",
    "data": "Data",
    "recovery": "Recovery",
    "device": "Device",
}


def _openpyxl() -> Any:
    """openpyxl, imported on first use: a tenth of a second every command paid at start,
    though only a workbook needs it."""
    import openpyxl  # type: ignore[import-untyped, unused-ignore]  # no type information
    import openpyxl.styles  # type: ignore[import-untyped, unused-ignore]
    import openpyxl.worksheet.worksheet  # type: ignore[import-untyped, unused-ignore]

    return openpyxl


def _cell(value: Any) -> Cell:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return str(int(value)) if value.is_integer() else repr(value)
    if isinstance(value, str):
        return value
    if isinstance(value, datetime.date | datetime.time | datetime.timedelta):
        return Bad(f"a {type(value).__name__} ({value})")
    return Bad(f"a {type(value).__name__}")


def _rows(ws: Any) -> Iterable[tuple[int, tuple[Any, ...]]]:
    for number, values in enumerate(ws.iter_rows(values_only=True), start=1):
        yield number, tuple(values)


#: What to do about a cell with text past the header, in a spreadsheet's terms (grid rule 3).
FIX = "delete the stray cells or name their column in the header row"


def column_letter(position: int) -> str:
    """A 1-based column as a spreadsheet names it: 1 is A, 27 is AA."""
    letters = ""
    while position > 0:
        position, rest = divmod(position - 1, 26)
        letters = chr(ord("A") + rest) + letters
    return letters


def _table(table: str, ws: Any, file: str, diags: list[Diagnostic]) -> RawTable | None:
    sheet = str(ws.title)
    source = FlatSource(
        table, file, f"sheet {sheet!r}", FIX, sheet, lambda n: f"column {column_letter(n)}"
    )
    records = [(n, [_cell(v) for v in values]) for n, values in _rows(ws)]
    return read_grid(source, records, diags)


#: Largest total a workbook's parts may unpack to (T117): a zip bomb stops here.
MAX_UNPACKED_BYTES = 64 << 20


def _unpacked_size(content: bytes) -> int:
    """What the workbook's zip says its parts unpack to (0 if it is no zip: T101 follows).

    Python's zip reader never returns more than a part's declared size, so the
    declared total bounds what openpyxl can read.
    """
    try:
        with zipfile.ZipFile(io.BytesIO(content)) as archive:
            return sum(info.file_size for info in archive.infolist())
    except (zipfile.BadZipFile, ValueError, OSError, EOFError):
        return 0


def read_xlsx(content: bytes, file: str, stem: str) -> tuple[DeviceTables | None, list[Diagnostic]]:
    """Read a workbook's bytes; ``stem`` names the device when there is no Device sheet."""
    diags: list[Diagnostic] = []
    source = Location(file)
    unpacked = _unpacked_size(content)
    if unpacked > MAX_UNPACKED_BYTES:
        return None, [
            diag(
                "T117",
                source,
                f"the workbook unpacks to {unpacked:,} bytes, more than the limit of "
                f"{MAX_UNPACKED_BYTES:,}",
                "a device workbook is small; see docs/limits.md",
            )
        ]
    try:
        wb = _openpyxl().load_workbook(io.BytesIO(content), read_only=True, data_only=True)
    except Exception as exc:  # openpyxl raises many kinds for a damaged workbook
        return None, [diag("T101", source, f"not a readable XLSX workbook: {exc}")]
    try:
        sheets = {str(name).strip().lower(): wb[name] for name in wb.sheetnames}
        formulas = uncached_formulas(content, file, wb)
        if formulas:
            return None, formulas
        if "states" not in sheets and "events" not in sheets:
            return None, [
                diag(
                    "T102",
                    source,
                    "not a device workbook: no 'States' or 'Events' sheet",
                    "sheets found: " + ", ".join(wb.sheetnames),
                )
            ]
        tables: dict[str, RawTable | None] = {}
        for table in ("states", "events"):
            if table not in sheets:
                diags.append(diag("T104", source, f"the workbook has no {SHEETS[table]!r} sheet"))
                tables[table] = None
            else:
                tables[table] = _table(table, sheets[table], file, diags)
        entries: list[tuple[str, object, Location]] = []
        if "data" in sheets:
            entries = data_entries(_table("data", sheets["data"], file, diags), diags)
        recovery = None
        if "recovery" in sheets:
            recovery = _table("recovery", sheets["recovery"], file, diags)
        device = stem
        profile = ""
        if "device" in sheets:
            for _, values in _rows(sheets["device"]):
                if len(values) >= 2 and str(values[0] or "").strip().lower() == "device":
                    device = str(_cell(values[1])) if isinstance(_cell(values[1]), str) else stem
                    break
            # an optional 'profile' row below it (docs/profiles.md)
            for _, values in _rows(sheets["device"]):
                if len(values) >= 2 and str(values[0] or "").strip().lower() == "profile":
                    profile = str(_cell(values[1])) if isinstance(_cell(values[1]), str) else ""
                    break
    except Exception as exc:  # a workbook can fail lazily while its sheets are read
        return None, [*diags, diag("T101", source, f"not a readable XLSX workbook: {exc}")]
    finally:
        wb.close()
    result = make_tables(
        device, tables["states"], tables["events"], entries, source, diags, recovery, profile
    )
    return result, diags


def _fill(ws: Any, header: tuple[str, ...], rows: Iterable[list[str]]) -> None:
    for col, text in enumerate(header, start=1):
        cell = ws.cell(row=1, column=col, value=text)
        cell.data_type = "s"
        cell.font = _openpyxl().styles.Font(bold=True)
    for number, row in enumerate(rows, start=2):
        for col, text in enumerate(row, start=1):
            if text:
                cell = ws.cell(row=number, column=col, value=text)
                cell.data_type = "s"  # never a formula, whatever the text starts with
    ws.freeze_panes = "A2"


def dump_xlsx(tables: DeviceTables) -> bytes:
    """The tables as workbook bytes (States, Events, Data and Recovery if any, Device)."""
    openpyxl = _openpyxl()
    wb = openpyxl.Workbook()
    for name, header, rows in flat_tables(tables):
        if name == "states":  # the sheet a new workbook has
            ws = wb.active
            assert isinstance(ws, openpyxl.worksheet.worksheet.Worksheet)
            ws.title = SHEETS["states"]
        else:
            ws = wb.create_sheet(SHEETS[name])
        _fill(ws, header, rows)
    profile = [["profile", tables.profile]] if tables.profile else []
    _fill(wb.create_sheet(SHEETS["device"]), ("device", tables.device), profile)
    out = io.BytesIO()
    wb.save(out)
    return out.getvalue()
