"""Device tables as one YAML file (the format of ``examples/motor/motor.yaml``).

Rules:
1. The document is a mapping with ``device``, ``states``, ``events``, an
   optional ``data`` mapping and an optional ``recovery`` list of rows
   (``state`` with ``event`` and ``data``, or ``redo: yes``); anything else at
   the top is T102 or T103.
2. The node tree is composed (not constructed, :mod:`statectl.front.tables.safeyaml`:
   no aliases, bounded nesting) so every row and cell keeps its
   1-based line; only ``data`` values and a recovery row's ``data`` are
   constructed, as YAML values. A state or event row of scalars comes as a
   :class:`~statectl.front.tables.safeyaml.FlatRow` (texts and lines, no nodes) and is
   read as its nodes would be (tests/test_yaml_flat_rows.py holds the two the same).
3. A cell is a scalar (its text as written; ``null`` is empty) or, for the list
   columns, a sequence of scalars; a mapping anywhere else is T108.
4. The writer leaves out empty optional cells and writes ``kind`` always, so
   a written file reads like the hand-written Motor; ``recovery`` comes last,
   its ``data`` in flow style (``data: {detail: restarted}``), a redo row as
   ``redo: yes``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

import yaml

from statectl.front.tables.cells import (
    PLAIN_EVENT,
    PLAIN_STATE,
    plain_event_row,
    plain_state_row,
)
from statectl.front.tables.eventdata import format_assign, format_fields, yaml_event_cell
from statectl.front.tables.literals import (
    format_literal,
    normalize_payload,
    normalize_value,
    to_plain,
)
from statectl.front.tables.rows import (
    Bad,
    Cell,
    DeviceTables,
    EventRow,
    RawRow,
    RawTable,
    StateRow,
    diag,
    normalize_column,
)
from statectl.front.tables.safeyaml import FlatRow, YamlRefused, compose, construct
from statectl.front.tables.schema import make_tables
from statectl.kernel.errors import Diagnostic, Location

__all__ = ["dump_yaml", "read_yaml"]

NULL_TAG = "tag:yaml.org,2002:null"
TOP_KEYS = ("device", "profile", "states", "events", "data", "recovery")


#: The location made last: a row's cells share their line (reused, not rebuilt per cell).
_last_at = [Location("", None)]
#: A key as written -> its column name: a file repeats a few keys on every row.
_columns: dict[str, str] = {}


def _at(file: str, node: yaml.Node) -> Location:
    return _at_line(file, node.start_mark.line + 1)


def _at_line(file: str, line: int) -> Location:
    last = _last_at[0]
    if last.line == line and last.file == file:
        return last
    made = _last_at[0] = Location(file, line)
    return made


def _column(key: str) -> str:
    name = _columns.get(key)
    if name is None:
        name = normalize_column(key)
        if len(_columns) < 1024:  # bounded: a file of unknown keys does not grow it
            _columns[key] = name
    return name


def _cell(node: yaml.Node) -> Cell:
    if isinstance(node, yaml.ScalarNode):
        return "" if node.tag == NULL_TAG else str(node.value)
    if isinstance(node, yaml.SequenceNode):
        items: list[str] = []
        for item in node.value:
            if not isinstance(item, yaml.ScalarNode):
                return Bad("a list holding a " + _kind_of(item))
            items.append("" if item.tag == NULL_TAG else str(item.value))
        return tuple(items)
    return Bad("a mapping")


def _kind_of(node: yaml.Node) -> str:
    if isinstance(node, yaml.MappingNode):
        return "mapping"
    if isinstance(node, yaml.SequenceNode):
        return "list"
    return "scalar"


def _pairs(
    file: str, node: yaml.MappingNode, diags: list[Diagnostic]
) -> list[tuple[str, yaml.Node, Location]]:
    """The mapping's (normalized key, value node, key location); duplicate keys are T101."""
    pairs: list[tuple[str, yaml.Node, Location]] = []
    seen: set[str] = set()
    for key, value in node.value:
        at = _at(file, key)
        if not isinstance(key, yaml.ScalarNode):
            diags.append(diag("T108", at, "a key must be text (got a " + _kind_of(key) + ")"))
            continue
        name = _column(str(key.value))
        if name in seen:
            diags.append(diag("T101", at, f"key {key.value!r} appears twice in one mapping"))
            continue
        seen.add(name)
        pairs.append((name, value, at))
    return pairs


