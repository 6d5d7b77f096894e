"""Code actions: the diagnostics whose hint is a mechanical edit, made for the user.

Rules:
1. C404 (a state neither handles nor ignores events): add the events named in
   the message to the state's ``ignore`` column, keeping what it lists.
2. B233 (a guard reads a field of an event that declares no data) and B232 (a
   field the event does not declare): declare the field, typed ``any``, on every
   row of the event (rows of one event must declare the same data, B230).
3. A hint that says "did you mean 'Moving'?" replaces the name the diagnostic is
   placed on (the server places it on the name the message quotes) by the
   suggestion, in every file kind: an unknown state, event, column or driver.
4. Edits keep the file's format: in YAML a flow list or mapping grows in place,
   a block one gets a line, a missing key is added to its row; in CSV and
   Markdown the cell is rewritten (quoted or escaped as the format needs). A
   CSV or Markdown table without the column gets no action: adding a column
   is a change to every row, which the user should make.
"""

from __future__ import annotations

import ast
import json
import re

import yaml

from statectl.channels.lsp.documents import Document
from statectl.channels.lsp.grid import GridCell, Row, Span, split_items

__all__ = ["Change", "Fix", "fixes"]

#: Replace the text from (line, character) to (line, character) with this text.
Change = tuple[int, int, int, int, str]
#: A code action: its title and its changes to the document.
Fix = tuple[str, list[Change]]

C404 = re.compile(r"^state (.+?) neither handles nor ignores (.+?)(?: and \d+ more)? \(missed")
_NONE = r" of event (.+?), which declares no data"
_UNDECLARED = r", which event (.+?) does not declare"
FIELD = re.compile(rf"reads field (.+?)(?:{_NONE}|{_UNDECLARED})")
PLAIN = re.compile(r"^[A-Za-z_][\w .()-]*$")
MEANT = re.compile(r"did you mean ('[^']*'|\"[^\"]*\")\?")
QUOTED = re.compile(r"'([^']+)'")


def fixes(
    doc: Document, code: str, message: str, line: int, hint: str = "", span: Span | None = None
) -> list[Fix]:
    """The fixes for one diagnostic of ``doc`` placed at ``span`` (rules 1-3)."""
    return [*_fixes(doc, code, message), *_meant(doc, message, hint, span)]


def _meant(doc: Document, message: str, hint: str, span: Span | None) -> list[Fix]:
    """Rule 3: the name the diagnostic is placed on, replaced by the hint's suggestion."""
    m = MEANT.search(hint)
    if m is None or span is None or not 0 <= span.line < len(doc.lines):
        return []
    word, meant = doc.lines[span.line][span.start : span.end], _literal(m.group(1))
    if not word.strip() or word == meant or word not in QUOTED.findall(message):
        return []  # only a name the message quotes (what was not found) is replaced
    change = (span.line, span.start, span.line, span.end, meant)
    return [(f"Change {word!r} to {meant!r}", [change])]


def _fixes(doc: Document, code: str, message: str) -> list[Fix]:
    if code == "C404" and (m := C404.match(message)):
        state, names = _literal(m.group(1)), [_literal(n) for n in m.group(2).split(", ")]
        row = next((r for r in doc.grid.table("states") if r.text("state") == state), None)
        changes = _add_items(doc, row, "ignore", names) if row is not None else []
        shown = ", ".join(names)
        return [(f"Ignore {shown} in state {state}", changes)] if changes else []
    if code in ("B232", "B233") and (m := FIELD.search(message)):
        field, event = _literal(m.group(1)), _literal(m.group(2) or m.group(3))
        rows = [r for r in doc.grid.table("events") if r.text("event") == event]
        changes = [c for r in rows for c in _declare(doc, r, field)]
        if changes and len(changes) >= len(rows):
            return [(f"Declare data field {field} on event {event}", changes)]
    return []


def _literal(text: str) -> str:
    try:
        value = ast.literal_eval(text.strip())
    except (ValueError, SyntaxError):
        return text.strip().strip("'\"")
    return str(value)


def _flow(name: str) -> str:
    return (
        name
        if PLAIN.match(name) and name.lower() not in ("yes", "no", "null")
        else json.dumps(name)
    )


