"""Completion: column names where a column is named, and the names a cell may hold.

Rules:
1. Where the cursor is decides the list: at a key (YAML) or in a header row (CSV,
   Markdown), the table's column names; in a cell, by its column: state names
   (``old``, ``new``, ``parent``, ``default``, the Recovery ``state``), event
   names (``event``, ``ignore``, ``defer``, the Recovery ``event``; ``ignore``
   also ``all others``), the device's APIs (``api``), the words of ``control``,
   ``type`` and ``kind``, and ``In('State')`` in a guard.
2. In a cell file the names are those of the devices the row names: a link's
   ``enters`` offers its ``from`` device's states, ``send`` its ``to`` device's
   events, ``from`` and ``to`` the cell's instances, an expression
   ``In('device.State')`` for every instance and state.
3. At the top level of a YAML file, the file's section names.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from statectl.cell.reader import ENVIRONMENT_FIELDS, INVARIANT_FIELDS, LINK_FIELDS
from statectl.cell.reader import RECOVERY_FIELDS as GOAL_FIELDS
from statectl.cell.values import TOP_KEYS as CELL_KEYS
from statectl.channels.lsp.documents import Document, FileKind, Project
from statectl.channels.lsp.index import Kind, device_key
from statectl.channels.runconfig import RUN_CONFIG_KEYS
from statectl.front.tables.rows import COLUMNS, CONTROL_WORDS, TYPE_NAMES, normalize_column
from statectl.front.tables.yaml_io import TOP_KEYS as DEVICE_KEYS
from statectl.kernel.model import EventKind
from statectl.run.devices.config import DEVICE_KEYS as DRIVER_KEYS
from statectl.run.devices.config import DRIVERS

__all__ = ["Candidate", "complete"]

#: (label, what it is)
Candidate = tuple[str, str]

STATE_COLUMNS = frozenset({"old", "new", "parent", "default"})
EVENT_COLUMNS = frozenset({"event", "ignore", "defer", "timeout"})
CELL_FIELDS = {
    "links": LINK_FIELDS,
    "environment": ENVIRONMENT_FIELDS,
    "invariants": INVARIANT_FIELDS,
    "recovery": GOAL_FIELDS,
    "on_violation": ("to", "send"),
}
EXPRESSION_KEYS = frozenset({"guard", "when", "holds"})
SECTION = re.compile(r"^([A-Za-z_]+)\s*:")


def complete(project: Project, doc: Document, line: int, character: int) -> list[Candidate]:
    """Rules 1-3: what may be written at the cursor."""
    lines = doc.lines
    if not 0 <= line < len(lines):
        return []  # a position past the text: nothing is written there
    prefix = lines[line][:character]
    table, key = _place(doc, lines, line, prefix)
    if doc.kind is FileKind.RUN_CONFIG:
        if key == "driver":
            return [(d, "driver") for d in DRIVERS]
        return [(k, "section") for k in (DRIVER_KEYS if table == "devices" else RUN_CONFIG_KEYS)]
    if doc.kind is FileKind.CELL:
        return _in_cell(project, doc, line, table, key)
    if table is None:
        return [(k, "section") for k in DEVICE_KEYS]
    if key is None:
        return [(c, f"{table} column") for c in COLUMNS.get(table, ())]
    docs = project.device_documents(device_key(doc.path)) if doc.grid.format == "csv" else []
    docs = [doc, *(d for d in docs if d.path != doc.path)]  # a CSV pair's names are in both
    return _in_device(docs, table, normalize_column(key))


def _place(
    doc: Document, lines: list[str], line: int, prefix: str
) -> tuple[str | None, str | None]:
    """The table the cursor is in and the column of its cell (``None``: where a key goes)."""
    if doc.grid.format in ("csv", "md"):
        row = doc.grid.row_at(line)
        for table, header in doc.grid.headers.items():
            if header and header[0].span.line == line:
                return table, None
            if row is not None and row.table == table:
                cells = sorted(row.cells.values(), key=lambda c: c.span.start)
                before = [c for c in cells if c.span.start <= len(prefix)]
                return table, (before[-1].column if before else cells[0].column if cells else None)
        return None, None
    section = next(
        (m.group(1) for text in reversed(lines[: line + 1]) if (m := SECTION.match(text))), None
    )
    if section is not None and SECTION.match(lines[line]) and ":" not in prefix:
        return None, None  # typing a top-level key
    return section, _yaml_key(prefix)


def _yaml_key(prefix: str) -> str | None:
    """The key whose value the cursor is in on this line, ``None`` where a key is typed.

    Each ``{`` opens a mapping whose commas separate entries; a ``[`` is a list value,
    whose commas do not.
    """
    frames: list[list[object]] = [["", None, 0]]  # opener, key, where the entry starts
    for i, ch in enumerate(prefix):
        frame = frames[-1]
        if ch in "{[":
            frames.append([ch, None, i + 1])
        elif ch in "}]" and len(frames) > 1:
            frames.pop()
        elif ch == "," and frame[0] == "{":
            frame[1], frame[2] = None, i + 1
        elif ch == ":" and frame[0] != "[" and frame[1] is None:
            start = frame[2]
            assert isinstance(start, int)
            frame[1] = prefix[start:i].strip().lstrip("-").strip().strip("'\"")
    key = next(f[1] for f in reversed(frames) if f[0] != "[")
    return str(key) if key else None


def _names(docs: Iterable[Document], kind: Kind) -> list[str]:
    return list(
        dict.fromkeys(s.name for d in docs for s in d.symbols if s.kind is kind and s.definition)
    )


def _in_device(docs: list[Document], table: str, key: str) -> list[Candidate]:
    states = [(n, "state") for n in _names(docs, Kind.STATE)]
    events = [(n, "event") for n in _names(docs, Kind.EVENT)]
    if key in STATE_COLUMNS or (key == "state" and table == "recovery"):
        return states
    if key == "ignore":
        return [*events, ("all others", "every event this state does not handle")]
    if key in EVENT_COLUMNS or (key == "event" and table == "recovery"):
        return events
    if key == "api":
        apis = (r.text("api") for d in docs for r in d.grid.rows if r.table in ("states", "events"))
        return [(a, "API") for a in dict.fromkeys(_split(apis))]
    if key == "control":
        return [(w, "control") for w in CONTROL_WORDS if " " in w or w == "default"]
    if key == "type":
        return [(w, "type") for w in TYPE_NAMES.values()]
    if key == "kind":
        return [(k.value, "kind") for k in EventKind if k is not EventKind.INTERNAL]
    if key == "guard":
        return [(f"In('{n}')", "state") for n, _ in states]
    return [*states, *events]


def _split(cells: Iterable[str]) -> Iterable[str]:
    for text in cells:
        yield from (p.strip() for p in text.split(",") if p.strip())


def _in_cell(
    project: Project, doc: Document, line: int, table: str | None, key: str | None
) -> list[Candidate]:
    if table is None:
        return [(k, "section") for k in CELL_KEYS]
    if key is None:
        return [(k, f"{table} key") for k in CELL_FIELDS.get(table, ())]
    row = doc.grid.row_at(line)
    instances = [(n, "device") for n in doc.devices]
    if key in ("from", "to") and table in ("links", "environment", "on_violation"):
        return instances
    if key in EXPRESSION_KEYS or table == "recovery":
        return [
            (f"In('{name}.{state}')", "state")
            for name in doc.devices
            for state in _device_names(project, doc, name, Kind.STATE)
        ]
    if row is None:
        return []
    source, target = row.text("from"), row.text("to")
    if key == "enters":
        return [(s, "state") for s in _device_names(project, doc, source, Kind.STATE)]
    if key in ("raises", "dropped"):
        return [(e, "event") for e in _device_names(project, doc, source, Kind.EVENT)]
    if key in ("send", "fault"):
        return [(e, "event") for e in _device_names(project, doc, target, Kind.EVENT)]
    return []


def _device_names(project: Project, doc: Document, instance: str, kind: Kind) -> list[str]:
    key = doc.devices.get(instance)
    if key is None:
        return []
    docs = project.device_documents(key)
    return _names(docs, kind)
