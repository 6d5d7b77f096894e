"""The optional extras a command line needs, checked before anything starts.

Rules:
1. A command that needs an extra which is not installed says which one, in one line
   (:class:`~statectl.kernel.errors.MissingExtra`), and exits 2 before it opens a file,
   a port or a bus: nothing half-started.
2. What needs what is read off the parsed arguments here, in one table, so every
   command says it the same way; the modules that import an extra at run time raise
   the same :class:`MissingExtra` should they be reached some other way (the API).
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator

from statectl.kernel.errors import require

__all__ = ["check_extras", "needed"]

#: Per extra of pyproject.toml, the modules it installs that statectl imports.
MODULES: dict[str, tuple[str, ...]] = {
    "canopen": ("canopen", "can"),
    "modbus": ("pymodbus",),
    "zenoh": ("zenoh",),
    "postgres": ("psycopg",),
    "opcua": ("asyncua",),
    "dashboard": ("aiohttp",),
    "lsp": ("pygls",),
    "test": ("hypothesis",),
}


def needed(args: argparse.Namespace) -> Iterator[tuple[str, str]]:
    """``(what needs it, extra)`` for every extra the parsed command line uses."""
    command = getattr(args, "command", None)
    driver = getattr(args, "driver", None)
    if driver is not None:
        from statectl.run.devices.config import BUS_LIBRARIES

        if driver in BUS_LIBRARIES:
            yield f"--driver {driver}", BUS_LIBRARIES[driver][1]
    if command in ("node", "dashboard"):
        yield "a node" if command == "node" else "the cell's dashboard", "zenoh"
    if command == "dashboard" or getattr(args, "dashboard", False) is True:
        yield "the dashboard", "dashboard"
    if command == "run" and args.opcua is not None:
        yield "--opcua", "opcua"
    if command == "journal":
        sub = args.journal_command
        if sub == "ship" or str(getattr(args, "db", "")).startswith("postgresql://"):
            yield "PostgreSQL", "postgres"
    if command == "lsp":
        yield "the language server", "lsp"
    if command == "testgen" and getattr(args, "hypothesis", False):
        yield "--hypothesis (and the module it writes)", "test"


def check_extras(args: argparse.Namespace) -> None:
    """Rule 1: raise MissingExtra for the first extra the command line needs and lacks."""
    for what, extra in needed(args):
        for module in MODULES[extra]:
            require(module, extra, what)
