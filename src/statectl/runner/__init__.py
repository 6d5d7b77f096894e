"""``statectl run DEVICE`` for real, and ``statectl journal show|replay|export``.

A package of three seams: :mod:`.command` (the run), :mod:`.journal_commands`
(reading a journal back) and :mod:`.events` (the event-line grammar); this
module only gathers their public names under the path callers have used.

Rules:
1. A run is a :class:`~statectl.system.System` (devices on one clock and one
   owner; journalled, a cell; see :mod:`statectl.system` for its own rules).
2. An existing journal is checked before the run uses it (journal/check.py): one
   that cannot be trusted is refused and nothing starts, unless ``--fresh`` sets it
   aside (renamed with a timestamp) for a new one. A journal that stops taking
   writes (a full disk) stops the run with a message; nothing more is accepted.
3. Time: ``--realtime`` runs on a :class:`WallClock`; otherwise a
   :class:`SimClock`, which a live run (``--dashboard``) moves in step with the
   wall clock and a batch run (events from a file or stdin) moves only to let
   each event's consequences settle, so a batch run is deterministic.
4. A cell file runs the same way, its links sent by the System.
5. Events come as lines ``[DEVICE:] EVENT [DATA]`` (DATA in YAML flow style, e.g.
   ``Movement {amount: 10}``); ``+SECONDS`` lets simulated time pass; ``#``
   starts a comment. A bad line is reported with its number and skipped. A
   batch run reads them from stdin, and so does a live run without a dashboard.
6. Drivers: a ``--config`` file, else ``--driver`` for every device, else a
   :class:`~statectl.devices.SimTwin` with defaults for each device, derived
   from its tables (the banner says so), so every device reports its
   completions on the clock. A twin's notes appear in the trace as ``twin``.
7. The dashboard's host, port and token: the flags, else (the token) the
   ``STATECTL_DASHBOARD_TOKEN`` environment variable, else the config file's
   ``dashboard:`` section, else loopback, any free port and a new token, which
   is printed; a token from elsewhere is not echoed. A token shorter than 16
   characters is refused.
"""

from __future__ import annotations

from statectl.runner.command import TOKEN_VARIABLE, cell_setups, is_cell, run
from statectl.runner.events import parse_event_line, parse_time
from statectl.runner.journal_commands import journal_export, journal_replay, journal_show
from statectl.system import DeviceSetup, System

__all__ = [
    "TOKEN_VARIABLE",
    "DeviceSetup",
    "System",
    "cell_setups",
    "is_cell",
    "journal_export",
    "journal_replay",
    "journal_show",
    "parse_event_line",
    "parse_time",
    "run",
]
