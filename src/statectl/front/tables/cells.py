"""Checking raw cells into rows: headers (T101, T103, T104), text, list, control, kind
and type cells (T106-T108, T111, T113), state and event rows, and recovery rows (T104,
T114; schema rule 5a). Split from :mod:`statectl.front.tables.schema`, which assembles whole
tables from these rows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from statectl.front.tables.eventdata import event_data_cells
from statectl.front.tables.literals import parse_payload
from statectl.front.tables.rows import (
    COLUMNS,
    CONTROL_WORDS,
    MAX_SEVERITY,
    REDO_WORDS,
    REQUIRED,
    TYPE_NAMES,
    TYPE_WORDS,
    Bad,
    EventRow,
    RawRow,
    RecoveryRow,
    StateRow,
    diag,
    normalize_column,
    unknown_column,
)
from statectl.front.tables.timeouts import timeout_cell
from statectl.kernel.errors import Diagnostic, Location, did_you_mean
from statectl.kernel.model import ControlKind, EventKind, StateKind


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
            diags.append(
                diag(
                    "T101",
                    at,
                    f"column {name!r} appears twice in the {table} header",
                    "name each column once: rename or delete the second",
                )
            )
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


#: Each table's columns as a set: every cell of every row is looked up here.
_KNOWN = {table: frozenset(columns) for table, columns in COLUMNS.items()}


def _check_keys(table: str, row: RawRow, diags: list[Diagnostic]) -> None:
    known = _KNOWN[table]
    for name in row.cells:
        if name not in known:
            diags.append(unknown_column(table, name, row.cells[name][1]))


#: The text columns of a state row that need no more than stripping when well formed.
PLAIN_STATE = frozenset(("component", "api", "state", "control", "description", "parent"))


def _plain_state_row(row: RawRow) -> StateRow | None:
    """The usual state row, when it has nothing to report: text cells of
    :data:`PLAIN_STATE` only, ``state`` filled, at most one control and a known one.
    ``None`` otherwise, and :func:`state_row` checks it cell by cell (as for event rows)."""
    texts = _plain_texts(row, PLAIN_STATE)
    return None if texts is None else plain_state_row(texts, row.where)


def _plain_texts(row: RawRow, columns: frozenset[str]) -> dict[str, str] | None:
    """The row's stripped cell texts when every cell is a text of ``columns``, else None."""
    texts: dict[str, str] = {}
    for name, (value, _) in row.cells.items():
        if type(value) is not str or name not in columns:
            return None
        texts[name] = value.strip()
    return texts


def plain_state_row(texts: Mapping[str, str], where: Location) -> StateRow | None:
    """:func:`_plain_state_row` from the cells' stripped texts (columns of
    :data:`PLAIN_STATE` only), for a reader that has them before any cell."""
    get = texts.get
    state, control = get("state", ""), get("control", "")
    if not state or "," in control:
        return None
    controls: tuple[ControlKind, ...] = ()
    if control:
        kind = CONTROL_WORDS.get(
            " ".join(control.lower().replace("_", " ").replace("-", " ").split())
        )
        if kind is None:
            return None
        controls = (kind,)
    return StateRow(
        component=get("component", ""),
        api=get("api", ""),
        state=state,
        controls=controls,
        description=get("description", ""),
        ignore=(),
        parent=get("parent", ""),
        where=where,
    )


def state_row(row: RawRow, diags: list[Diagnostic]) -> StateRow:
    if type(row.read) is StateRow:
        return row.read
    plain = _plain_state_row(row)
    if plain is not None:
        return plain
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
        number=_text(row, "number", diags),
        timeout=timeout_cell(row, diags),
        defer=_items(row, "defer", diags)[0],
    )


#: The text columns of an event row that need no more than stripping when well formed.
PLAIN_EVENT = frozenset(("event", "condition", "guard", "old", "new", "kind", "api", "invoke"))
#: An event kind's text -> the kind.
_KINDS = {k.value: k for k in EventKind}


