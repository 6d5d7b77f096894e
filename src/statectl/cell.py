"""Cells: several devices and the rules by which they interact.

A device table describes one device alone; the paper names interaction between
devices as its open problem. A cell file composes devices with explicit rules.

Rules:
1. ``devices`` maps an instance name to a device file (path relative to the cell
   file); the same file may appear under several names. Instance names are
   identifiers without dots, because expressions say ``In('arm.Moving')``.
2. A link reads ``when <from> enters <state> | raises <event> [guard]: send
   <event> to <to>``. ``raises E`` fires when the source device takes a
   transition on ``E``. The guard is a global expression (rule 4).
3. ``environment`` lists what the outside world may do: ``send: E, to: D``
   (a command from the operator or a sensor; optional ``when``), and ``fault: E,
   to: D`` (hardware may raise it whenever ``D`` is in a state that requires
   monitoring). Completion events are reported by each device itself whenever
   its state has a transition for them, unless ``completions: off``.
4. Invariants, recovery goals, link guards and ``when`` conditions are global
   expressions: the safe expression language restricted to ``In('device.State')``,
   ``and``, ``or``, ``not``, ``True`` and ``False``, so every host (the explorer,
   SPIN) reads them the same way.
5. Loading never stops at the first problem: every one is a ``V8xx`` diagnostic
   with the cell file's line; a device file's own diagnostics are passed on.
"""

from __future__ import annotations

import ast
import enum
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import yaml

from statectl.build import load_and_build
from statectl.codes import family
from statectl.errors import Diagnostic, DiagnosticError, Location, Severity, has_errors
from statectl.expr import compile_expression
from statectl.model import Chart, ControlKind, EventKind
from statectl.tables.safeyaml import YamlRefused, compose

__all__ = [
    "CODES",
    "Cell",
    "DeviceRef",
    "EnvInput",
    "GlobalExpr",
    "InputKind",
    "Invariant",
    "Link",
    "Recovery",
    "Trigger",
    "load_cell",
    "load_cell_or_raise",
    "parse_global",
]

#: Code -> one-line summary of every V8xx code (a view of statectl.codes.REGISTRY).
CODES: Mapping[str, str] = family("V8")

TOP_KEYS = ("cell", "devices", "links", "environment", "invariants", "recovery", "completions")


class Trigger(enum.Enum):
    ENTERS = "enters"  # the source device entered a state
    RAISES = "raises"  # the source device took a transition on an event


class InputKind(enum.Enum):
    COMMAND = "environment"  # the operator or a sensor sends it
    FAULT = "fault"  # hardware raises it in a monitored state
    COMPLETION = "completion"  # the device reports it back itself


@dataclass(frozen=True, slots=True)
class GlobalExpr:
    """A checked global expression and the ``(device, state)`` pairs it reads."""

    source: str
    refs: tuple[tuple[str, str], ...]
    where: Location


@dataclass(frozen=True, slots=True)
class DeviceRef:
    name: str
    path: str
    chart: Chart
    where: Location


@dataclass(frozen=True, slots=True)
class Link:
    """``when source <trigger> what [guard]: send event to target``."""

    source: str
    trigger: Trigger
    what: str
    target: str
    event: str
    guard: GlobalExpr | None
    where: Location

    @property
    def label(self) -> str:
        text = f"{self.source} {self.trigger.value} {self.what} -> {self.target}.{self.event}"
        if self.guard is not None:
            text += f" [{self.guard.source}]"
        return text


@dataclass(frozen=True, slots=True)
class EnvInput:
    kind: InputKind
    device: str
    event: str
    when: GlobalExpr | None
    where: Location


@dataclass(frozen=True, slots=True)
class Invariant:
    name: str
    expr: GlobalExpr


@dataclass(frozen=True, slots=True)
class Recovery:
    """From every reachable state where ``source`` holds, some path must reach ``target``."""

    name: str
    target: GlobalExpr
    source: GlobalExpr | None


@dataclass(frozen=True, slots=True)
class Cell:
    name: str
    path: str
    devices: tuple[DeviceRef, ...]
    links: tuple[Link, ...] = ()
    environment: tuple[EnvInput, ...] = ()
    invariants: tuple[Invariant, ...] = ()
    recovery: tuple[Recovery, ...] = ()
    completions: bool = True

    def device(self, name: str) -> DeviceRef:
        for d in self.devices:
            if d.name == name:
                return d
        raise KeyError(name)


