"""The breadth-first walk over a cell's global states (rules 1, 2, 5, 6 of
:mod:`statectl.cell.explore.search`), apart from the verdicts read off it.

Rules:
1. The walk stores each new state with its parent's number and checks the
   invariants on it; a deadlock is a state where no stimulus happens.
2. The common step, an xor from the precomputed tables, runs in the walk's own
   loop on locals; a device state with cascading stimuli, unanticipated inputs or
   raising guards goes through :meth:`Walk._rare`, called only for those.
3. Reaching ``max_states`` stops the walk and marks it incomplete.
4. With partial-order reduction (:mod:`statectl.cell.explore.ample`), a state the
   reduction accepts is expanded through its cluster alone
   (:meth:`Walk.expand_cluster`); the others are expanded in full as before.
5. With ``symmetry`` (symmetry reduction, :mod:`statectl.cell.explore.symmetry`) every
   state is stored as its orbit's representative; what a step meets on the way is
   noted with the concrete state it reached. A walk takes one reduction or the
   other, never both (explore/search.py rule 8).
"""

from __future__ import annotations

import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from statectl.cell.explore.compose import Composed, Predicate, Stimulus
from statectl.cell.explore.pack import seen_store, state_store
from statectl.cell.model import InputKind

if TYPE_CHECKING:
    from statectl.cell.explore.ample import Ample
    from statectl.cell.explore.search import _Tables
    from statectl.cell.explore.symmetry import Symmetry


@dataclass(frozen=True, slots=True)
class Progress:
    states: int
    expanded: int
    depth: int
    seconds: float


