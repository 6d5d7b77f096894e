"""What ``statectl run`` and ``statectl node`` set up before a System runs: the devices'
setups from the model or cell, their drivers (rule 6 of :mod:`statectl.channels.cli.run`),
where a driver module may be found (rule 11) and the dashboard's settings (rule 7).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TextIO

from statectl.cell.model import Cell, load_cell
from statectl.channels.runconfig import RunConfig
from statectl.channels.web.config import MIN_TOKEN, DashboardConfig
from statectl.kernel.errors import DiagnosticError, Severity, StatectlError
from statectl.run.devices import DeviceDriver, SimTwin, TwinNote, make_driver
from statectl.run.journal import load_device
from statectl.run.runner.cells import load_setups, relevant_warnings
from statectl.run.system import DeviceSetup

__all__ = [
    "NO_DRIVER",
    "TOKEN_VARIABLE",
    "dashboard_settings",
    "drivers_for",
    "load_cell_setups",
    "load_device_setups",
    "search_beside",
    "show_notes",
]


def drivers_for(
    devices: Sequence[DeviceSetup], driver: str | None, config: str | None, table: RunConfig
) -> dict[str, DeviceDriver]:
    """Rule 6: the config file's drivers, else ``driver`` for all, else a twin for each."""
    names = [d.name for d in devices]
    if table.drivers is not None:
        drivers = table.drivers
        missing = [n for n in names if n not in drivers]
        if missing:
            raise StatectlError(f"{config}: no driver for device(s) {missing}")
        return {d.name: make_driver(*drivers[d.name], chart=d.chart) for d in devices}
    if driver == NO_DRIVER:
        return {}  # rule 10: the model alone
    return {d.name: make_driver(driver or "sim-twin", chart=d.chart) for d in devices}


def search_beside(*files: str | None) -> None:
    """Rule 11: a driver module may sit beside the model or config file (searched last)."""
    for f in files:
        if f is not None:
            folder = str(Path(f).resolve().parent)
            if folder not in sys.path:
                sys.path.append(folder)


#: ``--driver none``: no driver at all, the model alone (rule 10).
NO_DRIVER = "none"

#: The environment variable that may hold the dashboard's token (rule 7).
TOKEN_VARIABLE = "STATECTL_DASHBOARD_TOKEN"


def dashboard_settings(
    host: str | None, port: int | None, token: str | None, config: str | None, dash: DashboardConfig
) -> tuple[str, int, str | None, str]:
    """Rule 7: flags, then the environment (token), then the config file, then the defaults.

    Returns host, port, token (None: the dashboard makes one) and where the token came from.
    """
    where = "--token"
    if token is None and os.environ.get(TOKEN_VARIABLE):
        token, where = os.environ[TOKEN_VARIABLE], TOKEN_VARIABLE
    if token is None and dash.token is not None:
        token, where = dash.token, str(config)
    if token is not None and len(token) < MIN_TOKEN:
        raise StatectlError(
            f"the dashboard token from {where} is shorter than {MIN_TOKEN} characters, "
            "so it could be guessed; make one with "
            "python -c 'import secrets; print(secrets.token_urlsafe(18))'"
        )
    host = host if host is not None else dash.host or "127.0.0.1"
    port = port if port is not None else dash.port or 0
    return host, port, token, where


def show_notes(drivers: Mapping[str, DeviceDriver], out: TextIO, width: int) -> None:
    """Rule 6: a twin's notes (what it did not report, and why) go into the trace."""

    def writer(name: str) -> Callable[[TwinNote], None]:
        def write(note: TwinNote) -> None:
            out.write(f"t={note.time:7.2f}  {name:<{width}}  {'twin':<8} {note}\n")

        return write

    for name, d in drivers.items():
        if isinstance(d, SimTwin):
            d.on_note = writer(name)


def load_cell_setups(
    path: str, err: TextIO, journalled: bool, node: str | None = None
) -> tuple[Cell, tuple[DeviceSetup, ...]]:
    """The cell and its setups; the warnings printed are those of ``node``'s own devices
    when one is named (``statectl node``: the others run on other nodes)."""
    cell, diags = load_cell(path)
    if cell is None:
        raise DiagnosticError([d for d in diags if d.severity is not Severity.INFO])
    only = None
    if node is not None and cell.nodes is not None:
        names = {n.name for n in cell.nodes.nodes}
        only = cell.nodes.node(node).devices if node in names else ()
    setups, warnings = load_setups(cell, journalled=journalled, only=only)
    for d in warnings:
        err.write(f"{d}\n")
    return cell, setups


def load_device_setups(path: str, err: TextIO, journalled: bool) -> tuple[DeviceSetup, ...]:
    device = load_device(path)
    for d in relevant_warnings(device.warnings, journalled):
        err.write(f"{d}\n")
    chart = device.chart
    return (DeviceSetup(chart.name, chart, device.rules, os.path.abspath(path)),)
