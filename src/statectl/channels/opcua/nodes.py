"""The OPC UA server's nodes and values that need no server state (rules 2, 3 and 5 of
:mod:`statectl.channels.opcua.server`): browse names, the optional properties a type
left out, nulls of the right type, method arguments and the data items' variables."""

from __future__ import annotations

import json
from typing import Any

from statectl.channels.opcua.access import ua_module as _ua
from statectl.channels.opcua.methods import DATA_ARGUMENT, FIELD_TYPES, MAX_DATA

__all__ = [
    "browse",
    "data_argument",
    "data_kind",
    "data_variant",
    "node_ids",
    "nothing_yet",
    "optional",
    "typed_argument",
    "write_data",
]


def browse(name: str) -> str:
    """A browse name: OPC UA allows most characters; ':' would read as a namespace index."""
    return name.replace(":", "_")


async def optional(node: Any, idx: int, name: str, variant: Any, empty: Any) -> Any:
    """An optional property (``Number``, ``TransitionTime``), added where instancing left it out."""
    ua = _ua()

    try:
        return await node.get_child(f"0:{name}")
    except ua.UaError:  # BadNoMatch: the type left it out
        where = ua.NodeId(0, idx)  # a new numeric id in statectl's namespace
        return await node.add_property(where, ua.QualifiedName(name, 0), ua.Variant(empty, variant))


async def nothing_yet(last: Any) -> None:
    """``LastTransition`` before the first transition: an empty text with a null ``Id``, nulls
    of their types (asyncua instances both as a Null variant, which generic clients flag)."""
    ua = _ua()

    await last.write_value(ua.Variant(ua.LocalizedText(""), ua.VariantType.LocalizedText))
    last_id = await last.get_child("0:Id")
    await last_id.write_value(ua.Variant(ua.NodeId(), ua.VariantType.NodeId))


async def node_ids(machine: Any, idx: int, name: str) -> Any:
    """An optional ``NodeId[]`` of a machine (``AvailableStates``, ``AvailableTransitions``):
    asyncua instances it with a null value, which becomes an empty array until the
    machine's state is first shown (added where instancing left it out)."""
    ua = _ua()

    empty = ua.Variant([], ua.VariantType.NodeId, is_array=True)
    try:
        node = await machine.get_child(f"0:{name}")
    except ua.UaError:  # BadNoMatch: the type left it out
        where, bname = ua.NodeId(0, idx), ua.QualifiedName(name, 0)
        node = await machine.add_variable(where, bname, empty, ua.VariantType.NodeId)
    await node.write_value(empty)
    await node.write_value_rank(ua.ValueRank.OneDimension)
    await node.write_array_dimensions([0])
    return node


def data_argument() -> Any:
    """A device method's one optional input (methods.py rule 2)."""
    ua = _ua()

    arg = ua.Argument()
    arg.Name = DATA_ARGUMENT
    arg.DataType = ua.NodeId(ua.ObjectIds.String)
    arg.ValueRank = -1
    arg.Description = ua.LocalizedText(
        f"the event's data as a JSON object, at most {MAX_DATA} bytes; empty: none"
    )
    return arg


def typed_argument(name: str, kind: str) -> Any:
    """One input of a method whose event declares its data: the field, typed (methods.py
    rule 2); ``list``, ``dict`` and ``any`` fields are JSON text."""
    ua = _ua()

    arg = ua.Argument()
    arg.Name = name
    arg.DataType = ua.NodeId(getattr(ua.ObjectIds, FIELD_TYPES.get(kind, "String")))
    arg.ValueRank = -1
    json_text = FIELD_TYPES.get(kind) == "String" and kind != "str"
    arg.Description = ua.LocalizedText(
        f"{name}: {kind}" + (f", as JSON text of at most {MAX_DATA} bytes" if json_text else "")
    )
    return arg


def data_kind(value: Any) -> str:
    """A data item's variable type, from its initial value (rule 5)."""
    if isinstance(value, bool):
        return "Boolean"
    if isinstance(value, int) and -(2**63) <= value < 2**63:
        return "Int64"
    if isinstance(value, float):
        return "Double"
    if isinstance(value, str):
        return "String"
    return "Json"  # null, a list, a mapping: JSON text


def data_variant(value: Any, kind: str) -> Any:
    """``value`` as a variant of ``kind``; None when it does not fit (rule 5)."""
    ua = _ua()

    if kind == "Json":
        try:
            text = json.dumps(value, default=str, allow_nan=True)
        except (TypeError, ValueError):
            return None
        return ua.Variant(text, ua.VariantType.String)
    if isinstance(value, bool) != (kind == "Boolean"):
        return None
    if kind == "Int64" and isinstance(value, float) and value.is_integer():
        value = int(value)
    if kind == "Double" and isinstance(value, int):
        value = float(value)
    fits = {"Boolean": bool, "Int64": int, "Double": float, "String": str}[kind]
    if not isinstance(value, fits):
        return None
    if isinstance(value, int) and kind == "Int64" and not -(2**63) <= value < 2**63:
        return None
    return ua.Variant(value, getattr(ua.VariantType, kind))


async def write_data(
    server: Any, shown: dict[str, list[Any]], data: dict[str, Any], now: Any
) -> None:
    """Rule 5: write the data items whose value changed; one that no longer fits its
    variable's type keeps its last value, marked ``UncertainLastUsableValue``."""
    ua = _ua()

    for item, value in data.items():
        entry = shown.get(item)
        if entry is None:
            continue
        variable, kind, last = entry
        variant = data_variant(value, kind)
        status = ua.StatusCode(ua.StatusCodes.Good)
        if variant is None:
            variant = last
            status = ua.StatusCode(ua.StatusCodes.UncertainLastUsableValue)
        elif variant == last:
            continue
        entry[2] = variant
        data_value = ua.DataValue(variant, status, SourceTimestamp=now, ServerTimestamp=now)
        await server.write_attribute_value(variable.nodeid, data_value)
