"""Step 2 for the state table's newer cells: ``timeout`` (B224, B225), ``defer`` (B225-B227),
the ``ignore: all others`` form, and the ``api`` column against the events' APIs (B228).

Rules:
1. A state's ``timeout`` becomes :class:`~statectl.kernel.model.Timeout` on its chart state; its
   event must be in the events table (B224). Whether the state handles it is
   ``check``'s C409, since an unhandled timeout is a missed transition, not a bad table.
2. ``defer`` names events of the events table (B226) that the state and its ancestors
   neither handle nor ignore (B227): a deferred event waits because the state has
   nothing to do with it yet.
3. History and final states are never active with a timer running or an event to keep:
   a timeout or defer there is B225.
4. ``ignore: all others`` expands to every declared event that neither the state nor an
   ancestor handles, in event order (:func:`expand_ignore`).
5. A method named in a state's ``api`` cell (``Movement()``, comma-separated) should be
   the API of an event that enters or leaves the state; one that is not is B228
   (warning): the paper's Table 1 and Table 2 disagree.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Protocol

from statectl.front.builder.common import _d, _hint
from statectl.front.tables.rows import EventRow
from statectl.front.tables.timeouts import is_all_others, parse_timeout
from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.model import StateKind, Timeout

__all__ = ["check_apis", "expand_ignore", "state_extras"]


class _Row(Protocol):
    """What these rules read of a merged state row (builder.states._Merged)."""

    @property
    def name(self) -> str: ...
    @property
    def api(self) -> str: ...
    @property
    def parent(self) -> str: ...
    @property
    def rows(self) -> tuple[Location, ...]: ...
    @property
    def timeout(self) -> str: ...
    @property
    def defer(self) -> tuple[str, ...]: ...
    @property
    def ignore(self) -> tuple[str, ...]: ...


def _lineage(name: str, merged: Mapping[str, _Row]) -> list[str]:
    """The state and its ancestors (a cycle is B210's, so stop at a repeat)."""
    chain, seen = [name], {name}
    parent = merged[name].parent
    while parent and parent in merged and parent not in seen:
        chain.append(parent)
        seen.add(parent)
        parent = merged[parent].parent
    return chain


def _handled(name: str, merged: Mapping[str, _Row], rows: Sequence[EventRow]) -> set[str]:
    lineage = set(_lineage(name, merged))
    return {r.event for r in rows if r.old in lineage}


def expand_ignore(
    name: str, merged: Mapping[str, _Row], rows: Sequence[EventRow], events: Sequence[str]
) -> tuple[str, ...]:
    """The state's ignore items with ``all others`` replaced by what it stands for (rule 4)."""
    items = merged[name].ignore
    if not any(is_all_others(i) for i in items):
        return items
    handled = _handled(name, merged, rows)
    named = [i for i in items if not is_all_others(i)]
    deferred = set(merged[name].defer)
    rest = [e for e in events if e not in handled and e not in deferred and e not in named]
    return tuple(dict.fromkeys([*named, *rest]))


def state_extras(
    merged: Mapping[str, _Row],
    kinds: Mapping[str, StateKind],
    rows: Sequence[EventRow],
    events: Sequence[str],
    diags: list[Diagnostic],
) -> dict[str, tuple[Timeout | None, tuple[str, ...]]]:
    """Each kept state's timeout and deferred events, every problem reported (rules 1-3)."""
    known = set(events)
    out: dict[str, tuple[Timeout | None, tuple[str, ...]]] = {}
    for name, kind in kinds.items():
        m = merged[name]
        where = m.rows[0]
        timeout: Timeout | None = None
        if (m.timeout or m.defer) and (kind.is_history or kind is StateKind.FINAL):
            cells = " and ".join(c for c, v in (("timeout", m.timeout), ("defer", m.defer)) if v)
            diags.append(
                _d(
                    "B225",
                    Severity.ERROR,
                    where,
                    f"state {name!r} is a {kind.value} state and has a {cells} cell",
                    "a history or final state is never active with time running: "
                    "move the cell to the parent or a sibling",
                )
            )
        parsed = parse_timeout(m.timeout) if m.timeout else None
        if isinstance(parsed, tuple):
            seconds, event = parsed
            if event not in known:
                diags.append(
                    _d(
                        "B224",
                        Severity.ERROR,
                        where,
                        f"state {name!r} times out with unknown event {event!r}",
                        _hint(event, list(events)) + "; add an event row for it",
                    )
                )
            timeout = Timeout(seconds, event, where)
        handled = _handled(name, merged, rows) if m.defer else set()
        # only a state that defers needs its lineage: a deep chain walked for every state
        # would be quadratic (a 10,000-level file is refused as B218, but built first)
        ignored = (
            {i for a in _lineage(name, merged) for i in merged[a].ignore} if m.defer else set()
        )
        for event in m.defer:
            if event not in known:
                diags.append(
                    _d(
                        "B226",
                        Severity.ERROR,
                        where,
                        f"state {name!r} defers unknown event {event!r}",
                        _hint(event, list(events)),
                    )
                )
            elif event in handled or event in ignored:
                what = "handles" if event in handled else "ignores"
                cell = "event rows" if what == "handles" else "ignore cell"
                diags.append(
                    _d(
                        "B227",
                        Severity.ERROR,
                        where,
                        f"state {name!r} defers {event!r}, which it (or an ancestor) {what}",
                        "defer an event only where nothing happens with it yet: remove it "
                        f"from the defer cell or from the {cell}",
                    )
                )
        out[name] = (timeout, m.defer)
    return out


def _methods(text: str) -> list[str]:
    """``Movement(), Error()`` -> ``["Movement", "Error"]``."""
    names = (part.strip() for part in text.split(","))
    return [n[:-2].strip() if n.endswith("()") else n for n in names if n]


def check_apis(
    merged: Mapping[str, _Row], rows: Sequence[EventRow], diags: list[Diagnostic]
) -> None:
    """Rule 5: every method a state's ``api`` cell names is an API of an event touching it."""
    touching: dict[str, set[str]] = {}
    every: set[str] = set()
    for r in rows:
        if r.api:
            every.add(r.api)
            touching.setdefault(r.old, set()).add(r.api)
            touching.setdefault(r.new, set()).add(r.api)
    if not every:
        return  # a device whose events name no API: the api column is prose
    for name, m in merged.items():
        for method in _methods(m.api):
            if method in touching.get(name, ()):
                continue
            known = method in every
            diags.append(
                _d(
                    "B228",
                    Severity.WARNING,
                    m.rows[0],
                    f"state {name!r} names API {method}() but "
                    + (
                        "no event entering or leaving it uses that API"
                        if known
                        else "no event row has that API"
                    ),
                    (_hint(method, sorted(every)) if not known else "")
                    + "; the state's api cell names the APIs of the events that drive it",
                )
            )
