"""Formula cells a workbook holds without a saved value: refused (T124), never read as empty.

A workbook stores a formula and, once a spreadsheet program computed it, its value.
statectl reads the values; a workbook written by a script (openpyxl, pandas) or a
program that does not compute formulas has none, and reading such a cell as empty
would make a guard or a state silently disappear. Every such cell of the sheets
statectl reads is reported with the file, the sheet and the cell reference.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Iterable

from statectl.front.tables.rows import diag
from statectl.kernel.errors import Diagnostic, Location

__all__ = ["uncached_formulas"]

#: The sheets statectl reads, by lowered name.
READ_SHEETS = frozenset({"states", "events", "data", "recovery", "device"})


def _has_formulas(content: bytes) -> bool:
    """Whether any worksheet part holds a formula element (cheap: no workbook parse)."""
    try:
        with zipfile.ZipFile(io.BytesIO(content)) as archive:
            for info in archive.infolist():
                name = info.filename
                if not (name.startswith("xl/worksheets/") and name.endswith(".xml")):
                    continue
                body = archive.read(info)
                if b"<f>" in body or b"<f " in body or b":f>" in body or b":f " in body:
                    return True
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError):
        return False
    return False


def _cells(ws: object) -> Iterable[tuple[int, object]]:
    for row in ws.iter_rows():  # type: ignore[attr-defined]
        for cell in row:
            yield cell.row, cell


def uncached_formulas(content: bytes, file: str, values: object) -> list[Diagnostic]:
    """T124 for each formula cell of a read sheet whose saved value is missing.

    ``values`` is the workbook as loaded with ``data_only=True`` (what the reader uses).
    """
    if not _has_formulas(content):
        return []
    import openpyxl  # type: ignore[import-untyped, unused-ignore]  # on first use only

    out: list[Diagnostic] = []
    try:
        formulas = openpyxl.load_workbook(io.BytesIO(content), read_only=True, data_only=False)
    except Exception:  # the reader reports an unreadable workbook itself
        return []
    try:
        for name in formulas.sheetnames:
            if str(name).strip().lower() not in READ_SHEETS:
                continue
            found = [
                (number, cell)
                for number, cell in _cells(formulas[name])
                if getattr(cell, "data_type", None) == "f"
                or str(getattr(cell, "value", "") or "").startswith("=")
            ]
            if not found:
                continue
            saved = {
                (number, getattr(cell, "column", 0)): getattr(cell, "value", None)
                for number, cell in _cells(values[name])  # type: ignore[index]
            }
            for number, cell in found:
                if saved.get((number, getattr(cell, "column", 0))) is not None:
                    continue
                ref = getattr(cell, "coordinate", "?")
                text = getattr(cell, "value", None)
                out.append(
                    diag(
                        "T124",
                        Location(file, number, sheet=str(name)),
                        f"cell {ref} of sheet {name!r} holds the formula {text!r} "
                        "with no saved value, so its text is unknown",
                        "open and save the workbook in a spreadsheet program (it stores "
                        "the value), or type the value instead of the formula",
                    )
                )
    finally:
        formulas.close()
    return out