def _add_items(doc: Document, row: Row, column: str, names: list[str]) -> list[Change]:
    """Rule 1's edit: ``names`` appended to a list cell."""
    cell = row.cells.get(column)
    if doc.grid.format != "yaml":
        if cell is None:
            return []
        old = [i.text for i in split_items(cell, doc.lines)]
        return [_rewrite(doc, cell, ", ".join([*old, *names]))]
    if cell is None:
        return _add_key(row, column, "[" + ", ".join(_flow(n) for n in names) + "]")
    node = cell.node
    if isinstance(node, yaml.SequenceNode):
        return _grow(node, [_flow(n) for n in names], "[]")
    old = [i.text for i in split_items(cell, doc.lines)]
    text = "[" + ", ".join(_flow(n) for n in [*old, *names]) + "]"
    return [_replace(cell, text, doc.lines)]


def _declare(doc: Document, row: Row, field: str) -> list[Change]:
    """Rule 2's edit on one event row: ``field: any`` in its ``data``."""
    cell = row.cells.get("data")
    if doc.grid.format != "yaml":
        if cell is None:
            return []
        return [_rewrite(doc, cell, ", ".join(p for p in (cell.text, f"{field}: any") if p))]
    entry = f"{_flow(field)}: any"
    if cell is None:
        return _add_key(row, "data", "{" + entry + "}")
    if isinstance(cell.node, yaml.MappingNode):
        return _grow(cell.node, [entry], "{}")
    if not cell.text:
        return [_replace(cell, "{" + entry + "}", doc.lines)]
    return []  # a data cell written as text in YAML: the user knows its shape


def _grow(node: yaml.CollectionNode, entries: list[str], brackets: str) -> list[Change]:
    """Append ``entries`` to a YAML list or mapping: inside a flow one, or as block lines."""
    items = node.value
    if node.flow_style or not items:
        end = node.end_mark
        text = (", " if items else "") + ", ".join(entries)
        if not node.flow_style:  # an empty block node: write the flow form in its place
            start = node.start_mark
            return [
                (start.line, start.column, end.line, end.column, brackets[0] + text + brackets[1])
            ]
        return [(end.line, end.column - 1, end.line, end.column - 1, text)]
    last = items[-1][1] if isinstance(node, yaml.MappingNode) else items[-1]
    first = items[0][0] if isinstance(node, yaml.MappingNode) else items[0]
    indent = " " * first.start_mark.column
    dash = "" if isinstance(node, yaml.MappingNode) else "- "
    if dash:
        indent = " " * max(first.start_mark.column - 2, 0)
    end = last.end_mark
    if end.column == 0:  # the last value ended its line (a block list): lines before the next
        text = "".join(f"{indent}{dash}{e}\n" for e in entries)
    else:
        text = "".join(f"\n{indent}{dash}{e}" for e in entries)
    return [(end.line, end.column, end.line, end.column, text)]


def _add_key(row: Row, key: str, value: str) -> list[Change]:
    """A new ``key: value`` in a YAML row: inside ``{...}``, or as a line of a block row."""
    node = row.node
    if node is None:
        return []
    if node.flow_style:
        end = node.end_mark
        return [(end.line, end.column - 1, end.line, end.column - 1, f", {key}: {value}")]
    return _grow(node, [f"{key}: {value}"], "{}")


def _replace(cell: GridCell, text: str, lines: list[str]) -> Change:
    """The cell's YAML value replaced by ``text`` (a space after the key's colon if none)."""
    node = cell.node
    assert node is not None
    start, end = node.start_mark, node.end_mark
    before = lines[start.line][: start.column] if start.line < len(lines) else ""
    lead = " " if before.endswith(":") else ""
    return (start.line, start.column, end.line, end.column, lead + text)


def _rewrite(doc: Document, cell: GridCell, text: str) -> Change:
    """A CSV or Markdown cell's content replaced by ``text``, quoted or escaped."""
    span = cell.span
    raw = doc.lines[span.line]
    if doc.grid.format == "csv":
        quoted = raw[span.start - 1 : span.start] == '"'
        start, end = (span.start - 1, span.end + 1) if quoted else (span.start, span.end)
        escaped = text.replace('"', '""')
        new = f'"{escaped}"' if any(c in text for c in ',"\n') else text
        return (span.line, start, span.line, end, new)
    escaped = text.replace("\\", "\\\\").replace("|", "\\|")
    padding = "" if raw[span.start - 1 : span.start] == " " else " "
    return (span.line, span.start, span.line, span.end, padding + escaped)