def _d(code: str, where: Location, message: str, hint: str = "") -> Diagnostic:
    return Diagnostic(code, Severity.ERROR, where, message, hint)


def parse_global(
    source: str, where: Location, charts: Mapping[str, Chart], *, what: str = "expression"
) -> tuple[GlobalExpr | None, list[Diagnostic]]:
    """Check a global expression (rule 4) against the cell's devices and their states."""
    try:
        expr, diags = compile_expression(source, where, what=what)
    except (RecursionError, MemoryError):
        shown = source if len(source) <= 40 else source[:37] + "..."
        message = f"{what} {shown!r} is nested too deeply to analyse"
        return None, [_d("V810", where, message, "write it with fewer nested parts")]
    if expr is None:
        return None, diags
    tree = ast.parse(source.strip(), mode="eval")
    refs: list[tuple[str, str]] = []
    allowed = (ast.Expression, ast.BoolOp, ast.And, ast.Or, ast.UnaryOp, ast.Not, ast.Load)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            arg = node.args[0] if len(node.args) == 1 else None
            ok = isinstance(arg, ast.Constant) and isinstance(arg.value, str)
            if not (isinstance(node.func, ast.Name) and node.func.id == "In") or not ok:
                diags.append(
                    _d(
                        "V811",
                        where,
                        f"{what} {source!r}: {ast.unparse(node)} is not In('device.State')",
                        "write In('arm.Moving'): one text argument naming device and state",
                    )
                )
                continue
            assert isinstance(arg, ast.Constant)
            device, dot, state = str(arg.value).partition(".")
            chart = charts.get(device)
            if not dot or chart is None:
                diags.append(
                    _d(
                        "V807",
                        where,
                        f"{what} {source!r}: In({arg.value!r}) names no device of the cell",
                        "devices: " + ", ".join(sorted(charts)),
                    )
                )
            elif not chart.has_state(state):
                diags.append(
                    _d(
                        "V808",
                        where,
                        f"{what} {source!r}: device {device!r} has no state {state!r}",
                        "states: " + ", ".join(s.name for s in chart.states),
                    )
                )
            else:
                refs.append((device, state))
        elif isinstance(node, ast.Name):
            if node.id != "In":
                diags.append(
                    _d(
                        "V810",
                        where,
                        f"{what} {source!r} reads {node.id!r}; the cell tracks only states",
                        "use In('device.State'), and, or, not, True, False",
                    )
                )
        elif isinstance(node, ast.Constant):
            if not isinstance(node.value, (bool, str)):
                diags.append(
                    _d(
                        "V810",
                        where,
                        f"{what} {source!r} uses the constant {node.value!r}",
                        "use True or False",
                    )
                )
        elif not isinstance(node, allowed):
            diags.append(
                _d(
                    "V810",
                    where,
                    f"{what} {source!r} uses {type(node).__name__}, which a global "
                    "expression does not allow",
                    "use In('device.State'), and, or, not, True, False",
                )
            )
    if diags:
        return None, diags
    return GlobalExpr(source.strip(), tuple(dict.fromkeys(refs)), where), diags


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
    entries: dict[str, yaml.Node] = {}
    for k, v in node.value:
        key = str(k.value) if isinstance(k, yaml.ScalarNode) else ""
        if key in entries:
            r.diags.append(_d("V806", r.at(k), f"device name {key!r} is used twice"))
        entries[key] = v
    if not entries:
        r.diags.append(_d("V815", r.at(node), "the cell has no devices"))
    loaded: dict[Path, tuple[Chart | None, list[Diagnostic]]] = {}
    out: list[DeviceRef] = []
    for name, value in entries.items():
        where = r.at(value)
        if not name.isidentifier():
            r.diags.append(
                _d(
                    "V806",
                    where,
                    f"device name {name!r} is not an identifier",
                    "use letters, digits and '_' (no dots): In('arm.Moving') splits at the dot",
                )
            )
            continue
        if isinstance(value, yaml.MappingNode):
            fields = r.mapping(value, f"device {name!r}", ("file",), ("file",))
            file = r.text(fields.get("file"), f"device {name!r} file") if fields else None
        else:
            file = r.text(value, f"device {name!r}")
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
    keys = ("from", "enters", "raises", "to", "send", "guard")
    for item in r.items(node, "links"):
        f = r.mapping(item, "link", keys, ("from", "to", "send"))
        if f is None:
            continue
        at = r.at(item)
        source = _device(r, f.get("from"), "link from", charts)
        target = _device(r, f.get("to"), "link to", charts)
        event = _event(r, f.get("send"), "link send", target, charts)
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
                        "states: " + ", ".join(s.name for s in chart.states),
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
            out.append(Link(source, trigger, what, target, event, guard, at))
    return out


