"""The paper's two tables in memory, and the rules every file format shares.

Rules:
1. A device file holds a device name, a State Definition table, an Event
   Definition table, optional data (name -> literal initial value) and an
   optional Recovery table (state -> what a restarted device does first when it
   resumes in that state; checked against the chart by ``statectl.front.recovery``).
2. Columns are those of ``examples/motor/motor.yaml``: states ``component, api,
   state, control, description, ignore, parent`` plus the optional hierarchy
   columns ``type`` and ``default``; events ``event, condition, guard, old, new,
   kind, api, invoke``. Required: ``state`` in states and ``event``, ``old``,
   ``new`` in events. Column names are read leniently (case, spaces, ``_``, and
   the paper's long names such as "old state").
3. Every cell is text with its surrounding whitespace stripped; empty means absent.
4. ``control``, ``ignore`` and ``default`` are lists: a YAML list or one
   comma-separated cell, so an event name never contains a comma (T111).
   ``control`` values are read leniently; ``kind`` defaults to ``command``.
4a. ``type`` is blank (atomic, or compound when other rows name the state as
   their parent) or one of :data:`TYPE_WORDS` (T113 otherwise); ``default`` names
   where a history state goes before it has recorded anything. Writers emit the
   two columns only when some row uses them, so flat tables look as before.
5. Data values are YAML literals: null, booleans, numbers, strings and lists of
   them (kept as tuples so the tables stay hashable values).
5a. Recovery rows have columns ``state, event, data, redo`` (``state`` required).
   A row either posts an event (``event``, optional ``data``) or redoes the
   device work of the step that entered the state (``redo: yes``; no event, no
   data): exactly one of the two, else T104 (neither) or T114 (both, data on a
   redo row, or a ``redo`` that is none of yes/no/true/false; empty is no).
   ``data`` is the event's payload as a YAML flow value such as
   ``{detail: restarted}``: null, booleans, numbers, strings, lists and mappings
   with text keys, kept as plain lists and dicts because that is what a running
   device receives and the journal stores (a row with data is not hashable).
   Writers emit the ``redo`` column only when some row uses it.
6. Format readers turn a file into :class:`RawTable` values (cells with their
   locations); :func:`make_tables` turns those into :class:`DeviceTables` and
   reports every problem as a T1xx diagnostic, never stopping at the first.

This module assembles whole tables and checks them for writing; the values live in
:mod:`statectl.front.tables.rows`, the data literals in :mod:`statectl.front.tables.literals`
and the cell checks in :mod:`statectl.front.tables.cells`: import each from where it lives.
"""

from __future__ import annotations

from collections.abc import Sequence

from statectl.front.tables.cells import (
    event_row,
    recovery_row,
    state_row,
)
from statectl.front.tables.eventdata import event_cells, event_columns
from statectl.front.tables.literals import (
    format_literal,
    make_data,
    normalize_payload,
    normalize_value,
)
from statectl.front.tables.rows import (
    DATA_COLUMNS,
    FLAT_EVENT_COLUMNS,
    FLAT_RECOVERY_COLUMNS,
    FLAT_STATE_COLUMNS,
    RECOVERY_COLUMNS,
    Bad,
    DeviceTables,
    EventRow,
    RawTable,
    RecoveryRow,
    StateRow,
    diag,
)
from statectl.front.tables.timeouts import optional_state_columns
from statectl.kernel.errors import Diagnostic, Location

#: The names this module defines (the values are in rows, literals and cells).
__all__ = [
    "FlatTable",
    "flat_tables",
    "make_tables",
    "recovery_cells",
    "recovery_columns",
    "state_cells",
    "state_columns",
    "validate_for_writing",
]

# --- whole tables -----------------------------------------------------------------------


def make_tables(
    device: str,
    states: RawTable | None,
    events: RawTable | None,
    data: Sequence[tuple[str, object, Location]],
    source: Location,
    diags: list[Diagnostic],
    recovery: RawTable | None = None,
    profile: str = "",
) -> DeviceTables | None:
    """Check raw tables and build :class:`DeviceTables`.

    Rows with bad cells are kept as far as they could be read (an unknown control
    is left out, an unknown kind reads as ``command``) so that the build can still
    report its own problems in the same run: diagnostics, not first errors. The
    result is ``None`` only when a table is missing altogether; a caller must
    check the diagnostics for errors before trusting the tables.
    """
    state_rows: list[StateRow] = []
    event_rows: list[EventRow] = []
    for raw in (states, events):
        if raw is not None and not raw.rows:
            diags.append(
                diag("T105", raw.where, f"the {raw.table} table is empty", "add at least one row")
            )
    if states is not None:
        state_rows.extend(state_row(r, diags) for r in states.rows)
    if events is not None:
        event_rows.extend(event_row(r, diags) for r in events.rows)
    data_items = make_data(data, diags)
    recovery_rows = tuple(recovery_row(r, diags) for r in recovery.rows) if recovery else ()
    if not device.strip():
        diags.append(diag("T104", source, "the device has no name", "add 'device: NAME'"))
    if states is None or events is None:
        return None
    return DeviceTables(
        device.strip(),
        tuple(state_rows),
        tuple(event_rows),
        data_items,
        source,
        recovery_rows,
        profile.strip(),
    )


