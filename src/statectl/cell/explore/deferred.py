"""Deferred events in the explorer: a kept event may come back when its state is left.

The explorer does not track which deferred events a device holds (that would multiply
its local states by every sequence of kept events). It over-approximates instead: when
a step leaves a configuration that defers events, the device may have kept any of them,
so besides the plain outcome the search also explores the step followed at once by the
delivery of kept events, as the runtime releases them (statectl.run.runtime.defer): every
ordered choice of up to :data:`MAX_RELEASED` distinct deferred events the new
configuration no longer defers, each delivered once. Every real run is among those
explored when a device keeps each event at most once per visit; a device that keeps
more (the same event twice, or more than three kinds) is explored as if it kept one of
each. On arrival the kernel answers "declared ignored" for a deferred event, as it does
at run time.
"""

from __future__ import annotations

import itertools
from collections import deque
from typing import TYPE_CHECKING, Any

from statectl.kernel.semantics import Snapshot

if TYPE_CHECKING:
    from statectl.cell.explore.local import LocalSpace, Reaction

__all__ = ["DEFERRED", "MAX_RELEASED", "released"]

#: Distinct deferred events explored as released together after one step, at most.
MAX_RELEASED = 3
#: What a released outcome assumes (``Reaction.assumed``; the report names it).
DEFERRED = "events the device may have kept (deferred) released at once"


def _deferring(space: LocalSpace, snap: Snapshot) -> tuple[str, ...]:
    return space.chart.deferring(snap.active)


def _values(space: LocalSpace, lid: int) -> tuple[Any, ...]:
    """The tracked data of local state ``lid``, for a space that tracks data, else nothing."""
    valuations = getattr(space, "valuations", None)
    return (valuations[lid],) if valuations else ()


def released(
    space: LocalSpace, snap: Snapshot, outs: tuple[Reaction, ...], queue: deque[int]
) -> list[Reaction]:
    """Outcomes of ``outs``' handled steps followed by the release of kept events."""
    from statectl.cell.explore.local import Reaction

    kept = _deferring(space, snap)
    if not kept:
        return []
    found: list[Reaction] = []
    for first in outs:
        if not first.handled:
            continue
        after = space.snapshots[first.target]
        free = [e for e in kept if e not in _deferring(space, after)]
        for n in range(1, min(len(free), MAX_RELEASED) + 1):
            for order in itertools.permutations(free, n):
                paths = [first]
                for event in order:
                    nxt: list[Reaction] = []
                    for o in paths:
                        here = space.snapshots[o.target]
                        values = _values(space, o.target)
                        for result, choices in space._runs(event, here, *values):
                            pend = space.pending[o.target] if getattr(space, "calls", None) else ()
                            vals = values[0] if values else ()
                            r = space._outcome(result, choices, queue, vals, pend)
                            if not r.handled:
                                nxt.append(o)
                                continue
                            nxt.append(
                                Reaction(
                                    r.target,
                                    None,
                                    o.entered | r.entered,
                                    o.events | r.events,
                                    o.exited + r.exited,
                                    o.entered_order + r.entered_order,
                                    o.notifies + r.notifies,
                                    o.choices + r.choices,
                                    assumed=(DEFERRED,),
                                )
                            )
                    paths = nxt
                found.extend(p for p in paths if p is not first)
    return found
