"""The Recovery table checked against its chart: what a restarted device may do first.

A device that was Moving when the power went away is not moving any more; its
chart says Moving, its motor says nothing. A Recovery row names the transition
to take before anything else when a journalled device resumes in that state
(an event row), or says to issue again the device API calls of the step that
entered the state (a redo row: a Motor that was Returning is not returning any
more, and only its device's completion can take it out). The tables layer reads
the rows (shape problems are T1xx there); this module judges them against the
chart the other two tables built.

Rules:
J603 error    A row names a state the chart does not have.
J604 error    An event row's event does not leave its state by any transition of the chart.
J605 error    A second row for one state (the first one counts).
J606 (given)  A ``monitoring required`` state has no row: after a crash it resumes as
              if nothing happened. Its severity is the caller's: ``statectl check``
              reports it as info (a device that is not journalled needs no rule), the
              journalled runner as a warning.
J607 error    A redo row for a state that no transition enters with a device API call
              (a notification): there is nothing to redo.
J608 (given)  A state left only by ``completion`` events (it waits for its device) has
              no row: after a crash nobody does that work and the state is never left.
              Its severity is the caller's, as for J606.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from statectl.front.tables.rows import RecoveryRow
from statectl.kernel.codes import family
from statectl.kernel.errors import Diagnostic, Severity
from statectl.kernel.model import (
    Action,
    Block,
    Chart,
    ControlKind,
    EventKind,
    If,
    Notify,
    Transition,
    field_accepts,
)
from statectl.kernel.semantics import entry_set, structural

__all__ = ["CODES", "check_recovery", "redo_sources", "waits_for_device"]

#: Code -> one-line summary of every J6xx code (a view of statectl.kernel.codes.REGISTRY).
CODES: Mapping[str, str] = family("J6")


def _notifies(actions: tuple[Action, ...]) -> bool:
    """Whether ``actions`` issue a notification (a device API call), nested content too."""
    for a in actions:
        if isinstance(a, Notify):
            return True
        if isinstance(a, Block) and _notifies(a.actions):
            return True
        if isinstance(a, If) and any(_notifies(body) for _, body in a.branches):
            return True
    return False


def _leaving(chart: Chart, name: str) -> list[Transition]:
    """Transitions that leave ``name``: its own and its ancestors'."""
    found: list[Transition] = []
    current: str | None = name
    while current is not None:
        found.extend(chart.transitions_from(current))
        current = chart.state(current).parent
    return found


def redo_sources(chart: Chart, state: str) -> tuple[Transition, ...]:
    """The transitions whose step enters ``state`` with a device API call (what a redo redoes).

    What a transition enters is the kernel's answer (:func:`~statectl.kernel.semantics.entry_set`):
    its targets, their ancestors, default children and every region of a parallel state.
    """
    m = structural(chart)
    return tuple(
        t
        for t in chart.transitions
        if t.targets and _notifies(t.actions) and state in entry_set(m, [t])
    )


def waits_for_device(chart: Chart, state: str) -> bool:
    """Whether ``state`` is left only by ``completion`` events: only its device takes it out.

    The first row that is not a completion answers no: J608 asks this of every state,
    and the usual state's first row is a command."""
    left = False
    current: str | None = state
    while current is not None:  # its own transitions, then its ancestors' (_leaving)
        for t in chart.transitions_from(current):
            if not t.events:
                return False  # an eventless transition leaves by itself
            for e in t.events:
                d = chart.event(e)
                if d is None or d.kind is not EventKind.COMPLETION:
                    return False
            left = True
        current = chart.state(current).parent
    return left


def _data_fits(chart: Chart, r: RecoveryRow) -> list[Diagnostic]:
    """C413: a rule's data that its event, declaring its fields, would refuse on resume."""
    declared = chart.event(r.event)
    if declared is None or not declared.fields or r.data is None:
        return []
    fields = dict(declared.fields)
    listed = ", ".join(f"{k}: {v}" for k, v in declared.fields)
    if not isinstance(r.data, dict):
        why = f"is a {type(r.data).__name__}, not a mapping"
    else:
        bad = [k for k, v in r.data.items() if k not in fields or not field_accepts(fields[k], v)]
        if not bad:
            return []
        k = bad[0]
        why = f"has field {k!r}, " + (
            "which the event does not declare" if k not in fields else f"which is no {fields[k]}"
        )
    return [
        Diagnostic(
            "C413",
            Severity.ERROR,
            r.origin,
            f"recovery data for {r.state!r} {why}: event {r.event!r} would refuse it on resume",
            f"{r.event!r} declares: {listed}",
        )
    ]


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
        diags.extend(_rule_problems(chart, r))
    diags.extend(_unruled(chart, seen, unruled))
    return diags


def _rule_problems(chart: Chart, r: RecoveryRow) -> list[Diagnostic]:
    """What is wrong with one rule for a known state: nothing to redo (J607), an event
    that does not leave the state (J604), data that does not fit the event."""
    diags: list[Diagnostic] = []
    if r.redo:
        if not redo_sources(chart, r.state):
            diags.append(
                Diagnostic(
                    "J607",
                    Severity.ERROR,
                    r.origin,
                    f"redo rule for {r.state!r}, but no transition enters it with a "
                    "device API call: there is nothing to redo",
                    "give the entering event an api (a command or fault event), or "
                    "name an event that leaves the state instead of redo",
                )
            )
        return diags
    leaving = _leaving(chart, r.state)  # a superstate's transition leaves it too
    if not any(r.event in t.events for t in leaving):
        here = sorted({e for t in leaving for e in t.events})
        diags.append(
            Diagnostic(
                "J604",
                Severity.ERROR,
                r.origin,
                f"event {r.event!r} does not leave {r.state!r}",
                f"events leaving {r.state!r}: {', '.join(here) or 'none'}",
            )
        )
    diags.extend(_data_fits(chart, r))
    return diags


def _unruled(chart: Chart, seen: dict[str, RecoveryRow], unruled: Severity) -> list[Diagnostic]:
    """States a crash would strand without a rule: monitored (J606) or waiting on a device
    (J608), at the caller's ``unruled`` severity."""
    diags: list[Diagnostic] = []
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
        elif s.name not in seen and not s.kind.is_history and waits_for_device(chart, s.name):
            diags.append(
                Diagnostic(
                    "J608",
                    unruled,
                    s.origin,
                    f"state {s.name!r} is left only by completion events and has no "
                    "recovery rule; after a crash nobody does its device's work, so it is "
                    "never left",
                    f"add '- {{state: {s.name}, redo: yes}}' under recovery: to redo the "
                    "device calls of the step that entered it",
                )
            )
    return diags
