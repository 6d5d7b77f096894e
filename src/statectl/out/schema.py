"""JSON Schemas for the YAML files statectl reads: device tables, cells and run configs.

Rules:
1. Generated from the code that reads the files, never written by hand: the
   columns and their accepted spellings (:mod:`statectl.front.tables.rows`), the
   device file's top keys (:mod:`statectl.front.tables.yaml_io`), the cell's keys
   (:mod:`statectl.cell.values`, :mod:`statectl.cell.reader`,
   :mod:`statectl.cell.nodes`, :mod:`statectl.cell.security`) and the run config's
   (:mod:`statectl.channels.runconfig` and each section's owner: run/devices/config.py,
   channels/web/config.py, channels/opcua/config.py, run/journal/ship_config.py,
   run/commands.py). The copies shipped in
   ``statectl/data/schema/`` are checked equal to these by the suite.
2. A schema accepts every file the loader accepts as to its shape (a column
   may be a scalar or, for the list columns, a list of scalars) and refuses
   unknown keys, so an editor flags a misspelt column before statectl runs.
   What a schema cannot say (a state that does not exist, a guard that does
   not parse) stays with ``statectl check`` and the language server.
3. Column names are matched as spelt canonically or by an alias, with ``_``
   for a space too (``old_state``); statectl also accepts other letter cases,
   which the schema does not.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from typing import Any

from statectl.cell.nodes import NODE_KEYS
from statectl.cell.reader import (
    ENVIRONMENT_FIELDS,
    INVARIANT_FIELDS,
    LINK_FIELDS,
    RECOVERY_FIELDS,
)
from statectl.cell.security import SECURITY_KEYS, TLS_KEYS
from statectl.cell.values import TOP_KEYS as CELL_KEYS
from statectl.channels.opcua.config import MIN_PASSWORD, OPCUA_KEYS, POLICIES
from statectl.channels.runconfig import RUN_CONFIG_KEYS
from statectl.channels.web.config import DASHBOARD_KEYS, MAX_STREAMS, MIN_TOKEN
from statectl.front.tables.rows import (
    ALIASES,
    COLUMNS,
    CONTROL_WORDS,
    MAX_SEVERITY,
    REDO_WORDS,
    REQUIRED,
    TYPE_WORDS,
)
from statectl.front.tables.yaml_io import TOP_KEYS as DEVICE_KEYS
from statectl.kernel.model import EventKind
from statectl.run.commands import CHANNELS, GRANT_KEYS
from statectl.run.devices.config import (
    DEVICE_KEYS as DRIVER_KEYS,
)
from statectl.run.devices.config import DRIVERS
from statectl.run.journal.ship_config import SHIP_KEYS

__all__ = ["KINDS", "schema", "schema_text"]

#: The file kinds that have a schema, as ``statectl schema KIND`` names them.
KINDS = ("device", "cell", "run-config")
DRAFT = "https://json-schema.org/draft/2020-12/schema"
BASE = "https://statectl.invalid/schema/"  # an identifier, never fetched

_SCALAR: dict[str, Any] = {"type": ["string", "number", "boolean", "null"]}
_TEXT: dict[str, Any] = {"type": "string"}
_LIST_COLUMNS = ("control", "ignore", "default", "defer")
_DESCRIBED = {
    "state": "the state's name",
    "event": "the event's name",
    "old": "the state the event leaves",
    "new": "the state the event enters",
    "guard": "a condition in the safe expression language, e.g. previous == 'Moving'",
    "condition": "the paper's condition for the trigger, in words",
    "api": "the device API the row drives or reports on",
    "parent": "the compound or parallel state this one is in",
    "ignore": "events this state ignores (or: all others)",
    "defer": "events kept until the state is left",
    "timeout": "DURATION -> EVENT, armed on entry",
    "severity": "a fault's OPC UA alarm severity, 1 (lowest) to 1000",
}


def _words(words: Iterable[str]) -> dict[str, Any]:
    """A cell that is one of ``words`` (as the loader reads it: lower case)."""
    return {"type": "string", "enum": sorted(set(words))}


def _cell(table: str, column: str) -> dict[str, Any]:
    """What one column of ``table`` accepts (rule 2)."""
    out: dict[str, Any]
    if table == "states" and column == "control":
        word = _words(CONTROL_WORDS)
        out = {"anyOf": [word, {"type": "array", "items": word}, {"type": "null"}]}
    elif table == "states" and column == "type":
        out = {"anyOf": [_words(TYPE_WORDS), {"type": "null"}]}
    elif table == "events" and column == "kind":
        out = {"anyOf": [_words(k.value for k in EventKind), {"type": "null"}]}
    elif table == "recovery" and column == "redo":
        out = {"anyOf": [{"type": "boolean"}, _words(REDO_WORDS), {"type": "null"}]}
    elif table == "events" and column == "severity":
        number = {"type": "integer", "minimum": 1, "maximum": MAX_SEVERITY}
        out = {"anyOf": [number, {"type": "string", "pattern": "^[0-9]+$"}, {"type": "null"}]}
    elif column in ("data", "assign"):  # event data declared, or a recovery payload
        out = {"type": ["object", "string", "null", "array", "number", "boolean"]}
    elif column in _LIST_COLUMNS:
        out = {"anyOf": [_SCALAR, {"type": "array", "items": _SCALAR}]}
    else:
        out = dict(_SCALAR)
    if column in _DESCRIBED:
        out["description"] = _DESCRIBED[column]
    return out


def _spellings(column: str) -> list[str]:
    """The names a column may be written as in YAML: its own, its aliases, ``_`` for spaces."""
    names = [column, *(alias for alias, target in ALIASES.items() if target == column)]
    return sorted({n for name in names for n in (name, name.replace(" ", "_"))})


def _row(table: str) -> dict[str, Any]:
    """A row of ``table``: a mapping of known columns, its required ones present."""
    properties = {
        name: _cell(table, column) for column in COLUMNS[table] for name in _spellings(column)
    }
    row: dict[str, Any] = {"type": "object", "properties": properties}
    required = [c for c in REQUIRED[table] if len(_spellings(c)) == 1]
    spelt = [c for c in REQUIRED[table] if len(_spellings(c)) > 1]
    if required:
        row["required"] = required
    if spelt:  # a required column with aliases: any one spelling of it
        row["allOf"] = [{"anyOf": [{"required": [n]} for n in _spellings(c)]} for c in spelt]
    row["additionalProperties"] = False
    return row


def _table(table: str) -> dict[str, Any]:
    return {"type": "array", "items": _row(table), "minItems": 1}


def _device() -> dict[str, Any]:
    sections: dict[str, Any] = {
        "device": {**_TEXT, "description": "the device's name"},
        "profile": {**_TEXT, "description": "the standard profile it follows (cia402, ...)"},
        "states": {**_table("states"), "description": "the State Definition table"},
        "events": {**_table("events"), "description": "the Event Definition table"},
        "data": {"type": ["object", "null"], "description": "data items: name -> initial value"},
        "recovery": {**_table("recovery"), "minItems": 0, "description": "the Recovery table"},
    }
    assert tuple(sections) == DEVICE_KEYS, "the device file's top keys changed: update rule 1"
    return _document("device", "a statectl device file", sections, ["device", "states", "events"])


def _mapping(
    keys: Iterable[str], types: Mapping[str, Any], required: Iterable[str] = ()
) -> dict[str, Any]:
    """A mapping of exactly ``keys`` (each typed from ``types``, else any value)."""
    return {
        "type": "object",
        "properties": {k: types.get(k, {}) for k in keys},
        "required": list(required),
        "additionalProperties": False,
    }


def _cell_file() -> dict[str, Any]:
    flag = {"type": "boolean"}
    link = _mapping(
        LINK_FIELDS,
        {
            "from": {**_TEXT, "description": "the source device"},
            "enters": {**_TEXT, "description": "a state of the source device"},
            "raises": {**_TEXT, "description": "an event of the source device"},
            "to": {**_TEXT, "description": "the target device"},
            "send": {**_TEXT, "description": "an event of the target device (EVENT {data})"},
            "guard": {**_TEXT, "description": "a global expression, e.g. In('arm.Moving')"},
            "forward_data": flag,
            "ignore_if_unhandled": flag,
            "lossy": flag,
            "delayed": flag,
            "on_peer_down": {"enum": ["queue", "drop"]},
            "dropped": _TEXT,
        },
        ("from", "to", "send"),
    )
    link["oneOf"] = [{"required": ["enters"]}, {"required": ["raises"]}]
    entry = _mapping(ENVIRONMENT_FIELDS, {k: _TEXT for k in ENVIRONMENT_FIELDS}, ("to",))
    entry["oneOf"] = [{"required": ["send"]}, {"required": ["fault"]}]
    sends = _mapping(("to", "send"), {"to": _TEXT, "send": _TEXT}, ("to", "send"))
    invariant = _mapping(
        INVARIANT_FIELDS,
        {"name": _TEXT, "holds": _TEXT, "on_violation": {"anyOf": [sends, {"items": sends}]}},
        ("holds",),
    )
    recovery = _mapping(RECOVERY_FIELDS, {k: _TEXT for k in RECOVERY_FIELDS}, ("to",))
    texts = {"type": "array", "items": _TEXT}
    node = _mapping(
        NODE_KEYS,
        {
            "devices": texts,
            "listen": texts,
            "connect": texts,
            "lease": {"type": "number", "exclusiveMinimum": 0},
            "peer_lost": {"type": "object", "additionalProperties": _TEXT},
        },
    )
    device = {"anyOf": [_TEXT, _mapping(("file",), {"file": _TEXT}, ("file",))]}
    sections: dict[str, Any] = {
        "cell": {**_TEXT, "description": "the cell's name"},
        "devices": {
            "type": "object",
            "minProperties": 1,
            "additionalProperties": device,
            "description": "instance name -> device file",
        },
        "links": {"type": ["array", "null"], "items": link},
        "environment": {"type": ["array", "null"], "items": entry},
        "invariants": {"type": ["array", "null"], "items": invariant},
        "recovery": {"type": ["array", "null"], "items": recovery},
        "completions": {"enum": ["auto", "off"]},
        "nodes": {"type": "object", "additionalProperties": node},
        "security": _security(texts),
    }
    assert tuple(sections) == CELL_KEYS, "the cell file's keys changed: update rule 1"
    return _document("cell", "a statectl cell file", sections, ["devices"])


def _security(texts: dict[str, Any]) -> dict[str, Any]:
    """The cell's ``security:`` section (statectl.cell.security)."""
    pair = _mapping(("certificate", "key"), {"certificate": _TEXT, "key": _TEXT})
    pair["required"] = ["certificate", "key"]
    given = _mapping(
        TLS_KEYS, {"ca": _TEXT, "certificates": {"type": "object", "additionalProperties": pair}}
    )
    given["required"] = list(TLS_KEYS)
    return _mapping(
        SECURITY_KEYS,
        {
            "tls": {
                "anyOf": [_TEXT, given],
                "description": "a directory for the cell's CA and node certificates, or files",
            },
            "users": {**_TEXT, "description": "a file of name:password lines"},
            "posts": {"type": "object", "additionalProperties": texts},
            "stations": texts,
            "insecure": {"type": "boolean"},
        },
    )