def _environment(r: _Reader, node: yaml.Node | None, charts: Mapping[str, Chart]) -> list[EnvInput]:
    out: list[EnvInput] = []
    for item in r.items(node, "environment"):
        f = r.mapping(item, "environment entry", ("send", "fault", "to", "when"), ("to",))
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


def load_cell(path: str | os.PathLike[str]) -> tuple[Cell | None, list[Diagnostic]]:
    """Load a cell file and its devices; ``None`` and every diagnostic if any is an error."""
    file = str(path)
    top = Location(file, 1)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        return None, [_d("V801", top, f"cannot read the cell file: {exc.strerror or exc}")]
    except UnicodeDecodeError as exc:
        return None, [
            _d(
                "V801",
                top,
                f"the cell file is not UTF-8 text (byte {exc.start})",
                "save the file as UTF-8",
            )
        ]
    try:
        root = compose(text)
    except YamlRefused as exc:
        code = "V801" if exc.code == "T101" else exc.code
        where = Location(file, exc.line or 1)
        return None, [Diagnostic(code, Severity.ERROR, where, exc.message, exc.hint)]
    if not isinstance(root, yaml.MappingNode):
        return None, [
            _d(
                "V801",
                top,
                "not a cell file: the top level is not a mapping",
                "a cell file has cell:, devices:, links:, environment:, invariants:",
            )
        ]
    r = _Reader(file)
    f = r.mapping(root, "cell file", TOP_KEYS, ("devices",)) or {}
    name = r.text(f.get("cell"), "cell") or Path(file).stem.removesuffix(".cell")
    devices = _load_devices(r, f.get("devices"), Path(file).parent, top) if "devices" in f else []
    charts = {d.name: d.chart for d in devices}
    completions = True
    if "completions" in f:
        value = r.text(f["completions"], "completions")
        if value not in ("auto", "off", None):
            r.diags.append(_d("V804", r.at(f["completions"]), "completions must be auto or off"))
        completions = value != "off"
    links = _links(r, f.get("links"), charts)
    environment = _environment(r, f.get("environment"), charts)
    invariants: list[Invariant] = []
    names: set[str] = set()
    for inv_name, fields, _ in _named(
        r, f.get("invariants"), "invariant", ("name", "holds"), ("holds",), names
    ):
        expr = _expr(r, fields.get("holds"), f"invariant {inv_name!r}", charts)
        if expr is not None:
            invariants.append(Invariant(inv_name, expr))
    recovery: list[Recovery] = []
    for rec_name, fields, _ in _named(
        r, f.get("recovery"), "recovery", ("name", "to", "from"), ("to",), names
    ):
        target = _expr(r, fields.get("to"), f"recovery {rec_name!r} to", charts)
        source = _expr(r, fields.get("from"), f"recovery {rec_name!r} from", charts)
        if target is not None and ("from" not in fields or source is not None):
            recovery.append(Recovery(rec_name, target, source))
    if has_errors(r.diags):
        return None, r.diags
    cell = Cell(
        name,
        file,
        tuple(devices),
        tuple(links),
        tuple(environment),
        tuple(invariants),
        tuple(recovery),
        completions,
    )
    return cell, r.diags


def load_cell_or_raise(path: str | os.PathLike[str]) -> Cell:
    """The cell of ``path``; raises :class:`DiagnosticError` carrying every problem."""
    cell, diags = load_cell(path)
    if cell is None:
        raise DiagnosticError(diags)
    return cell
