"""The rules `statectl check` applies to a built chart: every problem at once, stable codes.

Rules (guards are ignored except where C403 says otherwise):

C401 error    A state is unreachable: no run from the initial configuration enters it,
              even if every guard held. Only the outermost unreachable state is reported;
              its descendants are unreachable with it.
C402 warning  A non-final atomic state has no way out (no transition of its own or of an
              ancestor leads anywhere else), in a chart with more than one state.
C403 error    Two rows of the same state and event can both fire and neither has a guard.
C403 warning  Two rows of the same state and event have guards that may both hold; rows
              whose guards are provably exclusive (:func:`guards_exclusive`) are fine.
C404 warning  A state neither handles an event (itself or through an ancestor) nor lists it
              in its ignore column: the paper's missed transitions.
C405 warning  An event is declared but no transition uses it.
C406 warning  A state's ignore column lists an event the state (or an ancestor) handles.
C407 warning  A ``monitoring required`` state has no ``fault`` event leaving it (its own
              transitions or a superstate's), so its monitor would have nothing to raise.
C408 warning  A ``fault`` event leaves a state that is not ``monitoring required`` and has
              no monitored substate, so no monitor is running there to raise it.
C418 warning  The device file declares a ``profile`` statectl does not ship
              (:mod:`statectl.front.profiles`), so nothing that reads profiles will know it.
C409 error    A state's timeout event is not handled where the timer can run out.
C410 warning  A transition leaves a state that defers an event for one that neither
              handles, defers nor ignores it: the kept event would be lost there.
C411 warning  An ``event trigger required`` state is entered by no command or fault event.
C419 warning  Every row of a state for one event is guarded and the guards are not proven
              to cover every case (statectl.front.rules.guards.guards_cover): the event
              may go unhandled.
C420 error    A guard's ``In('X')`` or ``previous == 'X'`` names a state the device does
              not have (statectl.front.rules.names).
C421 error    A guard compares ``_event.name`` with an event the device does not have.
C422 warning  A completion answers no call (statectl.front.rules.completions): the twin
              never reports it and verify never offers it, unless it is ``unasked``.

Undefined guard names and other table errors are the builder's (X3xx, T/B codes);
:func:`check_paths` reports those too, then checks each chart that built, and its
Recovery table with :func:`statectl.front.recovery.check_recovery` (J603-J605 errors, J606 info).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field

from statectl.front.builder.build import build
from statectl.front.profiles import PROFILES, find
from statectl.front.recovery import check_recovery
from statectl.front.rules.completions import check_completions
from statectl.front.rules.guards import guards_cover, guards_exclusive
from statectl.front.rules.names import check_guard_names
from statectl.front.rules.timing import check_deferred, check_timeouts, check_triggers
from statectl.front.tables import load
from statectl.front.tables.bulk import gc_paused
from statectl.kernel.codes import family
from statectl.kernel.errors import Diagnostic, Location, Severity, did_you_mean, has_errors
from statectl.kernel.model import Chart, ControlKind, EventKind, State, StateKind, Transition
from statectl.kernel.semantics import Machine, entry_set, release, structural

__all__ = ["CODES", "check_chart", "check_paths", "guards_exclusive"]

#: Code -> one-line summary of every C4xx code (a view of statectl.kernel.codes.REGISTRY).
CODES: Mapping[str, str] = family("C4")


# -- chart structure ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Structure:
    """Parent/child/ancestor tables of a chart, computed once per check."""

    chart: Chart
    by_name: dict[str, State]
    children: dict[str | None, tuple[str, ...]]
    ancestors: dict[str, tuple[str, ...]]
    outgoing: dict[str, tuple[Transition, ...]]  # a state's own transitions, in chart order
    descriptors: dict[str, frozenset[str]]  # event descriptors of a state and its ancestors
    #: What each transition enters (by id), asked of the kernel once per check: C401 and
    #: the timing rules each asked it for every row, the bulk of a 100,000-row check.
    entry_sets: dict[int, tuple[str, ...]] = field(default_factory=dict)

    @classmethod
    def of(cls, chart: Chart) -> _Structure:
        by_name = {s.name: s for s in chart.states}
        children: dict[str | None, list[str]] = {}
        for s in chart.states:
            children.setdefault(s.parent, []).append(s.name)
        ancestors: dict[str, tuple[str, ...]] = {}
        for s in chart.states:
            chain: list[str] = []
            p = s.parent
            while p is not None and p in by_name and p not in chain:
                chain.append(p)
                p = by_name[p].parent
            ancestors[s.name] = tuple(chain)
        outgoing: dict[str, list[Transition]] = {}
        for t in chart.transitions:
            outgoing.setdefault(t.source, []).append(t)
        own = {name: frozenset(e for t in ts for e in t.events) for name, ts in outgoing.items()}
        descriptors = {
            s.name: frozenset().union(*(own.get(a, ()) for a in (s.name, *ancestors[s.name])))
            for s in chart.states
        }
        return cls(
            chart,
            by_name,
            {k: tuple(v) for k, v in children.items()},
            ancestors,
            {k: tuple(v) for k, v in outgoing.items()},
            descriptors,
        )

    def entered(self, m: Machine, t: Transition) -> tuple[str, ...]:
        """The kernel's entry set of taking ``t`` alone (cached for this check)."""
        got = self.entry_sets.get(id(t))
        if got is None:
            got = self.entry_sets[id(t)] = tuple(entry_set(m, [t]))
        return got

    def out(self, name: str) -> tuple[Transition, ...]:
        return self.outgoing.get(name, ())

    def kind(self, name: str) -> StateKind:
        return self.by_name[name].kind

    def handles(self, state: str, event: str) -> bool:
        """Whether a transition of ``state`` or an ancestor names ``event``."""
        mine = self.descriptors.get(state, frozenset())
        return bool(mine) and any(d in mine for d in _matching(event))

    def rows(self, state: str, event: str) -> list[Transition]:
        """The transitions of ``state`` and its ancestors that ``event`` matches."""
        names = set(_matching(event))
        return [
            t
            for a in (state, *self.ancestors.get(state, ()))
            for t in self.out(a)
            if any(e in names for e in t.events)
        ]

    def ignores(self, state: str, event: str) -> bool:
        return any(
            (s, event) in self.chart.ignored for s in (state, *self.ancestors.get(state, ()))
        )