def state_columns(tables: DeviceTables) -> tuple[str, ...]:
    """The state columns a writer emits: the flat ones, and ``type``/``default``/``number``/
    ``timeout``/``defer`` when a row uses them."""
    columns: tuple[str, ...] = FLAT_STATE_COLUMNS
    if any(s.type is not None or s.default for s in tables.states):
        columns += ("type", "default")
    if any(s.number for s in tables.states):
        columns += ("number",)
    return columns + optional_state_columns(tables)


def state_cells(s: StateRow, columns: Sequence[str]) -> list[str]:
    """One state row as text cells (lists comma-separated) for CSV, XLSX and Markdown."""
    cells = {
        "component": s.component,
        "api": s.api,
        "state": s.state,
        "control": ", ".join(c.value for c in s.controls),
        "description": s.description,
        "ignore": ", ".join(s.ignore),
        "parent": s.parent,
        "type": s.type_text,
        "default": ", ".join(s.default),
        "number": s.number,
        "timeout": s.timeout,
        "defer": ", ".join(s.defer),
    }
    return [cells[c] for c in columns]


def recovery_columns(tables: DeviceTables) -> tuple[str, ...]:
    """The recovery columns a writer emits: the flat ones, plus ``redo`` if a row uses it."""
    return RECOVERY_COLUMNS if any(r.redo for r in tables.recovery) else FLAT_RECOVERY_COLUMNS


def recovery_cells(r: RecoveryRow, columns: Sequence[str] = FLAT_RECOVERY_COLUMNS) -> list[str]:
    """One recovery row as text cells (data as a YAML flow value, empty for none; redo yes/"")."""
    cells = {
        "state": r.state,
        "event": r.event,
        "data": "" if r.data is None else format_literal(r.data),
        "redo": "yes" if r.redo else "",
    }
    return [cells[c] for c in columns]


#: A table as the flat formats write it: its name, its header, its rows of text cells.
FlatTable = tuple[str, tuple[str, ...], list[list[str]]]


def flat_tables(tables: DeviceTables) -> tuple[FlatTable, ...]:
    """What CSV, Markdown and XLSX each write, in file order: the states and events, then
    the data and recovery tables when they have rows."""
    scols = state_columns(tables)
    ecols = event_columns(tables.events, FLAT_EVENT_COLUMNS)
    flat: list[FlatTable] = [
        ("states", scols, [state_cells(s, scols) for s in tables.states]),
        ("events", ecols, [event_cells(e, ecols) for e in tables.events]),
    ]
    if tables.data:
        flat.append(("data", DATA_COLUMNS, [[n, format_literal(v)] for n, v in tables.data]))
    if tables.recovery:
        rcols = recovery_columns(tables)
        flat.append(("recovery", rcols, [recovery_cells(r, rcols) for r in tables.recovery]))
    return tuple(flat)


def validate_for_writing(tables: DeviceTables, where: Location) -> list[Diagnostic]:
    """What would not survive a round trip through a file: report it instead of writing."""
    diags: list[Diagnostic] = []
    if not tables.device or "\n" in tables.device or "\r" in tables.device:
        diags.append(diag("T104", where, f"device name {tables.device!r} cannot be written"))
    for e in tables.events:
        if "," in e.event:
            diags.append(diag("T111", e.where, f"event name {e.event!r} contains a comma"))
    for s in tables.states:
        for item in s.ignore:
            if "," in item or item != item.strip() or not item:
                diags.append(diag("T111", s.where, f"ignore item {item!r} cannot be written"))
        for item in s.defer:
            if "," in item or item != item.strip() or not item:
                diags.append(diag("T111", s.where, f"defer item {item!r} cannot be written"))
        for item in s.default:
            if "," in item or item != item.strip() or not item:
                diags.append(diag("T111", s.where, f"default item {item!r} cannot be written"))
    seen: set[str] = set()
    for name, value in tables.data:
        if not name.isidentifier() or name in seen:
            diags.append(diag("T112", where, f"data name {name!r} cannot be written"))
        seen.add(name)
        if isinstance(normalize_value(value), Bad):
            diags.append(diag("T108", where, f"data {name!r} is not a literal: {value!r}"))
    for r in tables.recovery:
        texts = (("state", r.state),) if r.redo else (("state", r.state), ("event", r.event))
        for column, text in texts:
            if not text or text != text.strip():
                diags.append(
                    diag("T104", r.origin, f"recovery {column} {text!r} cannot be written")
                )
        if r.redo and (r.event or r.data is not None):
            diags.append(
                diag("T114", r.origin, f"recovery row for {r.state!r}: redo with an event or data")
            )
        if isinstance(normalize_payload(r.data), Bad):
            diags.append(diag("T108", r.origin, f"recovery data is not a plain value: {r.data!r}"))
    return diags
