"""The paper's two tables in memory, and the rules every file format shares.

Rules:
1. A device file holds a device name, a State Definition table, an Event
   Definition table, optional data (name -> literal initial value) and an
   optional Recovery table (state -> what a restarted device does first when it
   resumes in that state; checked against the chart by ``statectl.recovery``).
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
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import yaml

from statectl.codes import family
from statectl.errors import Diagnostic, Location, Severity
from statectl.model import ControlKind, EventKind, StateKind
from statectl.tables.safeyaml import YamlRefused, load_value

__all__ = [
    "CODES",
    "DATA_COLUMNS",
    "EVENT_COLUMNS",
    "NOWHERE",
    "RECOVERY_COLUMNS",
    "STATE_COLUMNS",
    "TYPE_NAMES",
    "TYPE_WORDS",
    "Bad",
    "DeviceTables",
    "EventRow",
    "RawRow",
    "RawTable",
    "RecoveryRow",
    "StateRow",
    "check_header",
    "diag",
    "format_literal",
    "make_tables",
    "parse_literal",
    "parse_payload",
    "recovery_cells",
    "recovery_columns",
    "state_cells",
    "state_columns",
    "strip_locations",
    "validate_for_writing",
]

NOWHERE = Location()

STATE_COLUMNS = (
    "component",
    "api",
    "state",
    "control",
    "description",
    "ignore",
    "parent",
    "type",
    "default",
)
#: The columns every writer emits; ``type`` and ``default`` only when a row uses them.
FLAT_STATE_COLUMNS = STATE_COLUMNS[:7]
EVENT_COLUMNS = ("event", "condition", "guard", "old", "new", "kind", "api", "invoke")
DATA_COLUMNS = ("name", "value")
RECOVERY_COLUMNS = ("state", "event", "data", "redo")
#: The recovery columns every writer emits; ``redo`` only when a row uses it.
FLAT_RECOVERY_COLUMNS = RECOVERY_COLUMNS[:3]
#: Spellings accepted in the ``redo`` column, after lowering (empty: no).
REDO_WORDS: Mapping[str, bool] = {"yes": True, "true": True, "no": False, "false": False}
COLUMNS: Mapping[str, tuple[str, ...]] = {
    "states": STATE_COLUMNS,
    "events": EVENT_COLUMNS,
    "data": DATA_COLUMNS,
    "recovery": RECOVERY_COLUMNS,
}
REQUIRED: Mapping[str, tuple[str, ...]] = {
    "states": ("state",),
    "events": ("event", "old", "new"),
    "data": ("name",),
    "recovery": ("state",),  # and per row an event or redo: yes (rule 5a)
}
#: The paper's and spreadsheet-friendly names for the columns.
ALIASES: Mapping[str, str] = {
    "controls": "control",
    "required state control": "control",
    "state control": "control",
    "component name": "component",
    "component name/api": "component",
    "condition for the trigger": "condition",
    "old state": "old",
    "new state": "new",
    "ignored": "ignore",
    "ignores": "ignore",
    "state type": "type",
    "history default": "default",
}
#: Spellings accepted in the ``type`` column, after lowering and collapsing spaces.
TYPE_WORDS: Mapping[str, StateKind] = {
    "atomic": StateKind.ATOMIC,
    "compound": StateKind.COMPOUND,
    "parallel": StateKind.PARALLEL,
    "final": StateKind.FINAL,
    "history": StateKind.HISTORY_SHALLOW,
    "shallow history": StateKind.HISTORY_SHALLOW,
    "deep history": StateKind.HISTORY_DEEP,
}
#: How writers spell each type (the first spelling above).
TYPE_NAMES: Mapping[StateKind, str] = {
    StateKind.ATOMIC: "atomic",
    StateKind.COMPOUND: "compound",
    StateKind.PARALLEL: "parallel",
    StateKind.FINAL: "final",
    StateKind.HISTORY_SHALLOW: "history",
    StateKind.HISTORY_DEEP: "deep history",
}
#: Spellings accepted in the ``control`` column, after lowering and collapsing spaces.
CONTROL_WORDS: Mapping[str, ControlKind] = {
    "default": ControlKind.DEFAULT,
    "monitoring required": ControlKind.MONITORING,
    "monitoring": ControlKind.MONITORING,
    "monitor": ControlKind.MONITORING,
    "event trigger required": ControlKind.TRIGGER,
    "event trigger": ControlKind.TRIGGER,
    "trigger required": ControlKind.TRIGGER,
    "trigger": ControlKind.TRIGGER,
}

#: Code -> one-line summary of every T1xx code (a view of statectl.codes.REGISTRY).
CODES: Mapping[str, str] = family("T1")


@dataclass(frozen=True, slots=True)
class StateRow:
    """One row of the State Definition table (the paper's Table 1)."""

    component: str
    api: str
    state: str
    controls: tuple[ControlKind, ...]
    description: str
    ignore: tuple[str, ...]
    parent: str = ""  # the compound or parallel state this one is in (empty: top level)
    where: Location = NOWHERE
    type: StateKind | None = None  # None: atomic, or compound when it has children
    default: tuple[str, ...] = ()  # a history state's targets before it recorded anything

    @property
    def type_text(self) -> str:
        """The ``type`` cell as writers spell it (empty for an implied type)."""
        return TYPE_NAMES[self.type] if self.type is not None else ""


@dataclass(frozen=True, slots=True)
class EventRow:
    """One row of the Event Definition table (the paper's Table 2)."""

    event: str
    condition: str
    guard: str
    old: str
    new: str
    kind: EventKind
    api: str
    invoke: str = ""  # explicit invoke name; empty: derived (observers rule 5)
    where: Location = NOWHERE


@dataclass(frozen=True, slots=True)
class RecoveryRow:
    """One row of the Recovery table: what a device resuming in ``state`` does first.

    Either it posts ``event`` with ``data`` (a Motor that was Moving is not moving
    any more: Error brings its chart back in line), or, with ``redo``, it issues
    again the device API calls of the step that entered ``state`` (a Motor that
    was Returning must be told to return again, or its completion never comes).
    """

    state: str
    event: str = ""  # empty on a redo row
    data: object = None  # the event's payload: a plain value, lists and dicts (rule 5a)
    origin: Location = NOWHERE
    redo: bool = False  # re-issue the entering step's notifications instead of an event


@dataclass(frozen=True, slots=True)
class DeviceTables:
    """A device's tables as read from one file (or one CSV pair)."""

    device: str
    states: tuple[StateRow, ...]
    events: tuple[EventRow, ...]
    data: tuple[tuple[str, object], ...] = ()
    source: Location = NOWHERE
    recovery: tuple[RecoveryRow, ...] = ()  # the third table; empty: none (rule 5a)


def strip_locations(tables: DeviceTables) -> DeviceTables:
    """The same tables with every location dropped: what a lossless conversion keeps."""
    return replace(
        tables,
        states=tuple(replace(s, where=NOWHERE) for s in tables.states),
        events=tuple(replace(e, where=NOWHERE) for e in tables.events),
        source=NOWHERE,
        recovery=tuple(replace(r, origin=NOWHERE) for r in tables.recovery),
    )


# --- raw tables, as format readers deliver them ---------------------------------------


@dataclass(frozen=True, slots=True)
class Bad:
    """A cell of the wrong type (T108): names what was found instead of text.

    ``code`` is T115 or T116 for YAML the safe reader refused (an alias, too deep).
    """

    found: str
    code: str = "T108"


Cell = str | tuple[str, ...] | Bad
DataValue = object


@dataclass(frozen=True, slots=True)
class RawRow:
    """A row's cells by normalized column name, each with where it was found."""

    where: Location
    cells: Mapping[str, tuple[Cell, Location]] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class RawTable:
    """A table before checking; ``rows`` of the data table carry ``name`` and ``value``."""

    table: str  # "states" | "events" | "data" | "recovery"
    where: Location
    rows: tuple[RawRow, ...]


def diag(code: str, where: Location, message: str, hint: str = "") -> Diagnostic:
    """An error diagnostic; the tables layer only reports errors."""
    return Diagnostic(code, Severity.ERROR, where, message, hint)


def did_you_mean(word: str, choices: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f"did you mean {close[0]!r}? " if close else ""


def normalize_column(name: str) -> str:
    key = " ".join(name.strip().lower().replace("_", " ").split())
    return ALIASES.get(key, key)


def unknown_column(table: str, name: str, where: Location) -> Diagnostic:
    known = COLUMNS[table]
    return diag(
        "T103",
        where,
        f"unknown column {name!r} in the {table} table",
        did_you_mean(normalize_column(name), known) + "known columns: " + ", ".join(known),
    )


def check_header(
    table: str, header: Sequence[tuple[str, Location]], where: Location, diags: list[Diagnostic]
) -> list[str | None] | None:
    """Map header cells to column names; ``None`` for the whole table if it is unusable.

    Unknown columns are reported (T103) and their cells dropped; a missing
    required column (T104) makes every row unreadable, so it is reported once here.
    """
    columns: list[str | None] = []
    seen: set[str] = set()
    for text, at in header:
        name = normalize_column(text)
        if not name:
            columns.append(None)
        elif name not in COLUMNS[table]:
            diags.append(unknown_column(table, text, at))
            columns.append(None)
        elif name in seen:
            diags.append(diag("T101", at, f"column {name!r} appears twice in the {table} header"))
            columns.append(None)
        else:
            seen.add(name)
            columns.append(name)
    missing = [c for c in REQUIRED[table] if c not in seen]
    for c in missing:
        diags.append(
            diag(
                "T104",
                where,
                f"the {table} table has no {c!r} column",
                "columns: " + ", ".join(COLUMNS[table]),
            )
        )
    return None if missing else columns


# --- cells ------------------------------------------------------------------------------


def _text(row: RawRow, column: str, diags: list[Diagnostic]) -> str:
    got = row.cells.get(column)
    if got is None:
        return ""
    value, where = got
    if isinstance(value, Bad):
        diags.append(diag("T108", where, f"{column!r} must be text (got {value.found})"))
        return ""
    if isinstance(value, tuple):
        diags.append(
            diag("T108", where, f"{column!r} must be text (got a list)", "write one value")
        )
        return ""
    return value.strip()


def _required(row: RawRow, column: str, table: str, diags: list[Diagnostic]) -> str:
    text = _text(row, column, diags)
    if not text and not (column in row.cells and isinstance(row.cells[column][0], Bad | tuple)):
        diags.append(
            diag(
                "T104", row.where, f"{table} row has no {column!r}", f"fill in the {column!r} cell"
            )
        )
    return text


def _items(row: RawRow, column: str, diags: list[Diagnostic]) -> tuple[tuple[str, ...], Location]:
    got = row.cells.get(column)
    if got is None:
        return (), row.where
    value, where = got
    if isinstance(value, Bad):
        diags.append(diag("T108", where, f"{column!r} must be text or a list (got {value.found})"))
        return (), where
    if isinstance(value, str):
        parts: Sequence[str] = value.split(",")
    else:
        parts = value
        for item in value:
            if "," in item:
                diags.append(
                    diag(
                        "T111",
                        where,
                        f"{column!r} item {item!r} contains a comma",
                        "event names must not contain commas",
                    )
                )
    return tuple(p.strip() for p in parts if p.strip()), where


def _controls(row: RawRow, diags: list[Diagnostic]) -> tuple[ControlKind, ...]:
    items, where = _items(row, "control", diags)
    kinds: list[ControlKind] = []
    for item in items:
        kind = CONTROL_WORDS.get(" ".join(item.lower().replace("_", " ").replace("-", " ").split()))
        if kind is None:
            accepted = [k.value for k in ControlKind]
            diags.append(
                diag(
                    "T106",
                    where,
                    f"unknown control {item!r}",
                    did_you_mean(item.lower(), accepted) + "accepted: " + ", ".join(accepted),
                )
            )
        elif kind not in kinds:
            kinds.append(kind)
    return tuple(kinds)


def _kind(row: RawRow, diags: list[Diagnostic]) -> EventKind:
    text = _text(row, "kind", diags).lower()
    if not text:
        return EventKind.COMMAND
    for kind in EventKind:
        if kind.value == text:
            return kind
    accepted = [k.value for k in EventKind]
    where = row.cells["kind"][1]
    diags.append(
        diag(
            "T107",
            where,
            f"unknown event kind {text!r}",
            did_you_mean(text, accepted) + "accepted: " + ", ".join(accepted),
        )
    )
    return EventKind.COMMAND


def _type(row: RawRow, diags: list[Diagnostic]) -> StateKind | None:
    text = " ".join(_text(row, "type", diags).lower().replace("_", " ").replace("-", " ").split())
    if not text:
        return None
    kind = TYPE_WORDS.get(text)
    if kind is None:
        accepted = list(TYPE_NAMES.values())
        diags.append(
            diag(
                "T113",
                row.cells["type"][1],
                f"unknown state type {text!r}",
                did_you_mean(text, accepted)
                + "accepted: "
                + ", ".join(accepted)
                + " (or leave it empty)",
            )
        )
    return kind


def _check_keys(table: str, row: RawRow, diags: list[Diagnostic]) -> None:
    for name, (_, where) in row.cells.items():
        if name not in COLUMNS[table]:
            diags.append(unknown_column(table, name, where))


def state_row(row: RawRow, diags: list[Diagnostic]) -> StateRow:
    _check_keys("states", row, diags)
    return StateRow(
        component=_text(row, "component", diags),
        api=_text(row, "api", diags),
        state=_required(row, "state", "states", diags),
        controls=_controls(row, diags),
        description=_text(row, "description", diags),
        ignore=_items(row, "ignore", diags)[0],
        parent=_text(row, "parent", diags),
        where=row.where,
        type=_type(row, diags),
        default=_items(row, "default", diags)[0],
    )


def event_row(row: RawRow, diags: list[Diagnostic]) -> EventRow:
    _check_keys("events", row, diags)
    event = _required(row, "event", "events", diags)
    if "," in event:
        diags.append(
            diag(
                "T111",
                row.cells["event"][1],
                f"event name {event!r} contains a comma",
                "commas separate the names in 'ignore' cells: rename the event",
            )
        )
    return EventRow(
        event=event,
        condition=_text(row, "condition", diags),
        guard=_text(row, "guard", diags),
        old=_required(row, "old", "events", diags),
        new=_required(row, "new", "events", diags),
        kind=_kind(row, diags),
        api=_text(row, "api", diags),
        invoke=_text(row, "invoke", diags),
        where=row.where,
    )


# --- data literals ----------------------------------------------------------------------


def normalize_value(value: object) -> object | Bad:
    """A YAML literal as the tables keep it (lists become tuples), or what is wrong."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, list | tuple):
        items = [normalize_value(v) for v in value]
        for item in items:
            if isinstance(item, Bad):
                return item
        return tuple(items)
    if isinstance(value, dict):
        return Bad("a mapping")
    return Bad(f"a {type(value).__name__}")


def normalize_payload(value: object) -> object | Bad:
    """A recovery row's data as the tables keep it (plain lists and dicts), or what is wrong."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, list | tuple):
        items = [normalize_payload(v) for v in value]
        bad = next((i for i in items if isinstance(i, Bad)), None)
        return bad if bad is not None else items
    if isinstance(value, dict):
        out: dict[str, object] = {}
        for key, item in value.items():
            if not isinstance(key, str):
                return Bad(f"a mapping key {key!r} that is not text")
            got = normalize_payload(item)
            if isinstance(got, Bad):
                return got
            out[key] = got
        return out
    return Bad(f"a {type(value).__name__}")


def _plain(value: object) -> object:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def to_plain(value: object) -> object:
    """The value as YAML writes it (tuples become lists)."""
    return _plain(value)


def format_literal(value: object) -> str:
    """One value as a YAML flow literal, for a CSV, XLSX or Markdown cell."""
    text = yaml.safe_dump(
        [_plain(value)],
        default_flow_style=True,
        allow_unicode=True,
        width=math.inf,
        sort_keys=False,
    ).strip()
    return text[1:-1].strip()


_REPORTED = Bad("malformed literal")  # a cell parse_literal reported already


def parse_literal(text: str, where: Location, diags: list[Diagnostic]) -> object | Bad:
    """Read a YAML literal from a cell; an empty cell is null."""
    try:
        value = load_value(text)
    except YamlRefused as exc:
        code = exc.code if exc.code in ("T115", "T116") else "T108"
        shown = text if len(text) <= 60 else text[:57] + "..."
        message = f"data value {shown!r} is not a YAML literal: {exc.message}"
        diags.append(diag(code, where, message, exc.hint))
        return Bad(_REPORTED.found, code)
    return normalize_value(value)


def parse_payload(text: str) -> object | Bad:
    """Read a recovery row's data cell (a YAML flow value); an empty cell is null."""
    try:
        value = load_value(text)
    except YamlRefused as exc:
        return Bad(exc.message, exc.code if exc.code in ("T115", "T116") else "T108")
    return normalize_payload(value)


def make_data(
    entries: Sequence[tuple[str, object, Location]], diags: list[Diagnostic]
) -> tuple[tuple[str, object], ...]:
    """Check data entries: identifier names, each once, literal values."""
    data: dict[str, object] = {}
    for name, value, where in entries:
        if not name.isidentifier() or name.startswith("_"):
            diags.append(
                diag(
                    "T112",
                    where,
                    f"data name {name!r} is not a usable name",
                    "use a name like speed or target_position (letters, digits, _; "
                    "not starting with _ or a digit)",
                )
            )
            continue
        if name in data:
            diags.append(diag("T112", where, f"data name {name!r} is given twice"))
            continue
        if isinstance(value, Bad) and value.found == _REPORTED.found:
            continue  # parse_literal has said why
        if isinstance(value, Bad):
            diags.append(
                diag(
                    value.code,
                    where,
                    f"data {name!r} must be a literal (got {value.found})",
                    "use null, true/false, a number, a string or a list of them",
                )
            )
            continue
        data[name] = value
    return tuple(data.items())


def _unreadable(row: RawRow, column: str) -> bool:
    """The cell is there but not text (already reported as T108)."""
    got = row.cells.get(column)
    return got is not None and isinstance(got[0], Bad | tuple)


def _redo(row: RawRow, diags: list[Diagnostic]) -> bool:
    text = _text(row, "redo", diags).lower()
    if not text:
        return False
    value = REDO_WORDS.get(text)
    if value is None:
        diags.append(
            diag(
                "T114",
                row.cells["redo"][1],
                f"recovery 'redo' must be yes or no (got {text!r})",
                "write redo: yes to redo the entering step's device calls; leave it empty for no",
            )
        )
        return False
    return value


def recovery_row(row: RawRow, diags: list[Diagnostic]) -> RecoveryRow:
    """A Recovery row: an event (data a YAML flow value) or ``redo: yes`` (rule 5a)."""
    _check_keys("recovery", row, diags)
    state = _required(row, "state", "recovery", diags)
    event = _text(row, "event", diags)
    redo = _redo(row, diags)
    if redo and event:
        diags.append(
            diag(
                "T114",
                row.where,
                f"recovery row for {state!r} has both an event ({event!r}) and redo: yes",
                "a row either posts an event or redoes the entering step: keep one",
            )
        )
    elif not redo and not event and not _unreadable(row, "event"):
        diags.append(
            diag(
                "T104",
                row.where,
                f"recovery row for {state!r} has neither an 'event' nor redo: yes",
                "name the event to post on resume, or write redo: yes",
            )
        )
    data: object = None
    got = row.cells.get("data")
    if got is not None:
        cell, where = got
        if isinstance(cell, str):
            value = parse_payload(cell)
        else:  # a list of names cannot come from any reader; a Bad cell stays Bad
            value = list(cell) if isinstance(cell, tuple) else cell
        if isinstance(value, Bad):
            diags.append(
                diag(
                    value.code,
                    where,
                    f"recovery data must be a plain value (got {value.found})",
                    "use null, true/false, numbers, text, lists and mappings with text keys",
                )
            )
        else:
            data = value
        if redo and data is not None:
            diags.append(
                diag(
                    "T114",
                    where,
                    f"recovery row for {state!r} redoes its entering step and takes no data",
                    "the redone calls get the data of the step that entered the state: "
                    "delete the data cell",
                )
            )
    return RecoveryRow(state, event, data, row.where, redo)


# --- whole tables -----------------------------------------------------------------------


def make_tables(
    device: str,
    states: RawTable | None,
    events: RawTable | None,
    data: Sequence[tuple[str, object, Location]],
    source: Location,
    diags: list[Diagnostic],
    recovery: RawTable | None = None,
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
    )


def state_columns(tables: DeviceTables) -> tuple[str, ...]:
    """The state columns a writer emits: the flat ones, plus ``type``/``default`` if used."""
    if any(s.type is not None or s.default for s in tables.states):
        return STATE_COLUMNS
    return FLAT_STATE_COLUMNS


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
