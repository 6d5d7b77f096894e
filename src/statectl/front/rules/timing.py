"""C409-C411: the rules about time and triggers (timeouts, deferred events,
``event trigger required``), beside the structural rules in :mod:`statectl.front.rules`.

They read the same :class:`~statectl.front.rules._Structure`; kept apart so each module stays
one concern.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from functools import partial
from typing import TYPE_CHECKING

from statectl.kernel.errors import Diagnostic, Severity
from statectl.kernel.model import ControlKind, EventKind, StateKind, Transition
from statectl.kernel.semantics import Machine, structural

if TYPE_CHECKING:
    from statectl.front.rules import _Structure

__all__ = ["check_deferred", "check_timeouts", "check_triggers"]


# -- C409 .. C411: timeouts, deferred events, trigger states ---------------------------------


def _entered(st: _Structure, m: Machine, t: Transition) -> tuple[str, ...]:
    """What taking ``t`` enters, by the kernel (:func:`~statectl.kernel.semantics.entry_set`):
    targets, their ancestors, default children and every region of a parallel state.
    One C401 already asked is answered from the check's cache first (its states are known)."""
    got = st.entry_sets.get(id(t))
    if got is not None:
        return got
    if not t.targets or not all(x in st.by_name for x in (t.source, *t.targets)):
        return ()
    return st.entered(m, t)


#: An unhandled configuration inside a state, as leaf names in region order: any one,
#: and one with a state that is not final (a configuration that does not leave at once).
_Lost = tuple[tuple[str, ...] | None, tuple[str, ...] | None]


def _lost(st: _Structure, name: str, uses: Callable[[str], bool]) -> _Lost:
    """Where inside ``name`` the kernel offers an event to no active state that ``uses``
    it (``uses`` asks about a leaf, its ancestors included). A parallel state's regions
    are all active: one region using it everywhere is enough, and a lost configuration
    takes a lost one from every region."""
    kind = st.kind(name)
    kids = [k for k in st.children.get(name, ()) if not st.kind(k).is_history]
    if not kids:
        if uses(name):
            return None, None
        return (name,), (None if kind is StateKind.FINAL else (name,))
    parts = [_lost(st, k, uses) for k in kids]
    if kind is not StateKind.PARALLEL:  # one child active at a time: the first that loses it
        lost = next((a for a, _ in parts if a is not None), None)
        return lost, next((n for _, n in parts if n is not None), None)
    if any(a is None for a, _ in parts):
        return None, None
    anyone = tuple(x for a, _ in parts for x in a or ())
    live = next((i for i, (_, n) in enumerate(parts) if n is not None), None)
    if live is None:
        return anyone, None
    nonfinal = tuple(x for i, (a, n) in enumerate(parts) for x in ((n if i == live else a) or ()))
    return anyone, nonfinal


def _quoted(names: tuple[str, ...]) -> str:
    return " and ".join(repr(n) for n in names)


def check_timeouts(st: _Structure) -> Iterator[Diagnostic]:
    """C409: a state's timeout event is handled wherever in the state the timer can run out.

    With a parallel state that is every configuration of its regions. One where every
    state waiting is final counts only if ``done.state.NAME`` is not handled.
    """
    for s in st.chart.states:
        if s.timeout is None:
            continue
        event = s.timeout.event
        anyone, nonfinal = _lost(st, s.name, partial(st.handles, event=event))
        lost = nonfinal
        done = f"done.state.{s.name}"
        if lost is None and anyone is not None and not st.handles(s.name, done):
            lost = anyone  # only configurations of final states lose it, and they stay
        if lost is None:
            continue
        if lost == (s.name,):
            who = "it does not handle"
        elif len(lost) == 1:
            who = f"{lost[0]!r} does not handle"
        else:
            who = f"none of {_quoted(lost)} (active together) handles"
        yield Diagnostic(
            "C409",
            Severity.ERROR,
            s.timeout.origin,
            f"state {s.name!r} times out with {event!r}, which {who}: the timeout would be lost",
            f"add an event row {event!r} with old state {s.name!r}",
        )


