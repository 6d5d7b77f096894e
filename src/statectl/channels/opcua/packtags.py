"""PackTags (OPC 30050) of a PackML device: the ``Status`` and ``Admin`` objects a PackML
client reads, filled from the device's state and the data items its tables declare.

Rules:
1. A device that declares ``profile: packml`` gets a ``Status`` and an ``Admin`` object
   (browse names in the PackML namespace, as OPC 30050 puts them on a PackML object),
   components of the device object; a ``PackTags`` folder of the device organizes
   both, so either path leads to the same variables.
2. Which tags (:data:`TAGS`): ``Status/StateCurrent`` (Int32) is always there: the
   PackML number of the state the unit is in (the innermost active state whose table
   gives a ``number``; 0, PackML's Undefined, when none is active).
   ``Status/UnitModeCurrent`` (Int32) is the data item ``unit_mode`` (or
   ``UnitModeCurrent``) when the device declares one, else 1 (Production): statectl
   runs a unit in one mode. Every other tag is there only when the device declares a
   data item of its name, in either spelling (``ProdProcessedCount`` or
   ``prod_processed_count``), and holds that item's value.
3. Types are the companion's for the scalar tags (Int32 counters and mode, Float
   speeds); ``StopReason`` is the ``ID`` of the companion's ``PackMLAlarmDataType``
   as an Int32 when the item holds a number, or its text as a String when it holds
   text. The companion's structures (``PackMLCountDataType``, ``PackMLAlarmDataType``)
   are not served: the server loads no OPC 30050 nodeset (so no type node ids).
4. They are written after each step that changed them, with the states and the
   ``Data`` variables; a value its tag's type cannot hold (text in a counter, an
   Int32 overflow) leaves the last one, marked ``UncertainLastUsableValue``. Nobody
   may write them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from statectl.channels.opcua.access import ua_module as _ua
from statectl.kernel.model import Chart

__all__ = ["TAGS", "PackTags", "tag_items"]

#: (object, tag) -> its variant type name; the state's and the mode's are always there.
TAGS: dict[tuple[str, str], str] = {
    ("Status", "StateCurrent"): "Int32",
    ("Status", "UnitModeCurrent"): "Int32",
    ("Status", "MachSpeed"): "Float",
    ("Status", "CurMachSpeed"): "Float",
    ("Admin", "ProdProcessedCount"): "Int32",
    ("Admin", "ProdDefectiveCount"): "Int32",
    ("Admin", "ProdConsumedCount"): "Int32",
    ("Admin", "StopReason"): "Int32",
}
#: The data item names that fill a tag besides its own and its snake_case spelling.
_ALSO = {"UnitModeCurrent": ("unit_mode",)}
#: PackML's Production mode: what a unit that declares no mode runs in (rule 2).
PRODUCTION = 1
_INT32 = (-(2**31), 2**31)


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


def tag_items(data: dict[str, Any]) -> dict[str, str]:
    """Tag -> the data item that fills it (rule 2), for the items ``data`` declares."""
    found: dict[str, str] = {}
    for _, tag in TAGS:
        for name in (tag, _snake(tag), *_ALSO.get(tag, ())):
            if name in data:
                found[tag] = name
                break
    return found


@dataclass(slots=True)
class _Tag:
    node: Any
    kind: str  # variant type name
    item: str | None  # the data item, or None for StateCurrent and a fixed mode
    shown: Any = None
    uncertain: bool = False  # shows the last value, marked UncertainLastUsableValue


class PackTags:
    """One PackML device's tags (rules 1-4); created and written on the server's loop."""

    def __init__(self, chart: Chart, tags: dict[str, _Tag]) -> None:
        self.tags = tags
        self._numbers = {s.name: s.number for s in chart.states if s.number is not None}
        self._depth = {s.name: _depth(chart, s.name) for s in chart.states}

    @classmethod
    async def create(
        cls, device: Any, chart: Chart, idx: int, packml_ns: int, data: dict[str, Any]
    ) -> PackTags:
        """Rule 1: the objects and their variables, each holding a value of its type."""
        ua = _ua()
        items = tag_items(data)
        folder = await device.add_folder(idx, "PackTags")
        objects: dict[str, Any] = {}
        tags: dict[str, _Tag] = {}
        for (holder, tag), kind in TAGS.items():
            item = items.get(tag)
            if item is None and tag not in ("StateCurrent", "UnitModeCurrent"):
                continue
            if tag == "StopReason" and item is not None and isinstance(data[item], str):
                kind = "String"
            if holder not in objects:
                made = await device.add_object(
                    ua.NodeId(0, idx), ua.QualifiedName(holder, packml_ns)
                )
                await folder.add_reference(made.nodeid, ua.ObjectIds.Organizes)
                objects[holder] = made
            start = _fit(data[item], kind) if item is not None else None
            if start is None:
                start = PRODUCTION if tag == "UnitModeCurrent" and item is None else _zero(kind)
            variant = ua.Variant(start, getattr(ua.VariantType, kind))
            node = await objects[holder].add_variable(
                ua.NodeId(0, idx), ua.QualifiedName(tag, packml_ns), variant
            )
            tags[tag] = _Tag(node, kind, item, start)
        return cls(chart, tags)

    def state_current(self, active: frozenset[str]) -> int:
        """Rule 2: the PackML number of the innermost numbered active state, else 0."""
        numbered = [s for s in active if s in self._numbers]
        if not numbered:
            return 0
        return int(self._numbers[max(numbered, key=lambda s: self._depth[s])] or 0)

    async def write(
        self, server: Any, active: frozenset[str], data: dict[str, Any] | None, now: Any
    ) -> None:
        """Rule 4: write the tags whose value changed."""
        ua = _ua()
        for name, tag in self.tags.items():
            if name == "StateCurrent":
                value: Any = self.state_current(active)
            elif tag.item is None or data is None or tag.item not in data:
                continue
            else:
                value = _fit(data[tag.item], tag.kind)
            status = ua.StatusCode(ua.StatusCodes.Good)
            if value is None:
                if tag.uncertain:
                    continue
                value, status = tag.shown, ua.StatusCode(ua.StatusCodes.UncertainLastUsableValue)
                tag.uncertain = True
            elif value == tag.shown and not tag.uncertain:
                continue
            else:
                tag.uncertain = False
            tag.shown = value
            variant = ua.Variant(value, getattr(ua.VariantType, tag.kind))
            data_value = ua.DataValue(variant, status, SourceTimestamp=now, ServerTimestamp=now)
            await server.write_attribute_value(tag.node.nodeid, data_value)


def _fit(value: Any, kind: str) -> Any:
    """``value`` as the tag's type, or None when it cannot be (rule 4)."""
    if isinstance(value, bool):
        return None
    if kind == "Int32":
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        return value if isinstance(value, int) and _INT32[0] <= value < _INT32[1] else None
    if kind == "Float":
        return float(value) if isinstance(value, int | float) else None
    return value if isinstance(value, str) else None


def _zero(kind: str) -> Any:
    return {"Int32": 0, "Float": 0.0}.get(kind, "")


def _depth(chart: Chart, state: str) -> int:
    depth, parent = 0, chart.state(state).parent
    while parent is not None:
        depth, parent = depth + 1, chart.state(parent).parent
    return depth