def _matching(event: str) -> tuple[str, ...]:
    """Every descriptor that matches ``event`` (as ``name_match`` decides): ``*``, the
    name itself, and each dot-prefix with and without ``.*``; a set lookup each, so a
    rule asks "does any row name this event" without scanning every row."""
    found = ["*", event]
    at = event.find(".")
    while at != -1:
        prefix = event[:at]
        found += [prefix, prefix + ".*"]
        at = event.find(".", at + 1)
    return tuple(found)


def _where(state: State) -> Location:
    return state.origin


def _line(loc: Location) -> str:
    return f"line {loc.line}" if loc.line is not None else str(loc)


# -- C401 reachability ----------------------------------------------------------------------


def _reachable(st: _Structure) -> set[str]:
    """States some run can enter, taking every transition as if its guard held.

    What the start and each transition enter is the kernel's answer
    (:func:`~statectl.kernel.semantics.entry_set`), history states entering their defaults
    (what they restore was entered before).
    """
    chart = st.chart
    m = structural(chart)
    reached = set(entry_set(m, []))
    work = list(reached)
    names = frozenset(st.by_name)
    while work:
        name = work.pop()
        for t in st.out(name):
            if not t.targets or not names.issuperset(t.targets):
                continue
            for entered in st.entered(m, t):
                if entered not in reached:
                    reached.add(entered)
                    work.append(entered)
    return reached


def _check_reachable(st: _Structure) -> Iterator[Diagnostic]:
    reached = _reachable(st)
    start = ", ".join(st.chart.initial) or "the first state"
    unreached_below: dict[str, int] = {}
    for d, anc in st.ancestors.items():
        if d not in reached:
            for a in anc:
                unreached_below[a] = unreached_below.get(a, 0) + 1
    for s in st.chart.states:
        if s.name in reached or s.kind.is_history:
            continue
        if any(a not in reached for a in st.ancestors[s.name]):
            continue  # reported with its outermost unreachable ancestor
        below = unreached_below.get(s.name, 0)
        extra = f" (and its {below} substates)" if below else ""
        yield Diagnostic(
            "C401",
            Severity.ERROR,
            _where(s),
            f"state {s.name!r}{extra} is unreachable from the initial state {start}",
            f"add an event row with new state {s.name!r}, or remove the state",
        )


