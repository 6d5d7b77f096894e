"""The Recovery table checked against its chart: what a restarted device may do first.

A device that was Moving when the power went away is not moving any more; its
chart says Moving, its motor says nothing. A Recovery row names the transition
to take before anything else when a journalled device resumes in that state.
The tables layer reads the rows (shape problems are T1xx there); this module
judges them against the chart the other two tables built.

Rules:
J603 error    A row names a state the chart does not have.
J604 error    A row's event does not leave its state by any transition of the chart.
J605 error    A second row for one state (the first one counts).
J606 (given)  A ``monitoring required`` state has no row: after a crash it resumes as
              if nothing happened. Its severity is the caller's: ``statectl check``
              reports it as info (a device that is not journalled needs no rule), the
              journalled runner as a warning.
"""

from __future__ import annotations

from collections.abc import Sequence

from statectl.errors import Diagnostic, Severity
from statectl.model import Chart, ControlKind
from statectl.tables.schema import RecoveryRow

__all__ = ["CODES", "check_recovery"]

#: Every code this module reports, with a one-line summary (docs/check.md expands them).
CODES: dict[str, str] = {
    "J603": "a recovery rule names a state the chart does not have",
    "J604": "a recovery rule's event does not leave its state by any transition",
    "J605": "two recovery rules for one state",
    "J606": "a monitored state has no recovery rule",
}


def check_recovery(
    chart: Chart, rows: Sequence[RecoveryRow], *, unruled: Severity = Severity.INFO
) -> list[Diagnostic]:
    """Problems of ``rows`` against ``chart`` (J603-J605 errors; J606 at ``unruled``)."""
    diags: list[Diagnostic] = []
    names = [s.name for s in chart.states]
    seen: dict[str, RecoveryRow] = {}
    for r in rows:
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
        if not any(t.source == r.state and r.event in t.events for t in chart.transitions):
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
                    unruled,
                    s.origin,
                    f"monitored state {s.name!r} has no recovery rule; after a "
                    "crash it resumes as if nothing happened",
                    f"add '- {{state: {s.name}, event: <fault event>}}' under recovery:",
                )
            )
    return diags
