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
6. A link may carry event data (``send: "Reset {status: true}"``, ``data:``,
   ``forward_data: true``) and say ``ignore_if_unhandled``, ``lossy`` or
   ``delayed``; an invariant may name ``on_violation`` events; a device row's guard
   may read ``In('other.State')`` of another device, checked here against the
   cell's devices (:mod:`~statectl.cell.options`, V830, V831).

This module parses the file and puts the sections together (:func:`load_cell`); the
values are in :mod:`statectl.cell.values`, global expressions in
:mod:`~statectl.cell.expressions` and the sections' reading in
:mod:`~statectl.cell.reader`. Every public name is importable from ``statectl.cell.model`` as
before the split.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import yaml

from statectl.cell.expressions import _d, parse_global
from statectl.cell.nodes import read_nodes
from statectl.cell.options import check_cross_refs, violation_events
from statectl.cell.reader import (
    INVARIANT_FIELDS,
    RECOVERY_FIELDS,
    _environment,
    _expr,
    _links,
    _load_devices,
    _named,
    _Reader,
)
from statectl.cell.security import read_security
from statectl.cell.values import (
    CODES,
    TOP_KEYS,
    Cell,
    DeviceRef,
    EnvInput,
    GlobalExpr,
    InputKind,
    Invariant,
    Link,
    RecoveryGoal,
    Trigger,
)
from statectl.front.tables.inputs import read_input_text
from statectl.front.tables.safeyaml import YamlRefused, compose
from statectl.kernel.errors import Diagnostic, DiagnosticError, Location, Severity, has_errors
from statectl.kernel.model import Chart

__all__ = [
    "CODES",
    "Cell",
    "DeviceRef",
    "EnvInput",
    "GlobalExpr",
    "InputKind",
    "Invariant",
    "Link",
    "RecoveryGoal",
    "Trigger",
    "load_cell",
    "load_cell_or_raise",
    "parse_global",
]


def load_cell(
    path: str | os.PathLike[str], text: str | None = None
) -> tuple[Cell | None, list[Diagnostic]]:
    """Load a cell file and its devices; ``None`` and every diagnostic if any is an error.

    ``text`` is the file's content when the caller holds it (an editor's buffer,
    statectl.channels.lsp); the devices are read from their files either way.
    """
    file = str(path)
    top = Location(file, 1)
    root = _root(path, text, file)
    if isinstance(root, list):
        return None, root
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
    nodes = read_nodes(r, f.get("nodes"), f.get("links"), charts)  # cell/nodes.py
    security = read_security(r, f.get("security"), nodes, Path(file).parent, list(charts))
    if nodes is not None:
        nodes = replace(nodes, security=security)
    environment = _environment(r, f.get("environment"), charts)
    names: set[str] = set()  # invariants and recovery rules share one namespace
    invariants = _invariants(r, f.get("invariants"), charts, names)
    recovery = _recoveries(r, f.get("recovery"), charts, names)
    r.diags.extend(check_cross_refs(charts, file))
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
        nodes,
    )
    return cell, r.diags


def _root(
    path: str | os.PathLike[str], text: str | None, file: str
) -> yaml.MappingNode | list[Diagnostic]:
    """The cell file's top mapping, or why there is none (V801, the YAML refusals)."""
    top = Location(file, 1)
    try:
        text = read_input_text(path) if text is None else text
    except OSError as exc:
        return [_d("V801", top, f"cannot read the cell file: {exc.strerror or exc}")]
    except UnicodeDecodeError as exc:
        return [
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
        return [Diagnostic(code, Severity.ERROR, where, exc.message, exc.hint)]
    if not isinstance(root, yaml.MappingNode):
        return [
            _d(
                "V801",
                top,
                "not a cell file: the top level is not a mapping",
                "a cell file has cell:, devices:, links:, environment:, invariants:",
            )
        ]
    return root


def _invariants(
    r: _Reader, node: yaml.Node | None, charts: Mapping[str, Chart], names: set[str]
) -> list[Invariant]:
    """The invariants: section, each a checked global expression and what it raises."""
    invariants: list[Invariant] = []
    for inv_name, fields, _ in _named(r, node, "invariant", INVARIANT_FIELDS, ("holds",), names):
        expr = _expr(r, fields.get("holds"), f"invariant {inv_name!r}", charts)
        react, problems = violation_events(fields.get("on_violation"), r.file, charts)
        r.diags.extend(problems)
        if expr is not None:
            invariants.append(Invariant(inv_name, expr, react))
    return invariants


def _recoveries(
    r: _Reader, node: yaml.Node | None, charts: Mapping[str, Chart], names: set[str]
) -> list[RecoveryGoal]:
    """The recovery: section; a rule whose to (or given from) does not parse is dropped."""
    recovery: list[RecoveryGoal] = []
    for rec_name, fields, _ in _named(r, node, "recovery", RECOVERY_FIELDS, ("to",), names):
        target = _expr(r, fields.get("to"), f"recovery {rec_name!r} to", charts)
        source = _expr(r, fields.get("from"), f"recovery {rec_name!r} from", charts)
        if target is not None and ("from" not in fields or source is not None):
            recovery.append(RecoveryGoal(rec_name, target, source))
    return recovery


def load_cell_or_raise(path: str | os.PathLike[str]) -> Cell:
    """The cell of ``path``; raises :class:`DiagnosticError` carrying every problem."""
    cell, diags = load_cell(path)
    if cell is None:
        raise DiagnosticError(diags)
    return cell
