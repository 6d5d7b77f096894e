"""The tables' values: column names and their accepted spellings, the row types,
:class:`DeviceTables`, raw tables as format readers deliver them, and the T1xx
diagnostic helpers every reader shares. Split from :mod:`statectl.front.tables.schema` so the
readers, the cell checks and the data literals import the values without the checks.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

from statectl.kernel.codes import family
from statectl.kernel.errors import Diagnostic, Location, Severity, did_you_mean
from statectl.kernel.model import ControlKind, EventKind, StateKind

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
    "number",
    "timeout",
    "defer",
)
#: The columns every writer emits; ``type`` and ``default`` only when a row uses them.
FLAT_STATE_COLUMNS = STATE_COLUMNS[:7]
EVENT_COLUMNS = (
    "event",
    "condition",
    "guard",
    "old",
    "new",
    "kind",
    "api",
    "invoke",
    "data",
    "assign",
    "unasked",
    "severity",
)
#: The event columns every writer emits; ``data``, ``assign``, ``unasked`` and
#: ``severity`` only when a row uses them.
FLAT_EVENT_COLUMNS = EVENT_COLUMNS[:8]
#: The highest alarm severity an event row may give (OPC UA's scale: 1 to 1000).
MAX_SEVERITY = 1000
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
    "state number": "number",
    "deferred": "defer",
    "defers": "defer",
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

#: Code -> one-line summary of every T1xx code (a view of statectl.kernel.codes.REGISTRY).
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
    number: str = ""  # the standard's state number (a profile's), checked by build (B236)
    timeout: str = ""  # ``DURATION -> EVENT`` (statectl.front.tables.timeouts), empty: none
    defer: tuple[str, ...] = ()  # events kept while the state is active

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
    #: declared event data ``((field, type), ...)`` (tables.eventdata rule 1)
    fields: tuple[tuple[str, str], ...] = ()
    #: data assignments ``((name, expression), ...)`` when taken (tables.eventdata rule 2)
    assign: tuple[tuple[str, str], ...] = ()
    #: a completion the device may report with no call pending (kernel.semantics.calls)
    unasked: bool = False
    #: the OPC UA alarm severity of a fault (1-1000); None: the default (channels/opcua)
    severity: int | None = None


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
    profile: str = ""  # the standard profile the device declares (docs/profiles.md)


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
    """A row's cells by normalized column name, each with where it was found.

    ``read`` is the row as a reader already read it, when it had nothing to report (a
    plain state or event row, :func:`statectl.front.tables.cells.plain_event_row`); its
    cells are then left empty: a YAML row made one location per cell only to drop them.
    """

    where: Location
    cells: Mapping[str, tuple[Cell, Location]] = field(default_factory=dict)
    read: StateRow | EventRow | None = None


@dataclass(frozen=True, slots=True)
class RawTable:
    """A table before checking; ``rows`` of the data table carry ``name`` and ``value``."""

    table: str  # "states" | "events" | "data" | "recovery"
    where: Location
    rows: tuple[RawRow, ...]


def diag(code: str, where: Location, message: str, hint: str = "") -> Diagnostic:
    """An error diagnostic; the tables layer only reports errors."""
    return Diagnostic(code, Severity.ERROR, where, message, hint)


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
