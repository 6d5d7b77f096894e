"""A device file loaded for a journalled run: its chart and its Recovery table's rules.

The Recovery table is checked in :mod:`statectl.front.recovery`; the rules are acted on
when a journalled device resumes, in :mod:`statectl.run.journal.device`. (A cell's
``recovery:`` goals are something else: properties verify checks, ``RecoveryGoal``.)

The Recovery table is the device file's third table (docs/tables.md): per state,
what a device does first when it resumes there, because a state such as Moving
cannot be trusted after the power went away, and a state such as Returning waits
for device work that nobody does any more::

    recovery:
      - state: Moving
        event: Error
        data: {detail: resumed after a restart}
      - state: Returning
        redo: yes

Rules:
1. The rows are read by the tables layer like the other two tables, in every
   format (shape problems are T1xx); :func:`statectl.front.recovery.check_recovery`
   judges them against the chart (J603-J605 and J607 errors).
2. A monitored state without a rule (J606) and a state left only by completion
   events without one (J608) are warnings here: with a journal there is
   something to recover from. ``statectl check`` shows them as info.
3. On resume, after the journalled snapshot is restored, each rule whose state is
   active acts first, in the table's order: an event rule posts its event, a
   redo rule issues the entering step's device calls again
   (:class:`~statectl.run.journal.device.JournalledDevice`); either is journalled
   as kind ``recovery``. A state without a rule resumes as it was.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from statectl.front.builder.build import build
from statectl.front.recovery import check_recovery
from statectl.front.tables import RecoveryRow
from statectl.front.tables import load as load_tables
from statectl.kernel.errors import Diagnostic, DiagnosticError, Severity, has_errors
from statectl.kernel.model import Chart

__all__ = ["DeviceFile", "RecoveryRule", "load_device"]

#: On resume in ``state``, post ``event`` with ``data`` (or redo) before any other event.
RecoveryRule = RecoveryRow


@dataclass(frozen=True, slots=True)
class DeviceFile:
    """A device file loaded for running: its chart and its recovery rules."""

    chart: Chart
    rules: tuple[RecoveryRule, ...]
    warnings: tuple[Diagnostic, ...]


def load_device(path: str | Path) -> DeviceFile:
    """Load a device file's chart and recovery rules; raise one DiagnosticError for all errors."""
    tables, diags = load_tables(path)
    chart = None
    if tables is not None:
        chart, more = build(tables)
        diags.extend(more)
    if tables is None or chart is None or has_errors(diags):
        raise DiagnosticError(diags)
    diags.extend(check_recovery(chart, tables.recovery, unruled=Severity.WARNING))
    if has_errors(diags):
        raise DiagnosticError(diags)
    return DeviceFile(chart, tables.recovery, tuple(diags))