def _table(
    file: str, table: str, node: yaml.Node, at: Location, diags: list[Diagnostic]
) -> RawTable | None:
    if isinstance(node, yaml.ScalarNode) and node.tag == NULL_TAG:
        return RawTable(table, at, ())
    if not isinstance(node, yaml.SequenceNode):
        diags.append(
            diag(
                "T108",
                _at(file, node),
                f"{table!r} must be a list of rows (got a {_kind_of(node)})",
                "start each row with '- '",
            )
        )
        return None
    rows: list[RawRow] = []
    for item in node.value:
        if type(item) is FlatRow:
            rows.append(_raw_row(file, table, item, diags))
            continue
        if not isinstance(item, yaml.MappingNode):
            diags.append(
                diag(
                    "T108",
                    _at(file, item),
                    f"a {table} row must be a mapping of columns (got a {_kind_of(item)})",
                )
            )
            continue
        rows.append(RawRow(_at(file, item), _row_cells(file, table, item, diags)))
    return RawTable(table, at, tuple(rows))


def _row_cells(
    file: str, table: str, item: yaml.MappingNode, diags: list[Diagnostic]
) -> dict[str, tuple[Cell, Location]]:
    """A row's cells by column, each with its value's location (as :func:`_pairs` and
    :func:`_row_cell` decide; a row of text cells, the usual row, takes the short way:
    this loop runs once per cell of a 100,000-row file)."""
    cells: dict[str, tuple[Cell, Location]] = {}
    scalar = yaml.ScalarNode
    plain = table != "recovery"  # a recovery row's data cell is constructed (_payload)
    at = _at(file, item)  # a cell on the row's line (or the last cell's) shares its location
    for key, value in item.value:
        if type(key) is not scalar:
            return _slow_row_cells(file, table, item, diags)
        name = key.value
        if name in cells or (_columns.get(name) or _column(name)) != name:
            return _slow_row_cells(file, table, item, diags)
        if type(value) is scalar and (plain or name != "data"):
            cell: Cell = "" if value.tag == NULL_TAG else str(value.value)
        else:
            cell = _row_cell(table, name, value)
        if value.start_mark.line + 1 != at.line:
            at = _at(file, value)
        cells[name] = (cell, at)
    return cells


_Read = StateRow | EventRow | None
#: A table's plain columns and how a plain row of it is read from its texts (cells.py).
_PLAIN: dict[str, tuple[frozenset[str], Callable[[dict[str, str], Location], _Read]]] = {
    "states": (PLAIN_STATE, plain_state_row),
    "events": (PLAIN_EVENT, plain_event_row),
}
#: The cells of a row read at once (:attr:`RawRow.read`): none, shared by every such row.
_NO_CELLS: Mapping[str, tuple[Cell, Location]] = MappingProxyType({})


def _raw_row(file: str, table: str, row: FlatRow, diags: list[Diagnostic]) -> RawRow:
    """A :class:`FlatRow` as a raw row: a plain row (text in plain columns only, each
    once, as cells.py reads the usual row) is read at once from its texts, with no cell
    and no location per cell; any other row gets its cells, as its nodes would."""
    where = _at_line(file, row.line)
    columns, read = _PLAIN[table]
    texts: dict[str, str] = {}
    for name, _, text, _ in row.entries:
        if name in texts or name not in columns:
            return RawRow(where, _flat_cells(file, where, row, diags))
        texts[name] = "" if text is None else text.strip()
    done = read(texts, where)
    if done is None:
        return RawRow(where, _flat_cells(file, where, row, diags))
    return RawRow(where, _NO_CELLS, done)


def _flat_cells(
    file: str, where: Location, row: FlatRow, diags: list[Diagnostic]
) -> dict[str, tuple[Cell, Location]]:
    """A :class:`FlatRow`'s cells, as :func:`_row_cells` reads the same row's nodes."""
    cells: dict[str, tuple[Cell, Location]] = {}
    at = where  # a cell on the row's line (or the last cell's) shares its location
    for name, _, text, line in row.entries:
        if name in cells or (_columns.get(name) or _column(name)) != name:
            return _slow_flat_cells(file, row, diags)
        if line != at.line:
            at = Location(file, line)
        cells[name] = ("" if text is None else text, at)
    return cells


def _slow_flat_cells(
    file: str, row: FlatRow, diags: list[Diagnostic]
) -> dict[str, tuple[Cell, Location]]:
    """Any :class:`FlatRow`: keys normalized, duplicates reported, as :func:`_pairs` does."""
    cells: dict[str, tuple[Cell, Location]] = {}
    for key, key_line, text, line in row.entries:
        name = _column(key)
        if name in cells:
            at = _at_line(file, key_line)
            diags.append(diag("T101", at, f"key {key!r} appears twice in one mapping"))
            continue
        cells[name] = ("" if text is None else text, _at_line(file, line))
    return cells


