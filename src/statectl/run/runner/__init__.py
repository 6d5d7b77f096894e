"""What runs a device or a cell, under the CLI: event lines, cell files and their setups.

The ``statectl run`` and ``statectl journal`` commands themselves (what they
print, their exit codes) are :mod:`statectl.channels.cli.run` and
:mod:`statectl.channels.cli.journal`;
the devices run on a :class:`~statectl.run.system.System`. Two modules:
:mod:`.events` (the event-line grammar) and :mod:`.cells` (cell files and the
setups of their devices).
"""

from __future__ import annotations

from statectl.front.kinds import is_cell
from statectl.run.runner.cells import cell_setups, load_setups, relevant_warnings
from statectl.run.runner.events import parse_event_line, parse_time
from statectl.run.system import DeviceSetup, System

__all__ = [
    "DeviceSetup",
    "System",
    "cell_setups",
    "is_cell",
    "load_setups",
    "parse_event_line",
    "parse_time",
    "relevant_warnings",
]
