"""C409-C411: the rules about time and triggers (timeouts, deferred events,
``event trigger required``), beside the structural rules in :mod:`statectl.rules`.

They read the same :class:`~statectl.rules._Structure`; kept apart so each module stays
one concern.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

from statectl.errors import Diagnostic, Severity
from statectl.model import ControlKind, EventKind, StateKind

if TYPE_CHECKING:
    from statectl.rules import _Structure

__all__ = ["check_deferred", "check_timeouts", "check_triggers"]


# -- C409 .. C411: timeouts, deferred events, trigger states ---------------------------------


def _settled(st: _Structure, name: str) -> str:
    """The atomic state default entry into ``name`` ends in (its initial chain)."""
    seen = {name}
    while st.kind(name) is StateKind.COMPOUND and st.by_name[name].initial:
        name = st.by_name[name].initial[0]
        if name in seen or name not in st.by_name:
            break
        seen.add(name)
    return name


def _atoms_in(st: _Structure, name: str) -> list[str]:
    out, pending = [], [name]
    while pending:
        n = pending.pop()
        kids = st.children.get(n, ())
        if not kids and st.kind(n) is StateKind.ATOMIC:
            out.append(n)
        pending.extend(kids)
    return out


def check_timeouts(st: _Structure) -> Iterator[Diagnostic]:
    """C409: a state's timeout event is handled wherever in the state the timer can run out."""
    for s in st.chart.states:
        if s.timeout is None:
            continue
        event = s.timeout.event
        missing = [a for a in (_atoms_in(st, s.name) or [s.name]) if not st.handles(a, event)]
        if missing:
            yield Diagnostic(
                "C409",
                Severity.ERROR,
                s.timeout.origin,
                f"state {s.name!r} times out with {event!r}, which "
                + (f"{missing[0]!r}" if missing != [s.name] else "it")
                + " does not handle: the timeout would be lost",
                f"add an event row {event!r} with old state {s.name!r}",
            )


def check_deferred(st: _Structure) -> Iterator[Diagnostic]:
    """C410: leaving a deferring state releases its events; the state reached should use them."""
    for s in st.chart.states:
        if not s.defer:
            continue
        inside = {s.name, *(a for a in st.by_name if s.name in st.ancestors.get(a, ()))}
        leaving = inside | set(st.ancestors.get(s.name, ()))  # a superstate's row leaves too
        for t in st.chart.transitions:
            if t.source not in leaving or not t.targets or all(x in inside for x in t.targets):
                continue
            for target in t.targets:
                lands = _settled(st, target)
                lineage = (lands, *st.ancestors.get(lands, ()))
                for event in s.defer:
                    if (
                        st.handles(lands, event)
                        or st.ignores(lands, event)
                        or any(event in st.by_name[a].defer for a in lineage)
                    ):
                        continue
                    yield Diagnostic(
                        "C410",
                        Severity.WARNING,
                        t.origin,
                        f"{t.label!r} leaves {s.name!r}, which defers {event!r}, for {lands!r}, "
                        f"which neither handles, defers nor ignores it: a kept {event!r} is lost",
                        f"add an event row {event!r} from {lands!r}, or list it in its ignore "
                        "or defer cell",
                    )


def check_triggers(st: _Structure) -> Iterator[Diagnostic]:
    """C411: an ``event trigger required`` state is entered by a command (or fault) event."""
    chart = st.chart
    for s in chart.states:
        if ControlKind.TRIGGER not in s.controls:
            continue
        # entered through itself, a substate, or an ancestor's default entry
        inside = {s.name, *st.ancestors.get(s.name, ())}
        inside.update(a for a in st.by_name if s.name in st.ancestors.get(a, ()))
        triggered = any(
            (d := chart.event(e)) is None or d.kind in (EventKind.COMMAND, EventKind.FAULT)
            for t in chart.transitions
            if any(x in inside for x in t.targets)
            for e in t.events
        )
        if not triggered:
            yield Diagnostic(
                "C411",
                Severity.WARNING,
                s.origin,
                f"state {s.name!r} is 'event trigger required' but no command or fault event "
                "enters it",
                "add a command event row with this new state, or drop 'event trigger required'",
            )
