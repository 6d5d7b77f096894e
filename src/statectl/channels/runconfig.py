"""A run config file, every section read by the package that uses it: ``statectl run --config``.

Rules:
1. A run config is a YAML mapping of five sections, each optional but one at least::

       devices:  {Motor: {driver: sim-motor, options: {speed: 10}}}   # run/devices/config.py
       dashboard: {port: 8765, token: ...}                            # channels/web/config.py
       opcua:    {endpoint: opc.tcp://127.0.0.1:4840}                 # channels/opcua/config.py
       ship:     {to: postgresql://statectl@db.plant/cell}            # run/journal/ship_config.py
       commands: [{from: dashboard, send: [Movement]}]                # run/commands.py

   Each section's owner parses it and reports its own codes (D504-D509, D511 and D512
   the drivers, D510 the dashboard, D520 OPC UA, D530 shipping, D540 commands); this module reads
   the file (D501 unreadable, D502 not YAML), finds the sections (D503 none or not a
   mapping, D507 an unknown key) and raises one
   :class:`~statectl.kernel.errors.DiagnosticError` carrying every problem.
2. Why here, in the channels: two of the sections configure channels (the dashboard,
   OPC UA) and the run layer must not import them; the System itself takes only what
   the file says (drivers, a :class:`~statectl.run.commands.Commands`), never the file.
   The command line, the language server and the JSON Schema (out/schema.py) read
   run configs through this module.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from statectl.channels.opcua.config import OpcuaConfig, parse_opcua
from statectl.channels.web.config import DashboardConfig, parse_dashboard
from statectl.front.tables import safeyaml
from statectl.front.tables.inputs import read_input_text
from statectl.kernel.errors import Diagnostic, DiagnosticError, Location, Severity
from statectl.run.commands import Commands, parse_commands
from statectl.run.devices.config import DriverConfig, SectionError, parse_devices
from statectl.run.journal.ship_config import ShipConfig, parse_ship

__all__ = ["RUN_CONFIG_KEYS", "RunConfig", "load_driver_config", "load_run_config", "run_config"]

#: The sections of a run config (the JSON Schema, out/schema.py, reads them).
RUN_CONFIG_KEYS = ("devices", "dashboard", "opcua", "ship", "commands")


@dataclass(frozen=True, slots=True)
class RunConfig:
    """A run's configuration file: drivers per device (None: no ``devices`` section)."""

    drivers: DriverConfig | None
    dashboard: DashboardConfig
    #: the ``opcua:`` section (channels/opcua/config.py)
    opcua: OpcuaConfig = field(default_factory=OpcuaConfig)
    #: the ``ship:`` section: the run's journal shipped to PostgreSQL (run/journal/ship_config.py)
    ship: ShipConfig | None = None
    #: the ``commands:`` section: who may command which device (run/commands.py)
    commands: Commands = field(default_factory=Commands)


def run_config(path: str | Path | None) -> RunConfig:
    """The run config ``--config`` names; without one, the empty config (no sections)."""
    return RunConfig(None, DashboardConfig()) if path is None else load_run_config(path)


def load_driver_config(path: str | Path) -> DriverConfig:
    """Read a driver config file; every problem becomes a D5xx diagnostic."""
    config = load_run_config(path)
    if config.drivers is None:
        diag = Diagnostic(
            "D503",
            Severity.ERROR,
            Location(str(path), 1),
            "no 'devices' mapping",
            "add 'devices:' with one entry per device",
        )
        raise DiagnosticError([diag])
    return config.drivers


def load_run_config(path: str | Path, text: str | None = None) -> RunConfig:
    """Read a run's config file (drivers, dashboard); every problem becomes a D5xx diagnostic.

    ``text`` is the file's content when the caller holds it (an editor's buffer).
    """
    file = str(path)
    diags: list[Diagnostic] = []

    def error(code: str, line: int | None, message: str, hint: str = "") -> None:
        diags.append(Diagnostic(code, Severity.ERROR, Location(file, line), message, hint))

    try:
        text = read_input_text(path) if text is None else text
    except (OSError, UnicodeDecodeError) as exc:
        error("D501", None, f"cannot read driver config ({exc})", "check the path")
        raise DiagnosticError(diags) from None
    try:  # no aliases, bounded depth: a config file may come from elsewhere too
        root = safeyaml.compose(text)
    except safeyaml.YamlRefused as exc:
        error("D502", exc.line, f"not valid YAML here ({exc.message})", exc.hint)
        raise DiagnosticError(diags) from None

    def line_of(node: yaml.Node) -> int:
        return int(node.start_mark.line) + 1

    def value(node: yaml.Node) -> Any:
        return safeyaml.construct(node)

    found = _sections(root, value, line_of, error)
    devices_node, dashboard_node = found.get("devices"), found.get("dashboard")
    opcua_node, ship_node, commands_node = (
        found.get("opcua"),
        found.get("ship"),
        found.get("commands"),
    )
    result = parse_devices(devices_node, value, line_of, error)
    dashboard = DashboardConfig()
    if dashboard_node is not None:
        dashboard = parse_dashboard(dashboard_node, value, line_of, error)
    opcua = OpcuaConfig() if opcua_node is None else parse_opcua(opcua_node, value, line_of, error)
    ship = None if ship_node is None else parse_ship(ship_node, value, line_of, error)
    commands = (
        Commands()
        if commands_node is None
        else parse_commands(commands_node, value, line_of, error, file)
    )
    if diags:
        raise DiagnosticError(diags)
    return RunConfig(result if devices_node is not None else None, dashboard, opcua, ship, commands)


def _sections(
    root: yaml.Node | None,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: SectionError,
) -> dict[str, yaml.Node]:
    """The file's sections by key (D503 if none or not a mapping, D507 for others)."""
    found: dict[str, yaml.Node] = {}
    if not isinstance(root, yaml.MappingNode):
        error(
            "D503",
            line_of(root) if root is not None else 1,
            "a driver config must be a mapping with a 'devices' key",
            "write 'devices: {Motor: {driver: sim-motor}}'",
        )
    else:
        for key, val in root.value:
            if value(key) in RUN_CONFIG_KEYS:
                found[value(key)] = val
            else:
                error(
                    "D507",
                    line_of(key),
                    f"unknown key {value(key)!r}",
                    "a run config has 'devices', 'dashboard', 'opcua', 'ship' and 'commands'",
                )
        if not found:
            error(
                "D503",
                line_of(root),
                "no 'devices' mapping",
                "add 'devices:' with one entry per device",
            )
        elif "devices" in found and not isinstance(found["devices"], yaml.MappingNode):
            error("D503", line_of(found["devices"]), "'devices' must map device names to entries")
            del found["devices"]
    return found
