"""The Event Definition table's ``data`` and ``assign`` columns, in every table format.

Rules:
1. ``data`` declares the fields an event carries and their types:
   ``pressure: float, part: str`` (braces optional; a YAML row may give a
   mapping). Types are those of :data:`FIELD_TYPES`; a field name is an
   identifier not starting with ``_``. Anything else is T122.
2. ``assign`` changes the device's data when the row's transition is taken:
   ``indexed = indexed + 1; total = total + _event.data.amount`` (statements
   separated by ``;`` or new lines), or a mapping ``{indexed: indexed + 1}`` (in
   a YAML row, or a cell starting with ``{``), whose values are expressions. A
   target is a plain name, once per cell; anything else is T123. The expressions
   are checked by the build (names, the safe language), not here.
3. The cells are kept as parsed tuples (hashable, like every row value); writers
   emit both columns only when some row uses them, so older tables look as before.
"""

from __future__ import annotations

import ast
from collections.abc import Sequence
from typing import Any

import yaml

from statectl.front.tables.literals import parse_payload
from statectl.front.tables.rows import Bad, Cell, RawRow, diag
from statectl.front.tables.safeyaml import YamlRefused, construct
from statectl.kernel.errors import Diagnostic, Location
from statectl.kernel.model import FIELD_TYPES

__all__ = [
    "Assignments",
    "Fields",
    "assign_cell",
    "event_columns",
    "event_data_cells",
    "fields_cell",
    "format_assign",
    "format_fields",
    "parse_assign",
    "parse_fields",
    "yaml_event_cell",
]

#: ``((field, type), ...)`` in declaration order.
Fields = tuple[tuple[str, str], ...]
#: ``((target, expression text), ...)`` in the order they are written.
Assignments = tuple[tuple[str, str], ...]

_TYPES_TEXT = ", ".join(FIELD_TYPES)


def _usable(name: str) -> bool:
    return name.isidentifier() and not name.startswith("_")


def parse_fields(text: str) -> Fields | str:
    """The declared fields of a ``data`` cell, or what is wrong with it."""
    body = text.strip()
    if body.startswith("{") and body.endswith("}"):
        body = body[1:-1]
    fields: list[tuple[str, str]] = []
    for part in body.split(","):
        if not part.strip():
            continue
        name, colon, kind = part.partition(":")
        name, kind = name.strip(), kind.strip().lower()
        if not colon or not name:
            return f"{part.strip()!r} is not 'name: type'"
        if not _usable(name):
            return f"field name {name!r} is not an identifier (or starts with '_')"
        if kind not in FIELD_TYPES:
            return f"field {name!r} has unknown type {kind!r} (types: {_TYPES_TEXT})"
        if any(name == f for f, _ in fields):
            return f"field {name!r} is declared twice"
        fields.append((name, kind))
    return tuple(fields)


def format_fields(fields: Fields) -> str:
    return ", ".join(f"{name}: {kind}" for name, kind in fields)


def _expression_text(value: object) -> str:
    """A mapping value as expression text: text as written, other YAML values as literals."""
    return value if isinstance(value, str) else repr(value)


def _pairs_checked(pairs: Sequence[tuple[str, str]]) -> Assignments | str:
    seen: set[str] = set()
    for target, expr in pairs:
        if not _usable(target):
            return f"assignment target {target!r} is not a data name"
        if target in seen:
            return f"{target!r} is assigned twice in one cell"
        if not expr.strip():
            return f"{target!r} is assigned nothing"
        seen.add(target)
    return tuple((t, e.strip()) for t, e in pairs)


def parse_assign(text: str) -> Assignments | str:
    """The assignments of an ``assign`` cell, or what is wrong with it."""
    body = text.strip()
    if not body:
        return ()
    if body.startswith("{"):
        value = parse_payload(body)
        if isinstance(value, Bad) or not isinstance(value, dict):
            found = value.found if isinstance(value, Bad) else type(value).__name__
            return f"not a mapping of data name -> expression ({found})"
        return _pairs_checked([(str(k), _expression_text(v)) for k, v in value.items()])
    try:
        module = ast.parse(body, mode="exec")
    except (SyntaxError, ValueError, RecursionError, MemoryError) as exc:
        msg = exc.msg if isinstance(exc, SyntaxError) else "unreadable"
        return f"does not parse as 'name = expression; ...': {msg}"
    pairs: list[tuple[str, str]] = []
    for stmt in module.body:
        if not (
            isinstance(stmt, ast.Assign)
            and len(stmt.targets) == 1
            and isinstance(stmt.targets[0], ast.Name)
        ):
            shown = ast.get_source_segment(body, stmt) or type(stmt).__name__
            return f"{shown!r} is not 'name = expression'"
        segment = ast.get_source_segment(body, stmt.value)
        pairs.append((stmt.targets[0].id, segment or ast.unparse(stmt.value)))
    return _pairs_checked(pairs)


