"""Which events a configuration could take at all, found without stepping the kernel.

A generator that asks the kernel about every (configuration, event) pair is quadratic
in the chart; a big generated chart has thousands of both, and almost every pair
is an event no active state has a transition for. :class:`Offers` indexes, per state,
the events its own and its ancestors' transitions match, and the events it declares
ignored (or deferred), in time linear in transitions plus event names. For an event
outside :meth:`Offers.offered` the kernel's step is known without running it: nothing
is taken, and the reason is ``declared ignored`` when an active state lists the event,
``no transition`` otherwise (as :func:`~statectl.kernel.semantics.stepping.unhandled_reason`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from statectl.kernel.semantics.machine import Machine

__all__ = ["Offers"]


class Offers:
    """Per state, the indices (into ``events``) of the events it could take or ignores."""

    def __init__(self, m: Machine, events: Sequence[str]) -> None:
        number = {e: i for i, e in enumerate(events)}
        below: dict[str, list[int]] = {}  # "a" -> events "a.b", "a.b.c", ...
        for i, e in enumerate(events):
            for k, ch in enumerate(e):
                if ch == ".":
                    below.setdefault(e[:k], []).append(i)
        every = frozenset(range(len(events)))
        own: dict[str, frozenset[int]] = {}
        # SCXML matching (machine.name_match): a descriptor is the event itself, or a
        # dot-prefix of it ("error" and "error.*" match "error.x"), or "*"
        for state, transitions in m.transitions_of.items():
            found: set[int] = set()
            for t in transitions:
                for d in t.events:
                    if d == "*":
                        found |= every
                        continue
                    if d in number:
                        found.add(number[d])
                    found.update(below.get(d.removesuffix(".*"), ()))
            own[state] = frozenset(found)
        empty: frozenset[int] = frozenset()
        self.reach = {
            s: own.get(s, empty).union(*(own.get(a, empty) for a in m.ancestors[s]))
            for s in m.order
        }
        ignored: dict[str, set[int]] = {}
        for state, event in m.ignored:
            if event in number:
                ignored.setdefault(state, set()).add(number[event])
        self.ignores = {s: frozenset(v) for s, v in ignored.items()}

    def offered(self, active: Iterable[str]) -> frozenset[int]:
        """Events some active state (or an ancestor) has a transition for."""
        return frozenset().union(*(self.reach[s] for s in active))

    def ignored(self, active: Iterable[str]) -> frozenset[int]:
        """Events some active state declares ignored or deferred."""
        return frozenset().union(*(self.ignores.get(s, frozenset()) for s in active))
