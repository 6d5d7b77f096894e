"""C422: a completion that answers no call is never reported.

A completion follows a call (:mod:`statectl.kernel.semantics.calls`): the twin reports
it after a command or fault row calls its API, and ``statectl verify`` offers it only
then. A completion no such call can be answered by (no API, or no driving row of its
API enters a state it leaves) is never reported by the twin nor offered by verify,
unless its row says ``unasked: yes``. Kept in its own module, apart from the
structural rules, so each can change alone.
"""

from __future__ import annotations

from collections.abc import Iterator

from statectl.kernel.errors import Diagnostic, Severity
from statectl.kernel.model import Chart, EventKind, Notify
from statectl.kernel.semantics.calls import DeviceCalls

__all__ = ["check_completions"]


def check_completions(chart: Chart) -> Iterator[Diagnostic]:
    """C422 (warning) for each completion no call of the chart can be answered by."""
    model = DeviceCalls(chart)
    answered: set[str] = set()
    for t in chart.transitions:
        for a in t.actions:
            if isinstance(a, Notify):
                answered.update(model.call(a.method, a.event).completions)
    for e in chart.events:
        if e.kind is not EventKind.COMPLETION or e.unasked or e.name in answered:
            continue
        why = (
            "it names no API"
            if not e.api
            else f"no command or fault row calls {e.api}() into a state it leaves"
        )
        yield Diagnostic(
            "C422",
            Severity.WARNING,
            e.origin,
            f"completion {e.name!r} answers no call ({why}): the simulated twin never "
            "reports it and statectl verify never offers it",
            f"give it the api of the call it completes, or write unasked: yes if "
            f"{chart.name} reports it by itself",
        )
