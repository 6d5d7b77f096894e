"""What a link, an invariant and a device row may say beyond the basic cell file.

Rules:
1. ``send: Reset {status: true}`` (quoted in block YAML) sends ``Reset`` with that
   event data; ``data: {status: true}`` says the same; ``forward_data: true`` sends
   the triggering step's event data on instead. Constant data must be YAML flow
   style; both a constant and ``forward_data`` is V830.
2. ``ignore_if_unhandled: true`` says the event is harmless where it lands
   unhandled (a second Abort to an Aborting unit): verify does not report it.
3. ``lossy: true`` / ``delayed: true`` let verify explore the link's event lost,
   or overtaken by the link events queued after it (docs/cells.md).
4. An invariant's ``on_violation`` lists ``{to: DEVICE, send: EVENT}``: what a run
   sends when the invariant turns false (an emergency stop to named devices).
5. A device row's guard may read another device of the cell with
   ``In('axis1.Standstill')``; such references are checked against the cell's
   devices when the cell loads (V831).
Kept out of :mod:`statectl.cell.reader` so the reader stays one small change away
from what it was.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping
from typing import Any

import yaml

from statectl.cell.expressions import _d
from statectl.front.tables import safeyaml
from statectl.kernel.errors import Diagnostic, Location
from statectl.kernel.expr import in_target
from statectl.kernel.model import Chart

__all__ = [
    "LINK_OPTION_KEYS",
    "check_cross_refs",
    "cross_refs",
    "foreign_in",
    "link_options",
    "send_and_data",
    "violation_events",
]

#: Keys a link may have beyond from/enters/raises/to/send/guard.
LINK_OPTION_KEYS = ("data", "forward_data", "ignore_if_unhandled", "lossy", "delayed")


def send_and_data(node: yaml.Node | None) -> tuple[yaml.Node | None, Any, str]:
    """Split ``send: Event {data}`` into the event's node and its data (rule 1).

    Returns the node naming the event alone, the data (``None``: none) and an
    error message ("" when the data reads).
    """
    if not isinstance(node, yaml.ScalarNode) or node.tag.endswith(":null"):
        return node, None, ""
    text = str(node.value)
    brace = min((i for i in (text.find("{"), text.find("[")) if i >= 0), default=-1)
    if brace < 0:
        return node, None, ""
    try:
        data = safeyaml.load_value(text[brace:])
    except safeyaml.YamlRefused as exc:
        return node, None, f"the data after the event is not YAML flow style ({exc.message})"
    event = " ".join(text[:brace].split())
    plain = yaml.ScalarNode(node.tag, event, node.start_mark, node.end_mark)
    return plain, data, ""


def _flag(node: yaml.Node | None, what: str, where: Location, diags: list[Diagnostic]) -> bool:
    if node is None:
        return False
    if isinstance(node, yaml.ScalarNode) and node.value in (
        "true",
        "True",
        "yes",
        "false",
        "False",
        "no",
    ):
        return node.value in ("true", "True", "yes")
    diags.append(_d("V804", where, f"{what} must be true or false"))
    return False


def _value(node: yaml.Node) -> Any:
    """The plain value of a composed YAML node (mappings, lists, scalars)."""
    return yaml.safe_load(yaml.serialize(node))


def link_options(
    fields: Mapping[str, yaml.Node], send: yaml.Node | None, at: Location
) -> tuple[dict[str, Any], list[Diagnostic]]:
    """The link's data and flags (rules 1-3) as keyword arguments of :class:`Link`."""
    diags: list[Diagnostic] = []
    plain, data, problem = send_and_data(send)
    if problem:
        diags.append(
            _d(
                "V830",
                at,
                f"link send {send.value if send else ''!r}: {problem}",
                'write e.g. send: "Reset {status: true}"',
            )
        )
    if "data" in fields:
        if data is not None:
            diags.append(
                _d(
                    "V830",
                    at,
                    "the link gives data twice: after the event and in data:",
                    "keep one",
                )
            )
        data = _value(fields["data"])
    forward = _flag(fields.get("forward_data"), "link forward_data", at, diags)
    if forward and data is not None:
        diags.append(
            _d(
                "V830",
                at,
                "a link cannot both send constant data and forward the triggering event's data",
                "drop data: or forward_data:",
            )
        )
    options: dict[str, Any] = {
        "data": data,
        "forward_data": forward,
        "ignore_if_unhandled": _flag(
            fields.get("ignore_if_unhandled"), "link ignore_if_unhandled", at, diags
        ),
        "lossy": _flag(fields.get("lossy"), "link lossy", at, diags),
        "delayed": _flag(fields.get("delayed"), "link delayed", at, diags),
    }
    del plain
    return options, diags


