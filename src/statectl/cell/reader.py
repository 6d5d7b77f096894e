"""Reading a cell file's sections from YAML nodes: devices (V805, V806, V815), links
(V813), environment inputs (V812), invariants and recovery goals (V814), each problem
a V8xx diagnostic with its line. Split from :func:`statectl.cell.model.load_cell`, which
parses the file and puts the sections together.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import yaml

from statectl.cell.expressions import _d, parse_global
from statectl.cell.nodes import LINK_KEYS
from statectl.cell.options import LINK_OPTION_KEYS, link_options, send_and_data
from statectl.cell.values import DeviceRef, EnvInput, GlobalExpr, InputKind, Link, Trigger
from statectl.front.builder.build import load_and_build
from statectl.front.rules.names import check_guard_names
from statectl.kernel.errors import Diagnostic, Location, Severity, did_you_mean, has_errors
from statectl.kernel.model import Chart, ControlKind, EventKind

#: The keys of an entry in each of a cell's lists (the JSON Schema, out/schema.py, reads them).
LINK_FIELDS = ("from", "enters", "raises", "to", "send", "guard", *LINK_OPTION_KEYS, *LINK_KEYS)
ENVIRONMENT_FIELDS = ("send", "fault", "to", "when")
INVARIANT_FIELDS = ("name", "holds", "on_violation")
RECOVERY_FIELDS = ("name", "to", "from")

# -- YAML reading ---------------------------------------------------------------------------


class _Reader:
    """Reads the composed YAML tree, keeping lines and collecting diagnostics."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.diags: list[Diagnostic] = []

    def at(self, node: yaml.Node) -> Location:
        return Location(self.file, node.start_mark.line + 1)

    def mapping(
        self, node: yaml.Node, what: str, keys: tuple[str, ...], required: tuple[str, ...] = ()
    ) -> dict[str, yaml.Node] | None:
        if not isinstance(node, yaml.MappingNode):
            self.diags.append(
                _d("V804", self.at(node), f"{what} must be a mapping", "write key: value lines")
            )
            return None
        out: dict[str, yaml.Node] = {}
        for k, v in node.value:
            key = str(k.value) if isinstance(k, yaml.ScalarNode) else ""
            if key not in keys:
                self.diags.append(
                    _d(
                        "V802",
                        self.at(k),
                        f"{what}: unknown key {key!r}",
                        "known keys: " + ", ".join(keys),
                    )
                )
            elif key in out:
                self.diags.append(_d("V802", self.at(k), f"{what}: key {key!r} appears twice"))
            else:
                out[key] = v
        for key in required:
            if key not in out:
                self.diags.append(
                    _d("V803", self.at(node), f"{what} has no {key!r}", f"add {key}: ...")
                )
        return out

    def text(self, node: yaml.Node | None, what: str) -> str | None:
        if node is None:
            return None
        if not isinstance(node, yaml.ScalarNode) or node.tag.endswith(":null"):
            self.diags.append(_d("V804", self.at(node), f"{what} must be text"))
            return None
        return str(node.value)

    def items(self, node: yaml.Node | None, what: str) -> list[yaml.Node]:
        if node is None or (isinstance(node, yaml.ScalarNode) and node.tag.endswith(":null")):
            return []
        if not isinstance(node, yaml.SequenceNode):
            self.diags.append(
                _d("V804", self.at(node), f"{what} must be a list", "start each entry with '- '")
            )
            return []
        return list(node.value)