def _plain_event_row(row: RawRow) -> EventRow | None:
    """The usual event row, when it has nothing to report: text cells of
    :data:`PLAIN_EVENT` only, ``event``, ``old`` and ``new`` filled, a known kind.
    ``None`` otherwise, and :func:`event_row` checks it cell by cell; a 100,000-row table
    asked each row's eleven cells one at a time."""
    texts = _plain_texts(row, PLAIN_EVENT)
    return None if texts is None else plain_event_row(texts, row.where)


def plain_event_row(texts: Mapping[str, str], where: Location) -> EventRow | None:
    """:func:`_plain_event_row` from the cells' stripped texts (columns of
    :data:`PLAIN_EVENT` only), for a reader that has them before any cell."""
    get = texts.get
    event, old, new = get("event", ""), get("old", ""), get("new", "")
    written = get("kind", "").lower()
    kind = _KINDS.get(written) if written else EventKind.COMMAND  # empty: a command (_kind)
    if not (event and old and new) or "," in event or kind is None:
        return None
    return EventRow(
        event=event,
        condition=get("condition", ""),
        guard=get("guard", ""),
        old=old,
        new=new,
        kind=kind,
        api=get("api", ""),
        invoke=get("invoke", ""),
        where=where,
    )


def event_row(row: RawRow, diags: list[Diagnostic]) -> EventRow:
    if type(row.read) is EventRow:
        return row.read
    plain = _plain_event_row(row)
    if plain is not None:
        return plain
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
        unasked=_unasked(row, diags),
        severity=_severity(row, diags),
        **event_data_cells(row, diags),
    )


def _unasked(row: RawRow, diags: list[Diagnostic]) -> bool:
    """The ``unasked`` cell: yes when the device may report this completion by itself."""
    value = _yes_no(
        row,
        ("event", "unasked", "T125"),
        "write unasked: yes on a completion the device may report with no call "
        "pending; leave it empty for no",
        diags,
    )
    kind = _text(row, "kind", diags).strip().lower() if "kind" in row.cells else ""
    if value and kind != EventKind.COMPLETION.value:
        diags.append(
            diag(
                "T125",
                row.cells["unasked"][1],
                f"unasked: yes on {kind or 'command'} event {_text(row, 'event', diags)!r}",
                "only a completion can come unasked: set kind: completion or remove it",
            )
        )
        return False
    return value


def _severity(row: RawRow, diags: list[Diagnostic]) -> int | None:
    """The ``severity`` cell: the OPC UA alarm severity (1-1000) of a fault; empty: none."""
    text = _text(row, "severity", diags)
    if not text:
        return None
    where = row.cells["severity"][1]
    if not (text.isascii() and text.isdigit() and 1 <= int(text) <= MAX_SEVERITY):
        diags.append(
            diag(
                "T126",
                where,
                f"event 'severity' must be a whole number from 1 to {MAX_SEVERITY} (got {text!r})",
                "write the alarm's severity as OPC UA counts it: 1 (lowest) to 1000 "
                "(highest), e.g. severity: 700; leave it empty for the default",
            )
        )
        return None
    kind = _text(row, "kind", diags).strip().lower() if "kind" in row.cells else ""
    if kind != EventKind.FAULT.value:
        diags.append(
            diag(
                "T126",
                where,
                f"severity on {kind or 'command'} event {_text(row, 'event', diags)!r}",
                "only a fault raises an alarm: set kind: fault or remove the severity",
            )
        )
        return None
    return int(text)


def _unreadable(row: RawRow, column: str) -> bool:
    """The cell is there but not text (already reported as T108)."""
    got = row.cells.get(column)
    return got is not None and isinstance(got[0], Bad | tuple)


def _redo(row: RawRow, diags: list[Diagnostic]) -> bool:
    return _yes_no(
        row,
        ("recovery", "redo", "T114"),
        "write redo: yes to redo the entering step's device calls; leave it empty for no",
        diags,
    )


def _yes_no(row: RawRow, where: tuple[str, str, str], fix: str, diags: list[Diagnostic]) -> bool:
    """A yes/no cell (``where``: its row's noun, column, code); empty or bad: no."""
    noun, column, code = where
    text = _text(row, column, diags).lower()
    if not text:
        return False
    value = REDO_WORDS.get(text)
    if value is None:
        message = f"{noun} {column!r} must be yes or no (got {text!r})"
        diags.append(diag(code, row.cells[column][1], message, fix))
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
