"""A document's tables as cells with their places in the text: what the language server points at.

Rules:
1. The loaders say which line a problem is on; an editor needs the columns too.
   This module reads the same text again and keeps, for every cell, the span of
   its value and, for cells that hold names (a list column, a guard's quoted
   names), the span of each name.
2. YAML (device files and cells alike) is composed with the loaders' safe
   composer (:mod:`statectl.front.tables.safeyaml`): a row is a mapping in a
   top-level list, its cells are keyed by the key as written (device columns are
   normalised as the loader normalises them). CSV is read per line, with quotes;
   Markdown per ``|`` row under a ``## States`` (Events, Data, Recovery) heading.
3. Spans are 0-based lines and character offsets in the line (an editor's
   positions, counted in code points, which equals UTF-16 for text in the Basic
   Multilingual Plane). A YAML scalar spanning lines is placed on its first line.
4. Reading never fails: text that cannot be read yields fewer rows, and the
   loaders' diagnostics say why.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from statectl.front.tables import safeyaml
from statectl.front.tables.rows import normalize_column

__all__ = ["Grid", "GridCell", "Item", "Row", "Span", "read_grid", "split_items"]

#: The top-level lists of a device file whose entries are table rows.
DEVICE_TABLES = ("states", "events", "recovery")
#: The top-level lists of a cell file whose entries are mappings the server reads.
CELL_LISTS = ("links", "environment", "invariants", "recovery")
SECTION = re.compile(r"^##\s+(states|events|data|recovery)\s*$", re.IGNORECASE)
QUOTED = re.compile(r"'([^'\\]*)'|\"([^\"\\]*)\"")


@dataclass(frozen=True, slots=True)
class Span:
    """Where a text is: a 0-based line and the characters ``start`` to ``end`` in it."""

    line: int
    start: int
    end: int

    def holds(self, line: int, character: int) -> bool:
        return line == self.line and self.start <= character <= self.end


@dataclass(frozen=True, slots=True)
class Item:
    """One name in a cell (an entry of a list cell, a quoted name in an expression)."""

    text: str
    span: Span


@dataclass(frozen=True, slots=True)
class GridCell:
    """A cell: its column, its text and where the text is (``node`` for YAML cells)."""

    column: str
    text: str
    span: Span
    node: yaml.Node | None = None


@dataclass(frozen=True, slots=True)
class Row:
    """A row of a table (or an entry of a cell's list): its cells by column."""

    table: str
    line: int  # 0-based, the row's first line
    cells: Mapping[str, GridCell]
    node: yaml.MappingNode | None = None  # the YAML mapping, for edits that add a cell
    last_line: int = -1  # 0-based, the row's last line

    def text(self, column: str) -> str:
        cell = self.cells.get(column)
        return cell.text if cell is not None else ""


@dataclass(frozen=True, slots=True)
class Grid:
    """Every row of a document, and the header cells of CSV and Markdown tables."""

    format: str  # "yaml" | "csv" | "md"
    rows: tuple[Row, ...] = ()
    headers: Mapping[str, tuple[GridCell, ...]] = field(default_factory=dict)

    def table(self, name: str) -> Iterator[Row]:
        return (r for r in self.rows if r.table == name)

    def row_at(self, line: int) -> Row | None:
        return next((r for r in self.rows if r.line <= line <= max(r.line, r.last_line)), None)


def split_items(cell: GridCell, lines: list[str]) -> list[Item]:
    """The comma-separated names of a list cell (a YAML list: each entry), with their spans."""
    node = cell.node
    if isinstance(node, yaml.SequenceNode):
        return [
            Item(str(n.value), _node_span(n, lines))
            for n in node.value
            if isinstance(n, yaml.ScalarNode)
        ]
    raw = _raw(cell.span, lines)
    out: list[Item] = []
    cursor = 0
    for part in cell.text.split(","):
        name = part.strip()
        if not name:
            continue
        at = raw.find(name, cursor)
        if at < 0:
            out.append(Item(name, cell.span))
            continue
        cursor = at + len(name)
        out.append(Item(name, Span(cell.span.line, cell.span.start + at, cell.span.start + cursor)))
    return out


def quoted_items(cell: GridCell, lines: list[str]) -> list[Item]:
    """The quoted texts of an expression cell (``In('Moving')``, ``previous == 'Moving'``)."""
    raw = _raw(cell.span, lines)
    out = []
    for m in QUOTED.finditer(raw):
        group = 1 if m.group(1) is not None else 2
        start = cell.span.start + m.start(group)
        out.append(Item(m.group(group), Span(cell.span.line, start, start + len(m.group(group)))))
    return out


def _raw(span: Span, lines: list[str]) -> str:
    text = lines[span.line] if 0 <= span.line < len(lines) else ""
    return text[span.start : span.end]


def _node_span(node: yaml.Node, lines: list[str]) -> Span:
    start, end = node.start_mark, node.end_mark
    line = start.line
    stop = end.column if end.line == line else len(lines[line]) if line < len(lines) else 0
    if isinstance(node, yaml.ScalarNode) and node.style in ("'", '"') and end.line == line:
        return Span(line, start.column + 1, max(stop - 1, start.column + 1))  # inside the quotes
    return Span(line, start.column, max(stop, start.column))


def read_grid(path: str, text: str) -> Grid:
    """The rows of ``text``, read as the file's suffix says (rule 2)."""
    suffix = Path(path).suffix.lower()
    lines = text.split("\n")
    if suffix in (".yaml", ".yml"):
        return _yaml_grid(text, lines)
    if suffix == ".csv":
        return _csv_grid(path, lines)
    if suffix in (".md", ".markdown"):
        return _md_grid(lines)
    return Grid("unknown")


# -- YAML -----------------------------------------------------------------------------------


def _yaml_grid(text: str, lines: list[str]) -> Grid:
    try:
        root = safeyaml.compose(text)
    except safeyaml.YamlRefused:
        return Grid("yaml")
    if not isinstance(root, yaml.MappingNode):
        return Grid("yaml")
    top = {str(k.value): v for k, v in root.value if isinstance(k, yaml.ScalarNode)}
    device = "states" in top or "events" in top
    rows: list[Row] = []
    for section in DEVICE_TABLES if device else CELL_LISTS:
        node = top.get(section)
        if isinstance(node, yaml.SequenceNode):
            rows.extend(
                _yaml_row(section, item, lines, normalize=device)
                for item in node.value
                if isinstance(item, yaml.MappingNode)
            )
    for section in ("data", "devices") if device else ("devices",):
        node = top.get(section)
        if isinstance(node, yaml.MappingNode):
            rows.extend(_named_entries(section, node, lines))
    for item in _violations(top.get("invariants")):
        rows.append(_yaml_row("on_violation", item, lines, normalize=False))
    rows.extend(_peer_lost(top.get("nodes"), lines))
    return Grid("yaml", tuple(rows))


def _yaml_row(table: str, node: yaml.MappingNode, lines: list[str], *, normalize: bool) -> Row:
    cells: dict[str, GridCell] = {}
    last = node.start_mark.line
    for key, value in node.value:
        if not isinstance(key, yaml.ScalarNode):
            continue
        column = normalize_column(str(key.value)) if normalize else str(key.value)
        text = str(value.value) if isinstance(value, yaml.ScalarNode) else ""
        if isinstance(value, yaml.ScalarNode) and value.tag.endswith(":null"):
            text = ""
        cells.setdefault(column, GridCell(column, text, _node_span(value, lines), value))
        end = value.end_mark
        last = max(last, end.line - 1 if end.column == 0 else end.line)
    return Row(table, node.start_mark.line, cells, node, last)


def _named_entries(section: str, node: yaml.MappingNode, lines: list[str]) -> Iterator[Row]:
    """``name: value`` entries (a device's data, a cell's devices) as rows ``name``, ``file``."""
    for key, value in node.value:
        if not isinstance(key, yaml.ScalarNode):
            continue
        cells = {"name": GridCell("name", str(key.value), _node_span(key, lines), key)}
        file = value
        if isinstance(value, yaml.MappingNode):  # {file: arm.yaml}
            file = next((v for k, v in value.value if getattr(k, "value", "") == "file"), value)
        if isinstance(file, yaml.ScalarNode):
            cells["file"] = GridCell("file", str(file.value), _node_span(file, lines), file)
        yield Row(section, key.start_mark.line, cells, None, value.end_mark.line)


def _violations(node: yaml.Node | None) -> Iterator[yaml.MappingNode]:
    """The ``{to, send}`` entries of every invariant's ``on_violation``."""
    if not isinstance(node, yaml.SequenceNode):
        return
    for item in node.value:
        if not isinstance(item, yaml.MappingNode):
            continue
        for key, value in item.value:
            if getattr(key, "value", "") != "on_violation":
                continue
            entries = value.value if isinstance(value, yaml.SequenceNode) else [value]
            yield from (e for e in entries if isinstance(e, yaml.MappingNode))


def _peer_lost(node: yaml.Node | None, lines: list[str]) -> Iterator[Row]:
    """Each ``device: EVENT`` of every node's ``peer_lost`` as a row ``device``, ``event``."""
    if not isinstance(node, yaml.MappingNode):
        return
    for _, entry in node.value:
        fields = entry.value if isinstance(entry, yaml.MappingNode) else []
        lost = next((v for k, v in fields if getattr(k, "value", "") == "peer_lost"), None)
        for key, value in lost.value if isinstance(lost, yaml.MappingNode) else []:
            if isinstance(key, yaml.ScalarNode) and isinstance(value, yaml.ScalarNode):
                cells = {
                    "device": GridCell("device", str(key.value), _node_span(key, lines), key),
                    "event": GridCell("event", str(value.value), _node_span(value, lines), value),
                }
                yield Row("peer_lost", key.start_mark.line, cells, None, value.end_mark.line)


# -- CSV and Markdown -----------------------------------------------------------------------


def _csv_fields(line: str) -> list[tuple[str, int, int]]:
    """The fields of one CSV line: text (unquoted) and where the field's content is."""
    out: list[tuple[str, int, int]] = []
    i, n = 0, len(line)
    while i <= n:
        if i < n and line[i] == '"':
            j, buf = i + 1, []
            while j < n and not (line[j] == '"' and line[j + 1 : j + 2] != '"'):
                buf.append(line[j])
                j += 2 if line[j] == '"' else 1
            out.append(("".join(buf), i + 1, j))
            i = line.find(",", j)
        else:
            comma = line.find(",", i)
            stop = n if comma < 0 else comma
            out.append((line[i:stop], i, stop))
            i = comma
        if i < 0:
            break
        i += 1
    return out


def _csv_table(path: str) -> str:
    name = Path(path).name.lower()
    for table in ("states", "events", "data", "recovery"):
        if name.endswith(f".{table}.csv"):
            return table
    return "states"


def _fields_row(
    table: str, line_no: int, header: list[str], fields: list[tuple[str, int, int]]
) -> Row:
    cells: dict[str, GridCell] = {}
    for column, (value, start, end) in zip(header, fields, strict=False):
        if column:
            cells[column] = GridCell(column, value.strip(), Span(line_no, start, end))
    return Row(table, line_no, cells, None, line_no)


def _csv_grid(path: str, lines: list[str]) -> Grid:
    table = _csv_table(path)
    rows: list[Row] = []
    header: list[str] | None = None
    headers: dict[str, tuple[GridCell, ...]] = {}
    for n, line in enumerate(lines):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = _csv_fields(line.rstrip("\r"))
        if header is None:
            header = [normalize_column(f[0]) for f in fields]
            headers[table] = tuple(
                GridCell(c, f[0], Span(n, f[1], f[2])) for c, f in zip(header, fields, strict=True)
            )
            continue
        rows.append(_fields_row(table, n, header, fields))
    return Grid("csv", tuple(rows), headers)


def _md_fields(line: str) -> list[tuple[str, int, int]]:
    """The cells of a ``| a | b |`` line: trimmed text and where it is."""
    out: list[tuple[str, int, int]] = []
    start = line.find("|") + 1
    i = start
    while i < len(line):
        if line[i] == "\\":
            i += 2
            continue
        if line[i] == "|":
            out.append(_trimmed(line, start, i))
            start = i + 1
        i += 1
    if line[start:].strip():
        out.append(_trimmed(line, start, len(line)))
    return out


def _trimmed(line: str, start: int, end: int) -> tuple[str, int, int]:
    raw = line[start:end]
    left = len(raw) - len(raw.lstrip())
    text = raw.strip()
    begin = start + left if text else start + min(1, len(raw))
    return text, begin, begin + len(text)


def _md_grid(lines: list[str]) -> Grid:
    rows: list[Row] = []
    headers: dict[str, tuple[GridCell, ...]] = {}
    table: str | None = None
    header: list[str] | None = None
    for n, line in enumerate(lines):
        m = SECTION.match(line.strip())
        if m:
            table, header = m.group(1).lower(), None
            continue
        if table is None or not line.lstrip().startswith("|"):
            if header is not None and not line.strip():
                table, header = None, None  # the first table after a heading only
            continue
        fields = _md_fields(line)
        if header is None:
            header = [normalize_column(f[0]) for f in fields]
            headers[table] = tuple(
                GridCell(c, f[0], Span(n, f[1], f[2])) for c, f in zip(header, fields, strict=True)
            )
        elif not all(set(f[0]) <= set(":-") and f[0] for f in fields):
            rows.append(_fields_row(table, n, header, fields))
    return Grid("md", tuple(rows), headers)