def format_assign(assignments: Assignments) -> str:
    return "; ".join(f"{target} = {expr}" for target, expr in assignments)


def _cell_text(row: RawRow, column: str, diags: list[Diagnostic]) -> tuple[str, Location] | None:
    got = row.cells.get(column)
    if got is None:
        return None
    value, where = got
    if isinstance(value, Bad):
        diags.append(diag(value.code, where, f"{column!r} cannot be read ({value.found})"))
        return None
    if isinstance(value, tuple):
        value = ", ".join(value)
    return value, where


def fields_cell(row: RawRow, diags: list[Diagnostic]) -> Fields:
    """The row's ``data`` declaration (T122 when it is not ``name: type, ...``)."""
    got = _cell_text(row, "data", diags)
    if got is None or not got[0].strip():
        return ()
    parsed = parse_fields(got[0])
    if isinstance(parsed, str):
        diags.append(
            diag(
                "T122",
                got[1],
                f"event data declaration {got[0].strip()!r}: {parsed}",
                f"write the fields as 'pressure: float, part: str' (types: {_TYPES_TEXT})",
            )
        )
        return ()
    return parsed


def assign_cell(row: RawRow, diags: list[Diagnostic]) -> Assignments:
    """The row's ``assign`` actions (T123 when they are not ``name = expression; ...``)."""
    got = _cell_text(row, "assign", diags)
    if got is None:
        return ()
    parsed = parse_assign(got[0])
    if isinstance(parsed, str):
        diags.append(
            diag(
                "T123",
                got[1],
                f"assign {got[0].strip()!r}: {parsed}",
                "write 'indexed = indexed + 1; total = 0' or {indexed: indexed + 1}",
            )
        )
        return ()
    return parsed


def event_data_cells(row: RawRow, diags: list[Diagnostic]) -> dict[str, Any]:
    """The ``data`` and ``assign`` values of an event row, as EventRow keyword arguments."""
    return {"fields": fields_cell(row, diags), "assign": assign_cell(row, diags)}


def yaml_event_cell(column: str, node: yaml.Node) -> Cell | None:
    """A YAML event row's ``data`` or ``assign`` mapping as the cell text every format
    shares; ``None`` when the node is not such a mapping (the usual cell rules apply)."""
    if column not in ("data", "assign") or not isinstance(node, yaml.MappingNode):
        return None
    try:
        value = construct(node)
    except YamlRefused as exc:
        return Bad(exc.message, exc.code if exc.code in ("T115", "T116") else "T108")
    if not isinstance(value, dict):
        return Bad("a mapping that is not a plain mapping")
    if column == "data":
        return ", ".join(f"{k}: {v}" for k, v in value.items())
    return "; ".join(f"{k} = {_expression_text(v)}" for k, v in value.items())


def event_columns(events: Sequence[Any], flat: Sequence[str]) -> tuple[str, ...]:
    """The event columns a writer emits: ``flat``, plus ``data``/``assign`` when used."""
    extra = []
    if any(e.fields for e in events):
        extra.append("data")
    if any(e.assign for e in events):
        extra.append("assign")
    if any(getattr(e, "unasked", False) for e in events):
        extra.append("unasked")
    if any(getattr(e, "severity", None) is not None for e in events):
        extra.append("severity")
    return (*flat, *extra)


def event_cells(e: Any, columns: Sequence[str]) -> list[str]:
    """One event row's cells for the columns a writer emits (the flat ones, then extras)."""
    return [
        e.event,
        e.condition,
        e.guard,
        e.old,
        e.new,
        e.kind.value,
        e.api,
        e.invoke,
        *event_extra_cells(e, columns),
    ]


def event_extra_cells(e: Any, columns: Sequence[str]) -> list[str]:
    """The ``data``/``assign`` cells of one event row, for the columns a writer emits."""
    out: list[str] = []
    if "data" in columns:
        out.append(format_fields(e.fields))
    if "assign" in columns:
        out.append(format_assign(e.assign))
    if "unasked" in columns:
        out.append("yes" if e.unasked else "")
    if "severity" in columns:
        out.append("" if e.severity is None else str(e.severity))
    return out