class Walk:
    """One breadth-first walk: the graph it stored and everything it met on the way."""

    def __init__(
        self,
        model: Composed,
        tables: _Tables,
        invariants: list[tuple[str, Predicate]],
        *,
        keep_edges: bool,
        max_states: int | None,
        ample: Ample | None = None,
        symmetry: Symmetry | None = None,
    ) -> None:
        assert ample is None or symmetry is None, "one reduction at a time (rule 5)"
        self.model = model
        self.ample = ample
        self.symmetry = symmetry
        self.canon = symmetry.canon if symmetry is not None else None
        self.tables = tables
        self.invariants = invariants
        self.keep_edges = keep_edges
        self.limit = max_states if max_states is not None else -1
        self.states = state_store(model.width)  # compact: explore/pack.py
        # numbered: recovery's edges and the reduction's cycle proviso ask state numbers
        self.index = seen_store(model.width, keep_edges or ample is not None)
        self.parent: array[int] = array("q")
        self.violated: dict[str, int] = {}
        self.violations: dict[str, int] = {}
        self.deadlocks: list[int] = []
        self.unhandled: dict[tuple[int, str, str], tuple[int, Stimulus, int]] = {}
        self.unhandled_count: dict[tuple[int, str, str], int] = {}
        self.livelocks: dict[int, tuple[int, Stimulus]] = {}
        # (device, local state label, event) -> first (state, stimulus, target or -1,
        # local id, link or -1)
        self.errors: dict[tuple[int, str, str], tuple[int, Stimulus, int, int, int]] = {}
        self.error_count: dict[tuple[int, str, str], int] = {}
        self.unant_first: dict[tuple[int, int, str, InputKind], int] = {}
        self.unant_count: dict[tuple[int, int, str, InputKind], int] = {}
        self.unant_states = 0
        self.src: array[int] = array("q")
        self.dst: array[int] = array("q")
        self.transitions = 0
        self.depth = 0
        self.complete = True

    def add(self, h: int, p: int) -> None:
        """Store state ``h`` reached from state number ``p``, checking the invariants."""
        self.index[h] = len(self.states)
        self.states.append(h)
        self.parent.append(p)
        for name, fn in self.invariants:
            if not fn(h):
                self.violations[name] = self.violations.get(name, 0) + 1
                self.violated.setdefault(name, len(self.states) - 1)

    def run(self, progress: Callable[[Progress], None] | None, t0: float) -> None:
        """Walk from the initial states until none is left or the bound is reached."""
        model, tables = self.model, self.tables
        index, states, add = self.index, self.states, self.add
        src, dst, keep_edges = self.src, self.dst, self.keep_edges
        canon = self.canon
        for g0 in model.initial:
            if canon is not None:
                g0 = canon(g0)
            if g0 not in index:
                add(g0, -1)
        n = len(model.names)
        shifts, masks = model.shift, model.mask
        simple, live = tables.simple, tables.live
        rare = [
            tuple(bool(c or u or e) for c, u, e in zip(cx, un, er, strict=True))
            for cx, un, er in zip(tables.complex, tables.unant, tables.errors, strict=True)
        ]
        transitions = 0
        head = 0
        level_end = len(states)
        limit = self.limit
        last_report = t0
        while head < len(states):
            if head == level_end:
                self.depth += 1
                level_end = len(states)
            if progress is not None and head & 0x3FFF == 0:
                now = time.perf_counter()
                if now - last_report >= 0.5:
                    progress(Progress(len(states), head, self.depth, now - t0))
                    last_report = now
            g = states[head]
            if self.ample is not None and self.ample.expand(self, g, head):
                if not self.complete:
                    break
                head += 1
                continue
            alive = False
            flagged = False
            for d in range(n):
                lid = (g >> shifts[d]) & masks[d]
                if live[d][lid]:
                    alive = True
                for delta in simple[d][lid]:
                    h = g ^ delta
                    if canon is not None:
                        h = canon(h)
                    transitions += 1
                    if h not in index:
                        if len(states) == limit:
                            self.complete = False
                            break
                        add(h, head)
                    if keep_edges:
                        src.append(head)
                        dst.append(index[h])
                if rare[d][lid]:
                    moved, unanticipated = self._rare(g, head, d, lid)
                    alive = alive or moved
                    flagged = flagged or unanticipated
                if not self.complete:
                    break
            if not self.complete:
                break
            if flagged:
                self.unant_states += 1
            if not alive:
                self.deadlocks.append(head)
            head += 1
        self.transitions += transitions

    def _rare(self, g: int, head: int, d: int, lid: int) -> tuple[bool, bool]:
        """Device ``d`` in local state ``lid`` of ``g``: run its cascading stimuli, count
        its unanticipated inputs and raising guards. Whether a stimulus happened, and
        whether an unanticipated input was met."""
        return self._cascades(g, head, d, lid), self._observe(g, head, d, lid)

    def _observe(self, g: int, head: int, d: int, lid: int) -> bool:
        """Count device ``d``'s unanticipated inputs and raising guards in ``g`` (state
        number ``head``); whether an unanticipated input was met."""
        model = self.model
        flagged = False
        for _i, s in self.tables.unant[d][lid]:
            if s.when >= 0:
                when = model.when[s.when]
                if when is not None and not when(g):
                    continue
            key2 = (d, lid, s.event, s.kind)
            self.unant_count[key2] = self.unant_count.get(key2, 0) + 1
            self.unant_first.setdefault(key2, head)
            flagged = True
        for s in self.tables.errors[d][lid]:
            if not model.offered(s, g):
                continue
            key = (d, model.spaces[d].state_of(lid), s.event)
            self.error_count[key] = self.error_count.get(key, 0) + 1
            self.errors.setdefault(key, (head, s, -1, lid, -1))
        return flagged

    def expand_cluster(
        self, g: int, head: int, lids: list[int], members: int, *, observe: bool = True
    ) -> None:
        """Expand ``g`` through the stimuli of the devices in the bit set ``members``
        alone (rule 4); every device's unanticipated inputs and raising guards are
        still counted (unless ``observe`` is false: they were)."""
        simple, index = self.tables.simple, self.index
        flagged = False
        for d, lid in enumerate(lids):
            if members >> d & 1:
                for delta in simple[d][lid]:
                    h = g ^ delta
                    self.transitions += 1
                    if h not in index:
                        if len(self.states) == self.limit:
                            self.complete = False
                            return
                        self.add(h, head)
                    if self.keep_edges:
                        self.src.append(head)
                        self.dst.append(index[h])
                if self.tables.complex[d][lid]:
                    self._cascades(g, head, d, lid)
                    if not self.complete:
                        return
            if observe and (self.tables.unant[d][lid] or self.tables.errors[d][lid]):
                flagged = self._observe(g, head, d, lid) or flagged
        if flagged:
            self.unant_states += 1

    def expand_rest(self, head: int, members: int) -> None:
        """Expand state number ``head``, once expanded through the cluster ``members``
        alone, through every other device's stimuli too (the cycle proviso of
        :mod:`statectl.cell.explore.ample`); what it met there was counted then."""
        g = self.states[head]
        model = self.model
        lids = [(g >> model.shift[d]) & model.mask[d] for d in range(len(model.names))]
        others = ~members & ((1 << len(lids)) - 1)
        self.expand_cluster(g, head, lids, others, observe=False)

    def _cascades(self, g: int, head: int, d: int, lid: int) -> bool:
        """The stimuli whose links fire (or that wait on ``when``), by the full cascade of
        :meth:`Composed.successors`; notes what the deliveries meet. Whether any happened."""
        model, index, states = self.model, self.index, self.states
        alive = False
        for i, s in self.tables.complex[d][lid]:
            if s.when >= 0:
                when = model.when[s.when]
                if when is not None and not when(g):
                    continue
            for h, bad, livelock in model.successors(g, s):
                alive = True
                for t, tlid, event, link in bad:
                    key = (t, model.spaces[t].state_of(tlid), event)
                    if link < 0:  # the delivery's guard raised (compose._bad)
                        self.error_count[key] = self.error_count.get(key, 0) + 1
                        self.errors.setdefault(key, (head, s, h, tlid, ~link))
                        continue
                    self.unhandled_count[key] = self.unhandled_count.get(key, 0) + 1
                    if key not in self.unhandled:
                        self.unhandled[key] = (head, s, h)
                if livelock and i not in self.livelocks:
                    self.livelocks[i] = (head, s)
                if self.canon is not None:
                    h = self.canon(h)
                if h == g:
                    continue
                self.transitions += 1
                if h not in index:
                    if len(states) == self.limit:
                        self.complete = False
                        break
                    self.add(h, head)
                if self.keep_edges:
                    self.src.append(head)
                    self.dst.append(index[h])
        return alive