# -- C402 no way out ------------------------------------------------------------------------


def _check_way_out(st: _Structure) -> Iterator[Diagnostic]:
    real = [s for s in st.chart.states if not s.kind.is_history]
    if len(real) <= 1:
        return
    for s in real:
        if s.kind is not StateKind.ATOMIC:
            continue
        leaves = any(
            any(x != s.name for x in t.targets)
            for src in (s.name, *st.ancestors[s.name])
            for t in st.out(src)
        )
        if not leaves:
            yield Diagnostic(
                "C402",
                Severity.WARNING,
                _where(s),
                f"state {s.name!r} has no transition out: once entered the device stays there",
                "add an event row with this old state, or mark the state final if it is",
            )


# -- C403 overlapping rows ------------------------------------------------------------------

#: Events a C404 message names at most (it counts the rest).
MAX_LISTED = 20
#: Rows of one state and event compared pair by pair at most (C403 warns beyond it).
MAX_OVERLAP_ROWS = 256


def _check_overlaps(st: _Structure) -> Iterator[Diagnostic]:
    names = st.chart.event_names
    position = {e: i for i, e in enumerate(names)}
    by_descriptor: dict[str, list[str]] = {}  # the event names each descriptor matches
    for e in names:
        for d in _matching(e):
            by_descriptor.setdefault(d, []).append(e)
    seen: set[tuple[int, int]] = set()
    for s in st.chart.states:
        own = st.out(s.name)
        if len(own) < 2:
            continue  # no pair of rows, nothing can overlap
        rows_of: dict[str | None, list[Transition]] = {}  # each event's rows, in table order
        for t in own:
            matched: set[str | None] = {n for d in t.events for n in by_descriptor.get(d, ())}
            for name in matched if t.events else {None}:
                rows_of.setdefault(name, []).append(t)
        events = sorted((e for e in rows_of if e is not None), key=position.__getitem__)
        for event in [*events, None]:
            rows = rows_of.get(event, [])
            if len(rows) > MAX_OVERLAP_ROWS:
                yield _too_many_rows(s.name, event, rows)
                rows = rows[:MAX_OVERLAP_ROWS]
            for i, first in enumerate(rows):
                for second in rows[i + 1 :]:
                    key = (id(first), id(second))
                    if key in seen:
                        continue
                    seen.add(key)
                    diag = _overlap(s.name, event, first, second)
                    if diag is not None:
                        yield diag


def _too_many_rows(state: str, event: str | None, rows: list[Transition]) -> Diagnostic:
    what = f"event {event!r}" if event is not None else "no event (eventless)"
    return Diagnostic(
        "C403",
        Severity.WARNING,
        rows[MAX_OVERLAP_ROWS].origin,
        f"state {state!r} has {len(rows)} rows for {what}: only the first "
        f"{MAX_OVERLAP_ROWS} were compared pair by pair, so later rows may overlap unseen",
        "split the rows over substates or events; see docs/limits.md",
    )


def _overlap(
    state: str, event: str | None, first: Transition, second: Transition
) -> Diagnostic | None:
    both_unguarded = first.guard is None and second.guard is None
    if not both_unguarded and guards_exclusive(first.guard, second.guard):
        return None  # the usual pair: said before any text is made for it
    what = f"event {event!r}" if event is not None else "no event (eventless)"
    rows = f"{_line(first.origin)} and {_line(second.origin)}"
    if both_unguarded:
        return Diagnostic(
            "C403",
            Severity.ERROR,
            second.origin,
            f"state {state!r} has two unguarded rows for {what} ({rows}); "
            "only the first can ever fire",
            "merge the rows, or give them guards that exclude each other",
        )
    guards = f"[{first.guard or 'no guard'}] and [{second.guard or 'no guard'}]"
    return Diagnostic(
        "C403",
        Severity.WARNING,
        second.origin,
        f"state {state!r} has rows for {what} ({rows}) whose guards {guards} may both hold",
        "make the guards exclusive, e.g. 'g' and 'not g', or x < c and x >= c",
    )


