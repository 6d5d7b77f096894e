"""Declared recovery transitions: what a device does when it resumes in a state it cannot trust.

A device that was Moving when the power went away is not Moving any more; its
chart says Moving, its motor says nothing. The device file names, per state,
the transition to take before anything else on ``--resume``::

    recovery:
      - state: Moving
        event: Error
        data: {detail: resumed after a restart}

Rules:
1. The ``recovery:`` section sits in the device's YAML file, or, for CSV, XLSX
   and Markdown tables, in a sidecar ``NAME.recovery.yaml`` beside them. It is a
   list of mappings with ``state``, ``event`` and optional ``data``.
2. On resume, after the journalled snapshot is restored, each rule whose state is
   active posts its event first, in the section's order; the step is journalled
   as kind ``recovery``. A state without a rule resumes as it was.
3. Every problem is a diagnostic (J601-J606) with the file and line: the event
   must leave the state by a transition of the chart, a state has one rule.
   A monitored state without a rule is a warning: it is the typical state that
   cannot be trusted after a crash.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from statectl.build import build
from statectl.errors import Diagnostic, DiagnosticError, Location, Severity, has_errors
from statectl.model import Chart, ControlKind
from statectl.tables import load as load_tables
from statectl.tables.yaml_io import read_yaml

__all__ = [
    "CODES",
    "DeviceFile",
    "RecoveryRule",
    "check_recovery",
    "load_device",
    "load_recovery",
    "recovery_file",
]

CODES = {
    "J601": "the recovery section cannot be read or is not a list of mappings",
    "J602": "a rule lacks 'state' or 'event', or has an unknown key",
    "J603": "a rule names a state the chart does not have",
    "J604": "a rule's event does not leave its state by any transition",
    "J605": "two rules for one state",
    "J606": "a monitored state has no recovery rule (warning)",
}

_KEYS = ("state", "event", "data")
_NOWHERE = Location()


@dataclass(frozen=True, slots=True)
class RecoveryRule:
    """On resume in ``state``, post ``event`` with ``data`` before any other event."""

    state: str
    event: str
    data: Any = None
    origin: Location = _NOWHERE


def recovery_file(device_file: str | Path) -> Path | None:
    """Where the recovery section of ``device_file`` is: the file itself or its sidecar."""
    p = Path(device_file)
    if p.suffix.lower() in (".yaml", ".yml") and _has_section(p):
        return p
    sidecar = p.with_name(p.name.split(".")[0] + ".recovery.yaml")
    return sidecar if sidecar.exists() else None


def _has_section(p: Path) -> bool:
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    return isinstance(data, dict) and "recovery" in data


def load_recovery(path: str | Path) -> tuple[tuple[RecoveryRule, ...], list[Diagnostic]]:
    """The rules of the ``recovery:`` section in ``path``; problems as diagnostics."""
    file = str(path)
    diags: list[Diagnostic] = []

    def error(code: str, line: int | None, message: str, hint: str = "") -> None:
        diags.append(Diagnostic(code, Severity.ERROR, Location(file, line), message, hint))

    try:
        root = yaml.compose(Path(path).read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
    except (OSError, UnicodeDecodeError) as exc:
        error("J601", None, f"cannot read the recovery section ({exc})", "check the path")
        return (), diags
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        error("J601", mark.line + 1 if mark else None, f"not valid YAML ({exc})")
        return (), diags
    section: yaml.Node | None = None
    if isinstance(root, yaml.MappingNode):
        for key, value in root.value:
            if key.value == "recovery":
                section = value
    if section is None:
        return (), diags
    if isinstance(section, yaml.ScalarNode) and section.value in ("", "null", "~"):
        return (), diags
    if not isinstance(section, yaml.SequenceNode):
        error(
            "J601",
            section.start_mark.line + 1,
            "'recovery' must be a list of rules",
            "write '- {state: Moving, event: Error}'",
        )
        return (), diags
    rules: list[RecoveryRule] = []
    for item in section.value:
        line = item.start_mark.line + 1
        if not isinstance(item, yaml.MappingNode):
            error("J601", line, "a recovery rule must be a mapping", "write '{state: S, event: E}'")
            continue
        fields: dict[str, Any] = {}
        for k, v in item.value:
            name = str(k.value)
            if name not in _KEYS:
                error(
                    "J602",
                    k.start_mark.line + 1,
                    f"unknown key {name!r} in a recovery rule",
                    "a rule has state, event and optional data",
                )
                continue
            fields[name] = yaml.SafeLoader("").construct_object(v, deep=True)
        state, event = fields.get("state"), fields.get("event")
        if not isinstance(state, str) or not isinstance(event, str) or not state or not event:
            error("J602", line, f"a recovery rule needs text 'state' and 'event' (got {fields!r})")
            continue
        data = fields.get("data")
        try:
            json.dumps(data)
        except (TypeError, ValueError):
            error("J602", line, f"recovery data must be plain values (got {data!r})")
            continue
        rules.append(RecoveryRule(state, event, data, Location(file, line)))
    return tuple(rules), diags


def check_recovery(chart: Chart, rules: tuple[RecoveryRule, ...]) -> list[Diagnostic]:
    """Problems of ``rules`` against ``chart``: J603-J606."""
    diags: list[Diagnostic] = []
    names = [s.name for s in chart.states]
    seen: dict[str, RecoveryRule] = {}
    for r in rules:
        if r.state not in names:
            diags.append(
                Diagnostic(
                    "J603",
                    Severity.ERROR,
                    r.origin,
                    f"recovery rule for unknown state {r.state!r}",
                    f"states: {', '.join(names)}",
                )
            )
            continue
        if r.state in seen:
            diags.append(
                Diagnostic(
                    "J605",
                    Severity.ERROR,
                    r.origin,
                    f"a second recovery rule for {r.state!r}",
                    f"the first is at {seen[r.state].origin}",
                )
            )
            continue
        seen[r.state] = r
        leaving = [t for t in chart.transitions if t.source == r.state and r.event in t.events]
        if not leaving:
            here = sorted({e for t in chart.transitions_from(r.state) for e in t.events})
            diags.append(
                Diagnostic(
                    "J604",
                    Severity.ERROR,
                    r.origin,
                    f"event {r.event!r} does not leave {r.state!r}",
                    f"events leaving {r.state!r}: {', '.join(here) or 'none'}",
                )
            )
    for s in chart.states:
        if ControlKind.MONITORING in s.controls and s.name not in seen:
            diags.append(
                Diagnostic(
                    "J606",
                    Severity.WARNING,
                    s.origin,
                    f"monitored state {s.name!r} has no recovery rule; after a "
                    "crash it resumes as if nothing happened",
                    f"add '- {{state: {s.name}, event: <fault event>}}' under recovery:",
                )
            )
    return diags


@dataclass(frozen=True, slots=True)
class DeviceFile:
    """A device file loaded for running: its chart and its recovery rules."""

    chart: Chart
    rules: tuple[RecoveryRule, ...]
    warnings: tuple[Diagnostic, ...]


def load_device(path: str | Path) -> DeviceFile:
    """Load a device file's chart and recovery rules; raise one DiagnosticError for all errors.

    A ``recovery:`` section is read here and blanked out (line for line, so every
    line number stays right) before the table loader sees the file.
    """
    diags: list[Diagnostic] = []
    text = _without_recovery(Path(path))
    if text is None:
        tables, found = load_tables(path)
    else:
        tables, found = read_yaml(text, str(path))
    diags.extend(found)
    chart = None
    if tables is not None and not has_errors(diags):
        chart, more = build(tables)
        diags.extend(more)
    rules: tuple[RecoveryRule, ...] = ()
    where = recovery_file(path)
    if where is not None:
        rules, more = load_recovery(where)
        diags.extend(more)
    if chart is not None:
        diags.extend(check_recovery(chart, rules))
    if chart is None or has_errors(diags):
        raise DiagnosticError(diags)
    return DeviceFile(chart, rules, tuple(diags))


def _without_recovery(p: Path) -> str | None:
    """The YAML device file's text with its recovery section blanked; None if it has none."""
    if p.suffix.lower() not in (".yaml", ".yml"):
        return None
    try:
        text = p.read_text(encoding="utf-8")
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    if not isinstance(root, yaml.MappingNode):
        return None
    lines = text.splitlines(keepends=True)
    found = False
    for key, value in root.value:
        if key.value == "recovery" and key.start_mark.column == 0:
            first, last = key.start_mark.line, value.end_mark.line
            if value.end_mark.column == 0:
                last -= 1
            for i in range(first, min(last, len(lines) - 1) + 1):
                lines[i] = "\n"
            found = True
    return "".join(lines) if found else None
