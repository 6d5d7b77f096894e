"""Device tables as Markdown: a heading and pipe tables a person can read and review.

Rules:
1. ``# Device: NAME`` names the device (else the file name); ``## States``,
   ``## Events`` and optional ``## Data`` and ``## Recovery`` each introduce the
   first pipe table after them. Other text is ignored.
2. A table is a header row, a ``---`` separator row, then rows; columns are
   matched by name as in every format.
3. In a cell, ``\\|`` is a pipe, ``\\\\`` a backslash, ``\\n`` a line break and
   ``\\r`` a carriage return, so any text survives a round trip.
4. Locations are the 1-based line of the row.
5. Blank lines (inside a table too), the header, short rows and cells past the header
   follow the rules every flat format shares (:mod:`statectl.front.tables.grid`). Since
   a blank line does not end a table, a second table under one heading is T101.
6. So is a table after the section's table has ended (after text, or under a second
   heading of the same name): its rows would otherwise be dropped without a word.
"""

from __future__ import annotations

import re

from statectl.front.tables.grid import FlatSource, data_entries, read_grid
from statectl.front.tables.rows import DeviceTables, RawTable, diag
from statectl.front.tables.schema import flat_tables, make_tables
from statectl.kernel.errors import Diagnostic, Location

__all__ = ["dump_md", "escape", "read_md", "unescape"]

DEVICE = re.compile(r"^#\s+device\s*:\s*(.*)$", re.IGNORECASE)
SECTION = re.compile(r"^##\s+(states|events|data|recovery)\s*$", re.IGNORECASE)
SEPARATOR = re.compile(r"^:?-+:?$")
PROFILE = re.compile(r"^profile\s*:\s*(.*)$", re.IGNORECASE)
UNESCAPE = {"|": "|", "\\": "\\", "n": "\n", "r": "\r"}


def escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("\n", "\\n").replace("\r", "\\r")


def unescape(text: str) -> str:
    out: list[str] = []
    i = 0
    while i < len(text):
        ch = text[i]
        if ch == "\\" and i + 1 < len(text) and text[i + 1] in UNESCAPE:
            out.append(UNESCAPE[text[i + 1]])
            i += 2
        else:
            out.append(ch)
            i += 1
    return "".join(out)


def split_row(line: str) -> list[str]:
    """The raw (still escaped) cells of a ``| a | b |`` line."""
    body = line.strip()
    if body.startswith("|"):
        body = body[1:]
    cells: list[str] = []
    buf: list[str] = []
    i = 0
    while i < len(body):
        ch = body[i]
        if ch == "\\" and i + 1 < len(body):
            buf.append(body[i : i + 2])
            i += 2
            continue
        if ch == "|":
            cells.append("".join(buf))
            buf = []
        else:
            buf.append(ch)
        i += 1
    if "".join(buf).strip():
        cells.append("".join(buf))
    return [c.strip() for c in cells]


#: What to do about a cell with text past the header, in Markdown's terms (grid rule 3).
FIX = "delete the stray cells or name their column in the header; write a pipe in a cell as \\|"


def _separator(text: str) -> bool:
    """The line is a ``|---|---|`` row."""
    cells = split_row(text)
    return bool(cells) and all(SEPARATOR.match(c) for c in cells)


def _parse_table(
    table: str, block: list[tuple[int, str]], file: str, diags: list[Diagnostic]
) -> RawTable | None:
    header_line = block[0][0]
    if len(block) < 2 or not _separator(block[1][1]):
        diags.append(
            diag(
                "T101",
                Location(file, block[1][0] if len(block) > 1 else header_line),
                f"the {table} table has no '|---|' separator under its header",
                "write a row such as |---|---| right under the header row",
            )
        )
        return None
    end = next((k for k in range(3, len(block)) if _separator(block[k][1])), len(block) + 1)
    if end <= len(block):  # a blank line does not end a table (rule 5): a second one is refused
        diags.append(
            diag(
                "T101",
                Location(file, block[end - 1][0]),
                f"a second table under '## {table.title()}': a section holds one table",
                "give the other table its own '## ' heading, or delete its header and "
                "'|---|' rows to go on with this one",
            )
        )
    records = [
        (line, [unescape(c) for c in split_row(text)])
        for line, text in (block[0], *block[2 : end - 1])
    ]
    return read_grid(FlatSource(table, file, f"the {table} table", FIX), records, diags)