# -- C404 .. C408 ----------------------------------------------------------------------------


def _check_missed(st: _Structure) -> Iterator[Diagnostic]:
    events = st.chart.event_names
    position = {e: i for i, e in enumerate(events)}
    by_descriptor: dict[str, set[str]] = {}  # the event names each descriptor matches
    for e in events:
        for d in _matching(e):
            by_descriptor.setdefault(d, set()).add(e)
    ignored: dict[str, set[str]] = {}
    for state, event in st.chart.ignored:
        ignored.setdefault(state, set()).add(event)
    for s in st.chart.states:
        if s.kind is not StateKind.ATOMIC:
            continue
        lineage = (s.name, *st.ancestors.get(s.name, ()))
        covered = {e for d in st.descriptors.get(s.name, ()) for e in by_descriptor.get(d, ())}
        covered.update(e for a in lineage for e in ignored.get(a, ()) if e in position)
        covered.update(e for a in lineage for e in st.by_name[a].defer if e in position)
        count = len(events) - len(covered)
        if count == 0:
            continue
        missed: list[str] = []
        for e in events:  # in event order, stopping at the listed few
            if e not in covered:
                missed.append(e)
                if len(missed) == MAX_LISTED:
                    break
        names = ", ".join(repr(e) for e in missed)
        if count > len(missed):
            names += f" and {count - len(missed)} more"
        yield Diagnostic(
            "C404",
            Severity.WARNING,
            _where(s),
            f"state {s.name!r} neither handles nor ignores {names} (missed transition)",
            "add an event row with this old state, or list the event in the state's ignore column",
        )


def _check_unused_events(st: _Structure) -> Iterator[Diagnostic]:
    used = {d for t in st.chart.transitions for d in t.events}
    for e in st.chart.events:
        if not any(d in used for d in _matching(e.name)):
            yield Diagnostic(
                "C405",
                Severity.WARNING,
                e.origin,
                f"event {e.name!r} is declared but no transition uses it",
                "add an event row for it, or remove the declaration",
            )


def _check_contradictory_ignores(st: _Structure) -> Iterator[Diagnostic]:
    for state, event in sorted(st.chart.ignored):
        if state in st.by_name and st.handles(state, event):
            rows = st.rows(state, event)
            if rows and all(t.guard is not None for t in rows):
                continue  # every row is guarded: the ignore is what happens when none holds
            yield Diagnostic(
                "C406",
                Severity.WARNING,
                _where(st.by_name[state]),
                f"state {state!r} lists {event!r} as ignored but a transition handles it",
                f"remove {event!r} from the state's ignore column, or remove the event row",
            )


def _is_fault(chart: Chart, event: str) -> bool:
    edef = chart.event(event)
    return edef is not None and edef.kind is EventKind.FAULT


def _check_monitors(st: _Structure) -> Iterator[Diagnostic]:
    chart = st.chart
    for s in chart.states:
        if ControlKind.MONITORING not in s.controls:
            continue
        # a superstate's fault transition leaves the state too (CiA 402's "from any state")
        leaving = (s.name, *st.ancestors.get(s.name, ()))
        raises = any(
            _is_fault(chart, e)
            for src in leaving
            for t in chart.transitions_from(src)
            for e in t.events
        )
        if not raises:
            yield Diagnostic(
                "C407",
                Severity.WARNING,
                _where(s),
                f"state {s.name!r} is monitoring required but no fault event leaves it, "
                "so its monitor would have nothing to raise",
                "add a fault-kind event row with this old state, or drop 'monitoring required'",
            )
    monitored_below = {
        anc
        for s in chart.states
        if ControlKind.MONITORING in s.controls
        for anc in st.ancestors.get(s.name, ())
    }
    faults = {e for e in chart.event_names if _is_fault(chart, e)}  # once per name, not row
    for t in chart.transitions:
        source = st.by_name.get(t.source)
        if source is None or ControlKind.MONITORING in source.controls:
            continue
        if t.source in monitored_below:
            continue  # a monitored substate's monitor raises it (a superstate's fault row)
        for e in t.events:
            if e in faults:
                yield Diagnostic(
                    "C408",
                    Severity.WARNING,
                    t.origin,
                    f"fault event {e!r} leaves {t.source!r}, which is not monitoring required, "
                    "so no monitor runs there to raise it",
                    f"mark {t.source!r} 'monitoring required', or make {e!r} a command event",
                )


