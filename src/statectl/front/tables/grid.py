"""One answer for the flat formats (CSV, Markdown, XLSX): how a grid of cells becomes a table.

Each reader only splits its file into records (a line or sheet row and its cells);
what a record means is decided here, once, so the three cannot drift apart
(docs/tables.md, "What every flat format accepts"):

1. A record whose cells are all empty or spaces is blank, and blank records are
   skipped wherever they are: before the header, between rows, at the end.
2. The first record that is not blank is the header (:func:`check_header`).
3. A row may have fewer cells than the header (the rest are empty) and any number of
   empty cells past it, since editors and spreadsheets leave them. A cell with text in
   a column the header does not name (past its end, or under an empty header cell) is
   T101 at the row, naming the cell, the text and what to do; the row's named cells
   are still read, so its other problems are reported in the same run (a row with
   text only there is a note beside the table, and not read as a row).
4. Every cell keeps its location: the row's line (sheet row) and its column's name.
5. A data row's name is stripped and its value read as a YAML literal; a value that is
   not one is reported at its cell (:func:`data_entries`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

from statectl.front.tables.cells import check_header
from statectl.front.tables.literals import LITERAL_HINT, parse_literal, reported
from statectl.front.tables.rows import (
    REQUIRED,
    Bad,
    Cell,
    RawRow,
    RawTable,
    diag,
    normalize_column,
)
from statectl.kernel.errors import Diagnostic, Location

__all__ = ["FlatSource", "Record", "data_entries", "numbered", "read_grid"]

#: One record as a format holds it: its line (or sheet row) and its cells in order.
Record = tuple[int, Sequence[Cell]]


def numbered(position: int) -> str:
    """A column by its 1-based position, as a text file's reader counts it."""
    return f"column {position}"


@dataclass(frozen=True, slots=True)
class FlatSource:
    """Where one flat table is, and how its format speaks of it in messages.

    ``noun`` names the whole table ("the states file", "sheet 'States'"); ``fix`` says
    what to do about a cell with text past the header in the format's own terms;
    ``column`` names a column by its 1-based position (spreadsheets use letters).
    """

    table: str
    file: str
    noun: str
    fix: str
    sheet: str | None = None
    column: Callable[[int], str] = field(default=numbered)

    def at(self, line: int, column: str | None = None) -> Location:
        return Location(self.file, line, sheet=self.sheet, column=column)


def blank(cells: Sequence[Cell]) -> bool:
    """Rule 1: every cell is text with nothing but spaces in it."""
    return all(isinstance(c, str) and not c.strip() for c in cells)


def read_grid(
    source: FlatSource, records: Iterable[Record], diags: list[Diagnostic]
) -> RawTable | None:
    """The table the records hold (rules 1-4); ``None`` if it has no usable header."""
    filled = [(line, cells) for line, cells in records if not blank(cells)]
    if not filled:
        diags.append(
            diag(
                "T105",
                source.at(1),
                f"{source.noun} has no header row and no rows",
                f"write a header row naming its columns, at least "
                f"{', '.join(REQUIRED[source.table])}, then the rows under it",
            )
        )
        return None
    header_line, header_cells = filled[0]
    where = source.at(header_line)
    header = [(c if isinstance(c, str) else "", where) for c in header_cells]
    columns = check_header(source.table, header, where, diags)
    if columns is None:
        return None
    named = [i for i, (text, _) in enumerate(header) if normalize_column(text)]
    unnamed = sorted(set(range(len(header))) - set(named))
    last = (named[-1], header[named[-1]][0].strip()) if named else (0, "")
    file, sheet = source.file, source.sheet
    rows: list[RawRow] = []
    for line, cells in filled[1:]:
        stray = _stray(cells, unnamed, len(header))
        if stray is not None:
            _report_stray(source, line, (stray, cells[stray]), last, diags)
            if blank([cells[i] for i in named if i < len(cells)]):
                continue  # a note beside the table: a row with nothing else is no row
        raw = {  # a Location per cell, built in place: a long table has a million cells
            name: (cell, Location(file, line, sheet, name))
            for name, cell in zip(columns, cells, strict=False)
            if name is not None
        }
        rows.append(RawRow(Location(file, line, sheet), raw))
    return RawTable(source.table, where, tuple(rows))


def _stray(cells: Sequence[Cell], unnamed: Sequence[int], width: int) -> int | None:
    """The position of a row's first cell with text under an empty header cell or past
    the header's end (rule 3), or ``None``."""
    for i in unnamed:
        if i < len(cells) and not blank((cells[i],)):
            return i
    for i in range(width, len(cells)):
        if not blank((cells[i],)):
            return i
    return None


def _report_stray(
    source: FlatSource,
    line: int,
    stray: tuple[int, Cell],
    last: tuple[int, str],
    diags: list[Diagnostic],
) -> None:
    """Rule 3: the first cell of a row with text where the header names no column."""
    i, cell = stray
    diags.append(
        diag(
            "T101",
            source.at(line),
            f"{source.column(i + 1)} holds {_found(cell)}, but the {source.table} header names no "
            f"column there (its last is {source.column(last[0] + 1)}, {last[1]!r})",
            source.fix,
        )
    )


def data_entries(
    table: RawTable | None, diags: list[Diagnostic]
) -> list[tuple[str, object, Location]]:
    """The data rows as (name, value, row) for :func:`make_data` (rule 5): the name
    stripped, the value a YAML literal read from its cell, reported at that cell."""
    entries: list[tuple[str, object, Location]] = []
    for row in table.rows if table is not None else ():
        cell = row.cells.get("name", ("", row.where))[0]
        name = cell.strip() if isinstance(cell, str) else ""
        value, at = row.cells.get("value", ("", row.where))
        if isinstance(value, str):
            literal: object = parse_literal(value, at, diags, name)
        else:  # a cell of another type (an XLSX date): said here, at the cell
            diags.append(
                diag(
                    "T108",
                    at,
                    f"data value of {name!r} must be a YAML literal (got {_found(value)})",
                    "type the value as text: " + LITERAL_HINT.removeprefix("write "),
                )
            )
            literal = reported()
        entries.append((name, literal, row.where))
    return entries


def _found(cell: Cell) -> str:
    """A cell as a message quotes it: its text (cut at 40 characters), or what it held."""
    if isinstance(cell, str):
        text = cell.strip()
        return repr(text if len(text) <= 40 else text[:37] + "...")
    return cell.found if isinstance(cell, Bad) else "a list"
