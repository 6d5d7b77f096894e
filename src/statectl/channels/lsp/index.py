"""Where each state and event of a device is named: its row, and every use.

Rules:
1. A device's **definitions** are the ``state`` cells of the States table and the
   ``event`` cells of the Events table (an event on several rows is defined by
   its first and named by the others).
2. Its **uses** are a state's ``parent`` and ``default``, an event row's ``old``
   and ``new``, the names quoted in a guard that are states (``In('Moving')``,
   ``previous == 'Moving'``), a state's ``ignore`` and ``defer`` entries and the
   event of its ``timeout`` (``2s -> Close timeout``), and the Recovery table's
   ``state`` and ``event``.
3. A cell names a device's states and events through its instances: a link's
   ``enters``/``raises`` (of ``from``) and ``send`` (of ``to``, data after ``{``
   left out) and ``dropped`` (of ``from``), an environment entry's ``send`` or
   ``fault`` (of ``to``), ``on_violation``'s ``send``, and ``In('dev.State')`` in
   ``guard``, ``when``, ``holds`` and a recovery goal's ``to``/``from``, and a
   node's ``peer_lost`` event (of the device it names). Each
   such use carries the device file it points into, so a rename there renames
   it in the device and in every cell that uses it.
"""

from __future__ import annotations

import enum
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from statectl.channels.lsp.grid import Grid, GridCell, Item, Row, Span, quoted_items, split_items
from statectl.front.tables.csv_io import csv_paths

__all__ = [
    "Kind",
    "Symbol",
    "cell_symbols",
    "device_files",
    "device_key",
    "device_symbols",
]

#: Words of a list column that are no event's name.
KEYWORDS = frozenset({"all others", "*"})
#: A cell's expression keys, by the list they are in.
EXPRESSIONS = {
    "links": ("guard",),
    "environment": ("when",),
    "invariants": ("holds",),
    "recovery": ("to", "from"),
}


class Kind(enum.Enum):
    STATE = "state"
    EVENT = "event"


@dataclass(frozen=True, slots=True)
class Symbol:
    """One naming of a state or event: which, where, and whether it is the definition."""

    kind: Kind
    name: str
    span: Span
    file: str  # the absolute path of the device file the name belongs to
    definition: bool = False
    row: Row | None = None  # the row it is named in


def device_symbols(
    grid: Grid, lines: list[str], file: str, states: Iterable[str] = ()
) -> list[Symbol]:
    """Every definition and use in a device's tables (rules 1 and 2), in document order.

    ``file`` is the device's key (:func:`device_key`); ``states`` adds the state names a
    CSV events file's guards may quote, which its states file holds.
    """
    out: list[Symbol] = []
    states = {*states, *(r.text("state") for r in grid.table("states"))}
    seen_events: set[str] = set()

    def add(kind: Kind, items: Iterable[Item], row: Row, definition: bool = False) -> None:
        for item in items:
            if item.text and item.text.lower() not in KEYWORDS:
                out.append(Symbol(kind, item.text, item.span, file, definition, row))

    for row in grid.rows:
        cells = row.cells
        if row.table == "states":
            add(Kind.STATE, _whole(cells.get("state")), row, definition=True)
            add(Kind.STATE, _whole(cells.get("parent")), row)
            add(Kind.STATE, _listed(cells.get("default"), lines), row)
            add(Kind.EVENT, _listed(cells.get("ignore"), lines), row)
            add(Kind.EVENT, _listed(cells.get("defer"), lines), row)
            add(Kind.EVENT, _timeout_event(cells.get("timeout"), lines), row)
        elif row.table == "events":
            name = row.text("event")
            add(Kind.EVENT, _whole(cells.get("event")), row, definition=name not in seen_events)
            seen_events.add(name)
            add(Kind.STATE, _whole(cells.get("old")), row)
            add(Kind.STATE, _listed(cells.get("new"), lines), row)
            guard = cells.get("guard")
            quoted = quoted_items(guard, lines) if guard is not None else []
            add(Kind.STATE, (i for i in quoted if i.text in states), row)
        elif row.table == "recovery":
            add(Kind.STATE, _whole(cells.get("state")), row)
            add(Kind.EVENT, _whole(cells.get("event")), row)
    return out