def _reached(st: _Structure, entered: tuple[str, ...]) -> tuple[tuple[str, ...], str]:
    """The innermost states of ``entered`` (one per active region) and the state to name
    in a message: that state alone, or the nearest one holding all of them (a parallel
    state whose regions were entered)."""
    names = set(entered)
    inner = [n for n in entered if not any(c in names for c in st.children.get(n, ()))]
    if len(inner) == 1:
        return tuple(inner), inner[0]
    common = [a for a in st.ancestors.get(inner[0], ()) if all(a in st.ancestors[n] for n in inner)]
    return tuple(inner), (common[0] if common else inner[0])


def _staying(st: _Structure, entered: tuple[str, ...]) -> list[str]:
    """The regions a transition that enters ``entered`` leaves active: those of every
    parallel state it stays inside, but for the region it enters (their states are
    whatever they were, so the kept event meets any configuration of them)."""
    names = set(entered)
    out: list[str] = []
    for a in st.ancestors.get(entered[0], ()):
        if a in names or st.kind(a) is not StateKind.PARALLEL:
            continue
        out.extend(
            r for r in st.children.get(a, ()) if r not in names and not st.kind(r).is_history
        )
    return out


def _keeps(st: _Structure, event: str, state: str) -> bool:
    """Whether ``state`` (or a superstate) handles, ignores or defers ``event``."""
    return (
        st.handles(state, event)
        or st.ignores(state, event)
        or any(event in st.by_name[b].defer for b in (state, *st.ancestors.get(state, ())))
    )


def check_deferred(st: _Structure) -> Iterator[Diagnostic]:
    """C410: leaving a deferring state releases its events; the state reached should use them.

    The state reached is what the kernel enters: with a parallel state, every region's
    state, any one of which may handle, defer or ignore the event. A transition inside one
    region of a parallel state leaves the other regions active: the event is used when one
    of them uses it in every configuration it can be in.
    """
    m: Machine | None = None
    for s in st.chart.states:
        if not s.defer:
            continue
        if m is None:
            m = structural(st.chart)
        inside = {s.name, *(a for a in st.by_name if s.name in st.ancestors.get(a, ()))}
        leaving = inside | set(st.ancestors.get(s.name, ()))  # a superstate's row leaves too
        for t in st.chart.transitions:
            if t.source not in leaving or not t.targets or all(x in inside for x in t.targets):
                continue
            entered = _entered(st, m, t)
            if not entered:
                continue
            inner, lands = _reached(st, entered)
            staying = _staying(st, entered)
            for event in s.defer:
                uses = partial(_keeps, st, event)
                if any(uses(a) for a in inner) or any(
                    _lost(st, r, uses) == (None, None) for r in staying
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
    """C411: an ``event trigger required`` state is entered by a command (or fault) event.

    Entered means in the kernel's entry set of such a transition: its target, a substate,
    an ancestor's default entry, or a region entered beside the target's.
    """
    chart = st.chart
    marked = [s for s in chart.states if ControlKind.TRIGGER in s.controls]
    if not marked:
        return
    m = structural(chart)
    drives = {  # per event name, asked once: whether it is a command or a fault
        e: (d := chart.event(e)) is None or d.kind in (EventKind.COMMAND, EventKind.FAULT)
        for e in chart.event_names
    }
    triggered: set[str] = set()
    for t in chart.transitions:
        for e in t.events:
            if drives[e]:
                triggered.update(_entered(st, m, t))
                break
    for s in marked:
        if s.name not in triggered:
            yield Diagnostic(
                "C411",
                Severity.WARNING,
                s.origin,
                f"state {s.name!r} is 'event trigger required' but no command or fault event "
                "enters it",
                "add a command event row with this new state, or drop 'event trigger required'",
            )