def _another_table(table: str, line: int, first: int, file: str) -> Diagnostic:
    """Rule 6: a table after the section's own (after text, or under a repeated heading)."""
    return diag(
        "T101",
        Location(file, line),
        f"another {table} table after the one at line {first}: the file holds one, and "
        "its rows would not be read",
        f"move its rows into the table at line {first}, or put it under a heading other "
        "than States, Events, Data or Recovery",
    )


def read_md(text: str, file: str, stem: str) -> tuple[DeviceTables | None, list[Diagnostic]]:
    """Read a Markdown device file; ``stem`` names the device without a heading."""
    diags: list[Diagnostic] = []
    device: str | None = None
    profile: str | None = None
    section: str | None = None
    blocks: dict[str, list[tuple[int, str]]] = {}
    closed: set[str] = set()
    refused: set[str] = set()  # sections whose further table was reported
    for number, raw_line in enumerate(text.split("\n"), start=1):
        line = raw_line.rstrip("\r").strip()
        if line.startswith("#"):
            m = DEVICE.match(line)
            s = SECTION.match(line)
            if m and device is None:
                device = m.group(1).strip()
            if section is not None and section in blocks:
                closed.add(section)
            section = s.group(1).lower() if s else None
            continue
        if section is None and profile is None and (p := PROFILE.match(line)):
            profile = p.group(1).strip()  # a 'Profile: NAME' line before the first table
        if section is None:
            continue
        if section in closed:  # a table here would be lost: said once (rule 6)
            if line.startswith("|") and section not in refused:
                refused.add(section)
                diags.append(_another_table(section, number, blocks[section][0][0], file))
            continue
        if line.startswith("|"):
            blocks.setdefault(section, []).append((number, line))
        elif line and section in blocks:  # text ends the table; a blank line does not (grid)
            closed.add(section)
    if "states" not in blocks and "events" not in blocks:
        return None, [
            diag(
                "T102",
                Location(file, 1),
                "not a device file: no '## States' or '## Events' table",
                "write '# Device: NAME', then '## States' and '## Events' pipe tables",
            )
        ]
    tables: dict[str, RawTable | None] = {}
    for table in ("states", "events", "data", "recovery"):
        if table in blocks:
            tables[table] = _parse_table(table, blocks[table], file, diags)
        else:
            tables[table] = None
            if table in ("states", "events"):
                diags.append(
                    diag("T104", Location(file, 1), f"no '## {table.title()}' table in the file")
                )
    result = make_tables(
        device if device is not None else stem,
        tables["states"],
        tables["events"],
        data_entries(tables["data"], diags),
        Location(file, 1),
        diags,
        tables["recovery"],
        profile or "",
    )
    return result, diags


def _table(header: tuple[str, ...], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    for row in rows:
        lines.append("| " + " | ".join(escape(c) for c in row) + " |")
    return lines


def dump_md(tables: DeviceTables) -> str:
    """The tables as Markdown that :func:`read_md` reads back unchanged."""
    lines = [f"# Device: {tables.device}", ""]
    if tables.profile:
        lines += [f"Profile: {tables.profile}", ""]
    for n, (name, header, rows) in enumerate(flat_tables(tables)):
        if n:
            lines.append("")  # a blank line between one table and the next heading
        lines += [f"## {name.title()}", "", *_table(header, rows)]
    return "\n".join(lines) + "\n"