def _load_devices(r: _Reader, node: yaml.Node | None, base: Path, at: Location) -> list[DeviceRef]:
    if node is None:
        r.diags.append(_d("V815", at, "the cell has no devices", "add devices: {name: file}"))
        return []
    if not isinstance(node, yaml.MappingNode):
        r.diags.append(
            _d(
                "V804",
                r.at(node),
                "devices must be a mapping of name: file",
                "write e.g. arm: arm.yaml",
            )
        )
        return []
    entries = _device_entries(r, node)
    loaded: dict[Path, tuple[Chart | None, list[Diagnostic]]] = {}
    out: list[DeviceRef] = []
    for name, value in entries.items():
        where = r.at(value)
        file = _device_file(r, name, value, where)
        if file is None:
            continue
        path = (base / file).resolve()
        if path not in loaded:
            if not path.exists():
                loaded[path] = (
                    None,
                    [
                        _d(
                            "V805",
                            where,
                            f"device file {file!r} does not exist",
                            f"looked for {path}",
                        )
                    ],
                )
            else:
                loaded[path] = load_and_build(path)
        chart, diags = loaded[path]
        if chart is not None:  # a guard naming a state or event the device lacks (C420/C421)
            diags = [*diags, *check_guard_names(chart)]
        if chart is None or has_errors(diags):
            errors = [d for d in diags if d.severity is Severity.ERROR]
            r.diags.append(
                _d(
                    "V805",
                    where,
                    f"device {name!r}: {file!r} does not load ({len(errors)} error(s) follow)",
                    "run: statectl check " + file,
                )
            )
            r.diags.extend(errors)
            continue
        out.append(DeviceRef(name, str(path), chart, where))
    return out


def _device_entries(r: _Reader, node: yaml.MappingNode) -> dict[str, yaml.Node]:
    """The devices: mapping by name; a repeated name is V806 and the last one counts."""
    entries: dict[str, yaml.Node] = {}
    for k, v in node.value:
        key = str(k.value) if isinstance(k, yaml.ScalarNode) else ""
        if key in entries:
            r.diags.append(_d("V806", r.at(k), f"device name {key!r} is used twice"))
        entries[key] = v
    if not entries:
        r.diags.append(_d("V815", r.at(node), "the cell has no devices"))
    return entries


def _device_file(r: _Reader, name: str, value: yaml.Node, where: Location) -> str | None:
    """The file one device entry names (``arm: arm.yaml`` or ``arm: {file: ...}``), or None
    with the reason: a name In() cannot split (V806), no text, a NUL (V805)."""
    if not name.isidentifier():
        r.diags.append(
            _d(
                "V806",
                where,
                f"device name {name!r} is not an identifier",
                "use letters, digits and '_' (no dots): In('arm.Moving') splits at the dot",
            )
        )
        return None
    if isinstance(value, yaml.MappingNode):
        fields = r.mapping(value, f"device {name!r}", ("file",), ("file",))
        file = r.text(fields.get("file"), f"device {name!r} file") if fields else None
    else:
        file = r.text(value, f"device {name!r}")
    if file is None:
        return None
    if "\x00" in file:  # no file system names one: resolve() would raise ValueError
        r.diags.append(
            _d("V805", where, f"device file {file!r} holds a NUL character", "name a file")
        )
        return None
    return file


def _expr(
    r: _Reader, node: yaml.Node | None, what: str, charts: Mapping[str, Chart]
) -> GlobalExpr | None:
    text = r.text(node, what)
    if text is None or node is None:
        return None
    expr, diags = parse_global(text, r.at(node), charts, what=what)
    r.diags.extend(diags)
    return expr


def _device(r: _Reader, node: yaml.Node | None, what: str, charts: Mapping[str, Chart]) -> str:
    name = r.text(node, what) or ""
    if node is not None and name and name not in charts:
        r.diags.append(
            _d(
                "V807",
                r.at(node),
                f"{what}: no device named {name!r}",
                "devices: " + ", ".join(sorted(charts)),
            )
        )
        return ""
    return name


def _event(
    r: _Reader, node: yaml.Node | None, what: str, device: str, charts: Mapping[str, Chart]
) -> str:
    event = r.text(node, what) or ""
    if node is not None and event and device and event not in charts[device].event_names:
        r.diags.append(
            _d(
                "V809",
                r.at(node),
                f"{what}: device {device!r} has no event {event!r}",
                "events: " + ", ".join(charts[device].event_names),
            )
        )
        return ""
    return event


