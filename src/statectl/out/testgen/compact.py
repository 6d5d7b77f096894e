"""The compact form of a generated test module, for big charts.

Rules:
1. A suite whose unhandled-event tables hold more than :data:`LOOP_ROWS` rows in all
   is *big*. Small suites keep the readable form: one parametrised test per table
   row, each path spelled out (``d.given("E0", "E1")``).
2. In a big suite each table is one test that sends its events in turn and checks
   each (the device must stay where it is, for the table's reason); a failure names
   the event. An unhandled event changes nothing, so one device serves the table.
   The table lists only the events it skips (handled there) and the reasons other
   than ``no transition``; every other event of ``EVENTS`` has no transition.
3. In a big suite the paths the tests send first are written once, as the tree
   ``_TREE`` of (parent entry, event); a test sends ``_path(k)``. Breadth-first paths
   share their prefixes, so the tree has about one entry per state, where spelling
   each path out would be quadratic in a ring of states.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from statectl.out.testgen.cases import NO_TRANSITION, Suite, Table

__all__ = ["LOOP_ROWS", "PathTree", "is_big", "loop_table", "module_events", "preamble"]

#: Table rows (events sent, one test each) above which a suite is written compactly.
LOOP_ROWS = 2000


def is_big(suite: Suite, loop_rows: int = LOOP_ROWS) -> bool:
    """Rule 1: do the suite's tables hold more than ``loop_rows`` rows?"""
    return sum(t.count for t in suite.tables) > loop_rows


class PathTree:
    """The given paths as a prefix tree (rule 3); ``entry`` numbers a path's last event."""

    def __init__(self) -> None:
        self.entries: list[tuple[int, Any]] = []  # (parent entry or -1, item)
        self.index: dict[tuple[int, str], int] = {}

    def entry(self, items: list[Any]) -> int:
        k = -1
        for item in items:
            key = (k, repr(item))
            found = self.index.get(key)
            if found is None:
                found = self.index[key] = len(self.entries)
                self.entries.append((k, item))
            k = found
        return k


def tree_given(tree: PathTree, lit: Callable[[Any], str]) -> Callable[[list[Any]], str]:
    """A writer of ``d.given(*_path(k))`` over ``tree`` (``items``: events or [e, data])."""

    def given(items: list[Any]) -> str:
        if not items:
            return ""
        k = tree.entry(items)
        return f"    d.given(*_path({k}))  # {len(items)} events, ending {lit(items[-1])}\n"

    return given


def loop_table(
    t: Table, events: tuple[str, ...], lit: Callable[[Any], str], given: str, head: str
) -> str:
    """Rule 2: one test for the whole table (``head``: its markers, def line and doc)."""
    reasons = {e: r for e, r in t.rows if r != NO_TRANSITION}
    # the shared sendable tuple (no copy, no O(events) compare), or rows list every event
    listed = t.events is events
    skip = t.skipped() if listed else frozenset(events) - {e for e, _ in t.rows}
    args = [
        lit(list(t.states)),
        f"skip={lit(sorted(skip))}",
        "reasons={" + ", ".join(f"{lit(e)}: {lit(r)}" for e, r in reasons.items()) + "}",
    ]
    call = f"    _each_unhandled(d, {', '.join(args)})\n"
    if len(call) > 101:
        call = "    _each_unhandled(\n" + "".join(f"        {a},\n" for a in args) + "    )\n"
    return head + "    d = statectl_device\n" + given + call + "\n\n"


def module_events(suite: Suite) -> tuple[str, ...]:
    """The events a big suite's tables loop over: the graph's sendable events."""
    for t in suite.tables:
        if t.events:
            return t.events
    seen: dict[str, None] = {}
    for t in suite.tables:
        seen.update((e, None) for e, _ in t.rows)
    return tuple(seen)


_PREAMBLE = '''

#: Every event a test can send, in table order (the unhandled-event tables loop over it).
EVENTS = @EVENTS@

#: The paths the tests send first, as a tree: entry k is (parent entry, event); the
#: path to k is the events from the root down to k (written once, shared by the tests).
_TREE = @TREE@


def _path(k):
    """The events from the root of _TREE down to entry k."""
    out = []
    while k >= 0:
        k, item = _TREE[k]
        out.append(item)
    return out[::-1]


def _each_unhandled(d, states, skip, reasons):
    """Send each event of EVENTS but ``skip``: each must leave the device in ``states``,
    unhandled for its reason (``reasons``, else no transition); a failure names it."""
    __tracebackhide__ = True
    for event in EVENTS:
        if event in skip:
            continue
        d.send(event)
        try:
            d.expect(states=states, unhandled=reasons.get(event, "@NONE@"))
        except AssertionError as exc:
            raise AssertionError(f"event {event!r} in {states}: {exc}") from None
'''


def preamble(events: tuple[str, ...], tree: PathTree, lit: Callable[[Any], str]) -> str:
    """The module-level helpers of a big suite (rules 2-3)."""
    ev = "[\n" + "".join(f"    {lit(e)},\n" for e in events) + "]" if events else "[]"
    rows = "".join(f"    ({k}, {lit(item)}),\n" for k, item in tree.entries)
    tr = "[\n" + rows + "]" if rows else "[]"
    return _PREAMBLE.replace("@EVENTS@", ev).replace("@TREE@", tr).replace("@NONE@", NO_TRANSITION)