def _slow_row_cells(
    file: str, table: str, item: yaml.MappingNode, diags: list[Diagnostic]
) -> dict[str, tuple[Cell, Location]]:
    """Any row: keys normalized, duplicates and non-text keys reported (:func:`_pairs`)."""
    return {
        name: (_row_cell(table, name, value), _at(file, value))
        for name, value, _ in _pairs(file, item, diags)
    }


def _row_cell(table: str, column: str, node: yaml.Node) -> Cell:
    """A row's cell: recovery data and event data/assign mappings become shared text."""
    if (table, column) == ("recovery", "data"):
        return _payload(node)
    if table == "events":
        mapped = yaml_event_cell(column, node)
        if mapped is not None:
            return mapped
    return _cell(node)


def _construct(node: yaml.Node) -> object:
    """The node as a YAML value, or :class:`Bad` naming why it cannot be one."""
    try:
        return construct(node)
    except YamlRefused as exc:
        return Bad(exc.message)


def _payload(node: yaml.Node) -> Cell:
    """A recovery row's data as the cell text every format shares (a YAML flow value)."""
    value = normalize_payload(_construct(node))
    return value if isinstance(value, Bad) else format_literal(value)


def _data(
    file: str, node: yaml.Node, diags: list[Diagnostic]
) -> list[tuple[str, object, Location]]:
    if isinstance(node, yaml.ScalarNode) and node.tag == NULL_TAG:
        return []
    if not isinstance(node, yaml.MappingNode):
        diags.append(
            diag("T108", _at(file, node), f"'data' must be a mapping (got a {_kind_of(node)})")
        )
        return []
    entries: list[tuple[str, object, Location]] = []
    for key, value in node.value:
        at = _at(file, key)
        if not isinstance(key, yaml.ScalarNode):
            diags.append(diag("T108", at, "a data name must be text"))
            continue
        constructed = _construct(value)
        literal = constructed if isinstance(constructed, Bad) else normalize_value(constructed)
        entries.append((str(key.value), literal, at))
    return entries


def _flat_table(key: str) -> bool:
    """Whether a top key names a table whose rows may come as a :class:`FlatRow`: the
    state and event tables, the big ones (a recovery row's data is a YAML value)."""
    return _column(key) in ("states", "events")


def read_yaml(text: str, file: str) -> tuple[DeviceTables | None, list[Diagnostic]]:
    """Read a YAML device file; every problem becomes a diagnostic."""
    diags: list[Diagnostic] = []
    source = Location(file, 1)
    try:
        root = compose(text, flat=_flat_table)
    except YamlRefused as exc:
        return None, [diag(exc.code, Location(file, exc.line or 1), exc.message, exc.hint)]
    if root is None:
        return None, [
            diag("T102", source, "the file is empty", "write device:, states: and events:")
        ]
    if not isinstance(root, yaml.MappingNode):
        return None, [
            diag(
                "T102",
                _at(file, root),
                f"not a device file: the top level is a {_kind_of(root)}, not a mapping",
                "a device file is a mapping with device:, states: and events:",
            )
        ]
    pairs = _pairs(file, root, diags)
    found = {name: (value, at) for name, value, at in pairs}
    if not any(k in found for k in ("states", "events")):
        return None, [
            diag(
                "T102",
                source,
                "not a device file: it has neither 'states' nor 'events'",
                "a device file is a mapping with device:, states: and events:",
            )
        ]
    for name, _, at in pairs:
        if name not in TOP_KEYS:
            diags.append(
                diag("T103", at, f"unknown top-level key {name!r}", "known: " + ", ".join(TOP_KEYS))
            )
    device = ""
    if "device" in found:
        value, at = found["device"]
        cell = _cell(value)
        if isinstance(cell, str):
            device = cell
        else:
            diags.append(diag("T108", at, "'device' must be text"))
            device = "?"
    profile = ""
    if "profile" in found:  # the standard profile the device follows (docs/profiles.md)
        value, at = found["profile"]
        cell = _cell(value)
        if isinstance(cell, str):
            profile = cell
        else:
            diags.append(diag("T108", at, "'profile' must be text"))
    tables: dict[str, RawTable | None] = {}
    for table in ("states", "events"):
        if table not in found:
            diags.append(diag("T104", source, f"the file has no {table!r} table"))
            tables[table] = None
            continue
        value, at = found[table]
        tables[table] = _table(file, table, value, at, diags)
    data = _data(file, found["data"][0], diags) if "data" in found else []
    recovery = None
    if "recovery" in found:
        value, at = found["recovery"]
        recovery = _table(file, "recovery", value, at, diags)
    if "device" not in found:
        diags.append(diag("T104", source, "the file has no 'device' name", "add 'device: NAME'"))
        device = "?"
    result = make_tables(
        device, tables["states"], tables["events"], data, source, diags, recovery, profile
    )
    return result, diags