def _links(r: _Reader, node: yaml.Node | None, charts: Mapping[str, Chart]) -> list[Link]:
    out: list[Link] = []
    for item in r.items(node, "links"):
        f = r.mapping(item, "link", LINK_FIELDS, ("from", "to", "send"))
        if f is None:
            continue
        at = r.at(item)
        source = _device(r, f.get("from"), "link from", charts)
        target = _device(r, f.get("to"), "link to", charts)
        options, problems = link_options(f, f.get("send"), at)  # cell/options.py
        r.diags.extend(problems)
        event = _event(r, send_and_data(f.get("send"))[0], "link send", target, charts)
        guard = _expr(r, f.get("guard"), "link guard", charts) if "guard" in f else None
        if ("enters" in f) == ("raises" in f):
            r.diags.append(
                _d(
                    "V813",
                    at,
                    "a link needs exactly one of 'enters' and 'raises'",
                    "enters: a state of the source device; raises: one of its events",
                )
            )
            continue
        trigger = Trigger.ENTERS if "enters" in f else Trigger.RAISES
        what = r.text(f[trigger.value], f"link {trigger.value}") or ""
        if source and what:
            chart = charts[source]
            if trigger is Trigger.ENTERS and not chart.has_state(what):
                r.diags.append(
                    _d(
                        "V808",
                        r.at(f["enters"]),
                        f"link: device {source!r} has no state {what!r}",
                        did_you_mean(what, [s.name for s in chart.states])
                        + "states: "
                        + ", ".join(s.name for s in chart.states),
                    )
                )
                continue
            if trigger is Trigger.RAISES and what not in chart.event_names:
                r.diags.append(
                    _d(
                        "V809",
                        r.at(f["raises"]),
                        f"link: device {source!r} has no event {what!r}",
                        "events: " + ", ".join(chart.event_names),
                    )
                )
                continue
        if source and target and event and what and ("guard" not in f or guard is not None):
            out.append(Link(source, trigger, what, target, event, guard, at, **options))
    return out


def _environment(r: _Reader, node: yaml.Node | None, charts: Mapping[str, Chart]) -> list[EnvInput]:
    out: list[EnvInput] = []
    for item in r.items(node, "environment"):
        f = r.mapping(item, "environment entry", ENVIRONMENT_FIELDS, ("to",))
        if f is None:
            continue
        at = r.at(item)
        if ("send" in f) == ("fault" in f):
            r.diags.append(
                _d(
                    "V803",
                    at,
                    "an environment entry needs exactly one of 'send' and 'fault'",
                    "send: a command the outside may give; fault: what hardware may raise",
                )
            )
            continue
        kind = InputKind.COMMAND if "send" in f else InputKind.FAULT
        device = _device(r, f.get("to"), "environment to", charts)
        key = "send" if kind is InputKind.COMMAND else "fault"
        event = _event(r, f.get(key), f"environment {key}", device, charts)
        when = _expr(r, f.get("when"), "environment when", charts) if "when" in f else None
        if kind is InputKind.FAULT and device and event:
            chart = charts[device]
            definition = chart.event(event)
            if definition is not None and definition.kind is not EventKind.FAULT:
                r.diags.append(
                    Diagnostic(
                        "V812",
                        Severity.WARNING,
                        r.at(f[key]),
                        f"environment fault {event!r} of {device!r} is a "
                        f"{definition.kind.value} event",
                        "faults are raised by monitors; use send: for commands",
                    )
                )
            if not any(ControlKind.MONITORING in s.controls for s in chart.states):
                r.diags.append(
                    _d(
                        "V812",
                        at,
                        f"device {device!r} has no state that requires monitoring, "
                        f"so fault {event!r} can never be raised",
                        "mark the watched state 'monitoring required'",
                    )
                )
                continue
        if device and event and ("when" not in f or when is not None):
            out.append(EnvInput(kind, device, event, when, at))
    return out


def _named(
    r: _Reader,
    node: yaml.Node | None,
    what: str,
    keys: tuple[str, ...],
    required: tuple[str, ...],
    seen: set[str],
) -> list[tuple[str, dict[str, yaml.Node], Location]]:
    """Entries with a ``name`` unique among all properties (invariants and recovery)."""
    out: list[tuple[str, dict[str, yaml.Node], Location]] = []
    for i, item in enumerate(r.items(node, what)):
        f = r.mapping(item, what, keys, required)
        if f is None:
            continue
        name = r.text(f.get("name"), f"{what} name") or f"{what}-{i + 1}"
        if name in seen:
            r.diags.append(
                _d(
                    "V814",
                    r.at(item),
                    f"two properties are named {name!r}",
                    "give each invariant and recovery goal a distinct name",
                )
            )
        seen.add(name)
        out.append((name, f, r.at(item)))
    return out