def _run_config() -> dict[str, Any]:
    driver = {
        "anyOf": [
            {"enum": list(DRIVERS)},
            {"type": "string", "pattern": r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$"},
        ],
        "description": "a driver statectl ships, or package.module:Class",
    }
    entry = _mapping(DRIVER_KEYS, {"driver": driver, "options": {"type": ["object", "null"]}})
    entry["required"] = ["driver"]
    seconds = {"type": "number", "minimum": 0.01, "maximum": 3600}
    sections: dict[str, Any] = {
        "devices": {"type": "object", "additionalProperties": entry},
        "dashboard": _mapping(
            DASHBOARD_KEYS,
            {
                "host": {"type": "string", "minLength": 1},
                "port": {"type": "integer", "minimum": 0, "maximum": 65535},
                "token": {"type": "string", "minLength": MIN_TOKEN},
                "streams": {"type": "integer", "minimum": 1, "maximum": MAX_STREAMS},
            },
        ),
        "opcua": _mapping(
            OPCUA_KEYS,
            {
                "endpoint": {"type": "string", "pattern": "^opc\\.tcp://"},
                "user": _TEXT,
                "password": {"type": "string", "minLength": MIN_PASSWORD},
                "security": {"type": "array", "items": {"enum": list(POLICIES)}},
                "certificates": _TEXT,
            },
        ),
        "ship": _mapping(
            SHIP_KEYS,
            {
                "to": {"type": "string", "pattern": "^postgres(ql)?://"},
                "source": {"type": "string", "minLength": 1},
                "interval": seconds,
                "retry": seconds,
                "batch": {"type": "integer", "minimum": 1, "maximum": 1_000_000},
            },
            ("to",),
        ),
        "commands": {"type": "array", "items": _grant()},
    }
    assert tuple(sections) == RUN_CONFIG_KEYS, "the run config's keys changed: update rule 1"
    document = _document("run-config", "a statectl run configuration", sections, [])
    document["minProperties"] = 1
    return document


def _grant() -> dict[str, Any]:
    """A grant of the ``commands:`` section (:mod:`statectl.run.commands`)."""
    name = {"type": "string", "minLength": 1}
    names = {"anyOf": [name, {"type": "array", "minItems": 1, "items": name}]}
    origin = {
        "type": "string",
        "pattern": f"^({'|'.join(CHANNELS)})(/.+)?$",
        "description": "CHANNEL (anyone), CHANNEL/* (anyone it authenticated) or CHANNEL/NAME",
    }
    return _mapping(GRANT_KEYS, {"from": origin, "to": names, "send": names}, ("from",))


def _document(
    kind: str, title: str, sections: dict[str, Any], required: list[str]
) -> dict[str, Any]:
    return {
        "$schema": DRAFT,
        "$id": f"{BASE}{kind}.schema.json",
        "title": title,
        "type": "object",
        "properties": sections,
        "required": required,
        "additionalProperties": False,
    }


def schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of ``kind`` (one of :data:`KINDS`); ``ValueError`` for another."""
    makers = {"device": _device, "cell": _cell_file, "run-config": _run_config}
    if kind not in makers:
        raise ValueError(f"no schema for {kind!r}: choose {', '.join(KINDS)}")
    return makers[kind]()


def schema_text(kind: str) -> str:
    """The schema as the shipped file holds it: indented JSON, keys in the order made."""
    return json.dumps(schema(kind), indent=2) + "\n"