def violation_events(
    node: yaml.Node | None, file: str, charts: Mapping[str, Chart]
) -> tuple[tuple[tuple[str, str], ...], list[Diagnostic]]:
    """An invariant's ``on_violation`` list as (device, event) pairs (rule 4)."""
    if node is None:
        return (), []
    where = Location(file, node.start_mark.line + 1)
    value = _value(node)
    items = value if isinstance(value, list) else [value]
    out: list[tuple[str, str]] = []
    diags: list[Diagnostic] = []
    for item in items:
        if not (isinstance(item, dict) and set(item) == {"to", "send"}):
            diags.append(
                _d(
                    "V804",
                    where,
                    "on_violation lists {to: DEVICE, send: EVENT} entries",
                    "e.g. on_violation: [{to: axis1, send: Stop}]",
                )
            )
            continue
        device, event = str(item["to"]), str(item["send"])
        chart = charts.get(device)
        if chart is None:
            diags.append(
                _d(
                    "V807",
                    where,
                    f"on_violation: no device named {device!r}",
                    "devices: " + ", ".join(sorted(charts)),
                )
            )
        elif event not in chart.event_names:
            diags.append(
                _d(
                    "V809",
                    where,
                    f"on_violation: device {device!r} has no event {event!r}",
                    "events: " + ", ".join(chart.event_names),
                )
            )
        else:
            out.append((device, event))
    return tuple(out), diags


def foreign_in(node: ast.AST, chart: Chart) -> str | None:
    """``'device.State'`` when ``node`` is an ``In`` of another device's state: a dotted name
    that is no state of ``chart`` (a name without a dot is the device's own, or a typo its
    device file reports)."""
    name = in_target(node)
    return name if name is not None and "." in name and not chart.has_state(name) else None


def cross_refs(chart: Chart) -> list[tuple[str, str, str, Location]]:
    """``In('device.State')`` calls in ``chart``'s guards that name no state of its own.

    Returns (guard, device, state, where) for each; a name without a dot is the
    device's own state and is the device file's to check.
    """
    out: list[tuple[str, str, str, Location]] = []
    for t in chart.transitions:
        if not t.guard:
            continue
        try:
            tree = ast.parse(t.guard.strip(), mode="eval")
        except SyntaxError:
            continue
        for node in ast.walk(tree):
            name = foreign_in(node, chart)
            if name is None:
                continue
            device, _, state = name.partition(".")
            out.append((t.guard, device, state, t.origin))
    return out


def check_cross_refs(devices: Mapping[str, Chart], file: str) -> list[Diagnostic]:
    """Rule 5: every device guard's ``In('device.State')`` names a device and state of the cell."""
    diags: list[Diagnostic] = []
    for name, chart in devices.items():
        for guard, device, state, origin in cross_refs(chart):
            other = devices.get(device)
            where = Location(file, 1) if origin is None else origin
            if other is None:
                diags.append(
                    _d(
                        "V831",
                        where,
                        f"device {name!r}: guard {guard!r} reads In({device + '.' + state!r}), "
                        f"but the cell has no device {device!r}",
                        "devices: " + ", ".join(sorted(devices)),
                    )
                )
            elif not other.has_state(state):
                diags.append(
                    _d(
                        "V831",
                        where,
                        f"device {name!r}: guard {guard!r} reads In({device + '.' + state!r}), "
                        f"but device {device!r} has no state {state!r}",
                        "states: " + ", ".join(s.name for s in other.states),
                    )
                )
    return diags