def _check_profile(st: _Structure) -> Iterator[Diagnostic]:
    profile = st.chart.profile
    if profile and find(profile) is None:
        names = [p.name for p in PROFILES]
        yield Diagnostic(
            "C418",
            Severity.WARNING,
            st.chart.origin,
            f"profile {profile!r} is not a profile statectl ships",
            _did_you_mean(profile, names) + "shipped: " + ", ".join(names),
        )


def _did_you_mean(word: str, choices: Sequence[str]) -> str:
    return did_you_mean(word.lower(), choices)  # kernel/errors.py: the one suggestion


def _check_cover(st: _Structure) -> Iterator[Diagnostic]:
    """C419: a state's rows for one event are all guarded and may all be false."""
    for s in st.chart.states:
        rows_of: dict[str, list[Transition]] = {}
        for a in (s.name, *st.ancestors.get(s.name, ())):
            for t in st.out(a):
                for e in t.events:
                    rows_of.setdefault(e, []).append(t)
        for event, rows in rows_of.items():
            if len(rows) > MAX_OVERLAP_ROWS or any(t.guard is None for t in rows):
                continue  # an unguarded row takes the event (the usual event): asked first
            own = [t for t in rows if t.source == s.name]
            if not own:
                continue
            if st.ignores(s.name, event):
                continue  # when no guard holds the kernel ignores it, as declared
            guards = [t.guard for t in rows if t.guard is not None]
            if guards_cover(guards):
                continue
            shown = " / ".join(f"[{g}]" for g in guards)
            yield Diagnostic(
                "C419",
                Severity.WARNING,
                own[0].origin,
                f"state {s.name!r}: the guards of its rows for {event!r} ({shown}) may all be "
                "false, and then no row takes the event (unhandled: guard false)",
                "add a row for the remaining case (e.g. the negation), or make the guards "
                "cover every case (x > 3 / x <= 3)",
            )


_RULES: tuple[Callable[[_Structure], Iterator[Diagnostic]], ...] = (
    _check_reachable,
    _check_way_out,
    _check_overlaps,
    _check_missed,
    _check_unused_events,
    _check_contradictory_ignores,
    _check_monitors,
    _check_profile,
    check_timeouts,
    check_deferred,
    check_triggers,
    _check_cover,  # C419
    lambda st: check_guard_names(st.chart),  # C420, C421 (rules/names.py)
    lambda st: check_completions(st.chart),  # C422 (rules/completions.py)
)


def check_chart(chart: Chart) -> Iterator[Diagnostic]:
    """Yield every problem the rules above find in ``chart``, rule by rule."""
    st = _Structure.of(chart)
    for rule in _RULES:
        yield from rule(st)


def check_paths(paths: Sequence[str], texts: Mapping[str, str] | None = None) -> list[Diagnostic]:
    """Load and build each file (its diagnostics included), then check each chart that built.

    The chart's Recovery table is checked too (J603-J605 errors); a monitored
    state without a rule (J606) is info here, since only a journalled run needs one.
    ``texts`` holds unsaved content by absolute path (:func:`statectl.front.tables.load`).
    """
    out: list[Diagnostic] = []
    with gc_paused():  # many objects, no garbage: the collector's walks grew with the file
        for path in paths:
            out.extend(_check_path(path, texts))
    return out


def _check_path(path: str, texts: Mapping[str, str] | None) -> list[Diagnostic]:
    tables, diagnostics = load(path, texts)
    out = list(diagnostics)
    if tables is None:
        return out
    errors = has_errors(out)
    chart, more = build(tables)  # built even after load errors: report both at once
    out.extend(more)
    if chart is not None and not errors:
        out.extend(check_chart(chart))
        out.extend(check_recovery(chart, tables.recovery))
    if chart is not None:
        release(chart)  # nobody steps this chart: free it now, while the collector is off
    return out