def _whole(cell: GridCell | None) -> list[Item]:
    return [Item(cell.text, cell.span)] if cell is not None and cell.text else []


def _listed(cell: GridCell | None, lines: list[str]) -> list[Item]:
    if cell is None:
        return []
    return split_items(cell, lines)


def _timeout_event(cell: GridCell | None, lines: list[str]) -> list[Item]:
    """The event after ``->`` in ``2s -> Close timeout``."""
    if cell is None or "->" not in cell.text:
        return []
    name = cell.text.split("->", 1)[1].strip()
    raw = lines[cell.span.line][cell.span.start : cell.span.end]
    at = raw.find(name, raw.find("->"))
    if not name or at < 0:
        return []
    start = cell.span.start + at
    return [Item(name, Span(cell.span.line, start, start + len(name)))]


def device_key(path: str) -> str:
    """The one name of a device whatever file of it is given: its absolute path, or for a
    CSV pair its states file's (``motor.csv``, ``motor.events.csv`` -> ``motor.states.csv``)."""
    absolute = os.path.abspath(path)
    if not absolute.lower().endswith(".csv"):
        return absolute
    files = csv_paths(Path(absolute))
    return str(files.states) if files is not None else absolute


def device_files(grid: Grid, cell_file: str) -> dict[str, str]:
    """A cell's instances and the key (:func:`device_key`) of each one's device file."""
    base = Path(cell_file).parent
    return {
        r.text("name"): device_key(str(base / r.text("file")))
        for r in grid.table("devices")
        if r.text("file") and "\x00" not in r.text("file")
    }


def cell_symbols(grid: Grid, lines: list[str], files: Mapping[str, str]) -> list[Symbol]:
    """Every use of a device's state or event in a cell (rule 3)."""
    out: list[Symbol] = []

    def add(kind: Kind, device: str, cell: GridCell | None, row: Row, cut: bool = False) -> None:
        if cell is None or device not in files or not cell.text:
            return
        name = cell.text.split("{")[0].split("[")[0].strip() if cut else cell.text
        span = Span(cell.span.line, cell.span.start, cell.span.start + len(name))
        if name:
            out.append(Symbol(kind, name, span, files[device], False, row))

    for row in grid.rows:
        c = row.cells
        if row.table == "links":
            add(Kind.STATE, row.text("from"), c.get("enters"), row)
            add(Kind.EVENT, row.text("from"), c.get("raises"), row)
            add(Kind.EVENT, row.text("to"), c.get("send"), row, cut=True)
            add(Kind.EVENT, row.text("from"), c.get("dropped"), row)
        elif row.table == "environment":
            add(Kind.EVENT, row.text("to"), c.get("send") or c.get("fault"), row)
        elif row.table == "on_violation":
            add(Kind.EVENT, row.text("to"), c.get("send"), row)
        elif row.table == "peer_lost":
            add(Kind.EVENT, row.text("device"), c.get("event"), row)
        for key in EXPRESSIONS.get(row.table, ()):
            expression = c.get(key)
            if expression is not None:
                out.extend(_in_states(quoted_items(expression, lines), files, row))
    return out


def _in_states(items: Iterable[Item], files: Mapping[str, str], row: Row) -> Iterable[Symbol]:
    """``In('arm.Moving')``: the state part of each quoted ``device.State``."""
    for item in items:
        device, dot, state = item.text.partition(".")
        if dot and device in files and state:
            start = item.span.start + len(device) + 1
            span = Span(item.span.line, start, start + len(state))
            yield Symbol(Kind.STATE, state, span, files[device], False, row)