def _state_doc(tables: DeviceTables) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for s in tables.states:
        row: dict[str, Any] = {}
        if s.component:
            row["component"] = s.component
        if s.api:
            row["api"] = s.api
        row["state"] = s.state
        if len(s.controls) == 1:
            row["control"] = s.controls[0].value
        elif s.controls:
            row["control"] = [c.value for c in s.controls]
        if s.description:
            row["description"] = s.description
        if s.ignore:
            row["ignore"] = list(s.ignore)
        if s.parent:
            row["parent"] = s.parent
        if s.type is not None:
            row["type"] = s.type_text
        if len(s.default) == 1:
            row["default"] = s.default[0]
        elif s.default:
            row["default"] = list(s.default)
        if s.number:  # a whole number is written as one, so it reads back the same
            n = s.number
            whole = n.isascii() and n.isdigit() and len(n) < 19 and str(int(n)) == n
            row["number"] = int(n) if whole else n
        if s.timeout:
            row["timeout"] = s.timeout
        if s.defer:
            row["defer"] = list(s.defer)
        rows.append(row)
    return rows


def _event_doc(tables: DeviceTables) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for e in tables.events:
        row: dict[str, Any] = {"event": e.event}
        if e.condition:
            row["condition"] = e.condition
        if e.guard:
            row["guard"] = e.guard
        row["old"] = e.old
        row["new"] = e.new
        row["kind"] = e.kind.value
        if e.api:
            row["api"] = e.api
        if e.invoke:
            row["invoke"] = e.invoke
        if e.fields:
            row["data"] = format_fields(e.fields)
        if e.assign:
            row["assign"] = format_assign(e.assign)
        if e.unasked:
            row["unasked"] = _Yes()
        if e.severity is not None:
            row["severity"] = e.severity
        rows.append(row)
    return rows


class _Flow(dict[str, Any]):
    """A recovery row's data: written in flow style, as people write it."""


class _FlowList(list[Any]):
    """A list in a recovery row's data: flow style too."""


def _flow(value: object) -> object:
    if isinstance(value, dict):
        return _Flow((k, _flow(v)) for k, v in value.items())
    if isinstance(value, list | tuple):
        return _FlowList(_flow(v) for v in value)
    return value


class _Yes:
    """The ``redo`` cell of a redo row: written ``yes``, as people write it."""


def _recovery_doc(tables: DeviceTables) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for r in tables.recovery:
        row: dict[str, Any] = {"state": r.state}
        if r.redo:
            row["redo"] = _Yes()
        else:
            row["event"] = r.event
        if r.data is not None:
            row["data"] = _flow(r.data)
        rows.append(row)
    return rows


class _Dumper(yaml.SafeDumper):
    """Rows in block style, lists of names in flow style (``ignore: [a, b]``), as people write."""


def _represent_list(dumper: yaml.SafeDumper, data: list[Any]) -> yaml.Node:
    flow = all(not isinstance(item, list | dict) for item in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


def _represent_flow(dumper: yaml.SafeDumper, data: _Flow) -> yaml.Node:
    return dumper.represent_mapping("tag:yaml.org,2002:map", data, flow_style=True)


def _represent_flow_list(dumper: yaml.SafeDumper, data: _FlowList) -> yaml.Node:
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)


def _represent_yes(dumper: yaml.SafeDumper, data: _Yes) -> yaml.Node:
    return dumper.represent_scalar("tag:yaml.org,2002:bool", "yes")


_Dumper.add_representer(list, _represent_list)
_Dumper.add_representer(_Yes, _represent_yes)
_Dumper.add_representer(_Flow, _represent_flow)
_Dumper.add_representer(_FlowList, _represent_flow_list)


def dump_yaml(tables: DeviceTables) -> str:
    """The tables as YAML text in the Motor's layout."""
    doc: dict[str, Any] = {
        "device": tables.device,
        **({"profile": tables.profile} if tables.profile else {}),
        "states": _state_doc(tables),
        "events": _event_doc(tables),
    }
    if tables.data:
        doc["data"] = {name: to_plain(value) for name, value in tables.data}
    if tables.recovery:
        doc["recovery"] = _recovery_doc(tables)
    body = yaml.dump(
        doc,
        Dumper=_Dumper,
        sort_keys=False,
        allow_unicode=True,
        default_flow_style=False,
        width=100,
    )
    return f"# Device tables of {tables.device} (statectl).\n{body}"
