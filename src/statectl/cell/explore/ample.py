"""Partial-order reduction: where the checked properties cannot tell the orders of
independent steps apart, the search expands one cluster of devices and not the rest.

Rules:
1. A *cluster* is a set D of devices; its *ample set* in a global state g is every
   stimulus of D that happens in g. D is *closed* in g (condition C1) when no stimulus
   of a device outside D, from any state reachable from g without a step of D, depends
   on a stimulus of D: it neither changes nor reads a device of D, and D's stimuli
   neither change nor read a device outside D. A link event delivered into D counts
   only when it is not *inert* (ignored, no change, no link fired, nothing reported)
   in the device's local state now or in one it can be in after one step of D.
   ``needs[d][lid]`` is the devices that must join d in local state lid for that,
   from tables built once; a cluster is the closure of one device under it.
2. C0: the ample set is not empty. C2: no ample step changes the value of an ``In()``
   atom of an invariant. C3, the breadth-first cycle proviso: no ample step leads back
   to the state itself or to a state expanded before it through a cluster (a step
   back to a fully expanded state is allowed); otherwise another cluster is tried,
   then the state is expanded in full. Every cycle of the reduced graph has a step
   from a state to one stored no later (numbers cannot grow all the way round), and
   one of those two states is fully expanded.
3. What it keeps, exactly: deadlocks (C0, C1); invariants (C1-C3); what a stimulus's
   cascade meets (unhandled link events, guard errors, livelocks: everything a cascade
   reads is in its footprint, so an independent step never changes what it meets); the
   device states reached (a step that enters one is never commuted past); raising
   guards and unanticipated inputs of outside stimuli (read off every stored state).
   Recovery ("can always reach") is branching and is not kept: a cell with recovery
   properties is searched in full (:func:`reducible`).
4. Traces and counts are the reduced graph's: a trace is not shortest, a count is over
   the states stored; :func:`statectl.cell.explore.search.explore` searches a failing
   cell again in full to give shortest traces.
"""

from __future__ import annotations

from array import array
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING

from statectl.cell.explore.compose import Composed, Stimulus
from statectl.cell.explore.conditions import foreign_leaf
from statectl.cell.explore.local import Reaction
from statectl.cell.model import Cell, GlobalExpr
from statectl.kernel.semantics import Unhandled

if TYPE_CHECKING:
    from statectl.cell.explore.search import _Tables
    from statectl.cell.explore.walk import Walk

__all__ = ["Ample", "reducible"]

#: How many clusters a state tries before it is expanded in full (C2 or C3 refused them).
TRIES = 4


def reducible(cell: Cell) -> str:
    """Why partial-order reduction cannot be used on ``cell`` ("" when it can)."""
    if cell.recovery:
        return "recovery properties are judged over the full graph"
    if len(cell.devices) < 2:
        return "one device"
    return ""


def _bits(model: Composed, refs: Iterable[tuple[str, str]]) -> int:
    out = 0
    for device, _state in refs:
        if device in model.position:
            out |= 1 << model.position[device]
    return out


def _expr_bits(model: Composed, expr: GlobalExpr | None) -> int:
    return 0 if expr is None else _bits(model, expr.refs)


def _cond_bits(model: Composed, o: Reaction) -> int:
    """The other devices whose state decides whether outcome ``o`` is possible."""
    refs = (foreign_leaf(leaf) for leaf, _value in o.choices)
    return _bits(model, (r for r in refs if r is not None))


class Ample:
    """The tables of rule 1 and the choice of an ample set per state (rules 2 and 3)."""

    def __init__(self, model: Composed, tables: _Tables, invariants: Iterable[GlobalExpr]) -> None:
        self.model = model
        self.tables = tables
        n = len(model.names)
        self.n = n
        self.reduced = 0  # states expanded through a cluster smaller than the cell
        #: per state number expanded so far: the cluster it was expanded through (0: all)
        self.members = array("q")
        self.mine: list[list[Stimulus]] = [[] for _ in range(n)]
        for s in model.stimuli:
            self.mine[s.device].append(s)
        self.inert_link = tuple(self._inert_everywhere(k) for k in range(len(model.links)))
        self.reads, self.writes, after = self._link_footprints()
        self.up = self._upstream(after)
        self.readers = self._readers()
        self.needs = tuple(
            tuple(self._needs(d, lid) for lid in range(model.mask[d] + 1)) for d in range(n)
        )
        self.maybe = tuple(
            tuple(bool(lv or cx) for lv, cx in zip(live, cx_, strict=True))
            for live, cx_ in zip(tables.live, tables.complex, strict=True)
        )
        self.visible = self._visible(list(invariants))

    # -- static tables ---------------------------------------------------------------------

    def _inert(self, t: int, lid: int, event: str, k: int) -> bool:
        """Whether link ``k`` delivering ``event`` to device ``t`` in ``lid`` does nothing
        anyone can see: no change, no link fired, nothing reported, no other device read."""
        harmless = self.model.harmless[k]
        for target, happens, why, fired, cond in self.model.moves(t, lid, event, k):
            if cond is not None:
                return False
            if happens:
                if target != lid or fired:
                    return False
            elif why is Unhandled.GUARD_ERROR or (why is Unhandled.NO_TRANSITION and not harmless):
                return False
        return True

    def _inert_everywhere(self, k: int) -> bool:
        model = self.model
        if k in model.dropped:
            return False
        t = model.link_target[k]
        event = model.links[k].event
        return all(self._inert(t, lid, event, k) for lid in range(len(model.spaces[t].snapshots)))

    def _into(self, k: int) -> list[tuple[int, str]]:
        """The deliveries link ``k`` may make: its event to its target, and on a node link
        that drops, the ``dropped`` event back to its source."""
        model = self.model
        out = [(model.link_target[k], model.links[k].event)]
        notify = model.dropped.get(k)
        if notify is not None:
            out.append(notify)
        return out

    def _link_footprints(self) -> tuple[list[int], list[int], list[set[int]]]:
        """Per link: the devices a cascade through it may read, may change, and the
        links its deliveries may fire."""
        model = self.model
        nl = len(model.links)
        reads, writes = [0] * nl, [0] * nl
        after: list[set[int]] = [set() for _ in range(nl)]
        for k in range(nl):
            if self.inert_link[k]:
                continue
            reads[k] = _expr_bits(model, model.links[k].guard)
            for t, event in self._into(k):
                writes[k] |= 1 << t
                for lid in range(len(model.spaces[t].snapshots)):
                    for o in model.outcomes(t, lid, event, k):
                        reads[k] |= _cond_bits(model, o)
                        after[k].update(i for i in model.fires(t, o) if not self.inert_link[i])
        changed = True
        while changed:
            changed = False
            for k in range(nl):
                r, w = reads[k], writes[k]
                for i in after[k]:
                    r |= reads[i]
                    w |= writes[i]
                if (r, w) != (reads[k], writes[k]):
                    reads[k], writes[k], changed = r, w, True
        return reads, writes, after

    def _upstream(self, after: list[set[int]]) -> list[int]:
        """Per link: the devices whose stimuli may start a cascade that fires it (its
        source, and upstream of every link whose delivery may fire it)."""
        model = self.model
        nl = len(model.links)
        up = [1 << model.position[k.source] for k in model.links]
        changed = True
        while changed:
            changed = False
            for i in range(nl):
                for k in after[i]:
                    if up[k] | up[i] != up[k]:
                        up[k] |= up[i]
                        changed = True
        return up

    def _stimulus_reads(self, s: Stimulus, lid: int) -> tuple[int, int]:
        """What stimulus ``s`` of its device in ``lid`` reads (its ``when``, the other
        devices its guards read, its cascade) and the devices it may change."""
        model = self.model
        d = s.device
        reads = _expr_bits(model, model.cell.environment[s.when].when) if s.when >= 0 else 0
        writes = 1 << d
        for o in model.outcomes(d, lid, s.event, model.via(s)):
            reads |= _cond_bits(model, o)
            if o.happens:
                for k in model.fires(d, o):
                    if not self.inert_link[k]:
                        reads |= self.reads[k]
                        writes |= self.writes[k]
        return reads, writes

    def _readers(self) -> list[int]:
        """Per device: the devices whose stimuli read its state (``when``, guards over
        ``In()``, link guards on their cascades)."""
        model = self.model
        out = [0] * self.n
        for d in range(self.n):
            for lid in range(len(model.spaces[d].snapshots)):
                for s in self.mine[d]:
                    reads, _ = self._stimulus_reads(s, lid)
                    for e in range(self.n):
                        if reads >> e & 1:
                            out[e] |= 1 << d
        for k in range(len(model.links)):
            for e in range(self.n):
                if self.reads[k] >> e & 1:
                    out[e] |= self.up[k]
        return out

    def _post(self, d: int, lid: int) -> set[int]:
        """The local states device ``d`` may be in after one global step from ``lid``."""
        model = self.model
        seen = {lid}
        for s in self.mine[d]:
            seen.update(o.target for o in model.outcomes(d, lid, s.event, model.via(s)))
        incoming = [(k, ev) for k in range(len(model.links)) for t, ev in self._into(k) if t == d]
        todo = list(seen)
        while todo:
            here = todo.pop()
            for k, ev in incoming:
                for o in model.outcomes(d, here, ev, k):
                    if o.happens and o.target not in seen:
                        seen.add(o.target)
                        todo.append(o.target)
        return seen

    def _needs(self, d: int, lid: int) -> int:
        """Rule 1: the devices that must be in a cluster with ``d`` in ``lid``."""
        model = self.model
        if lid >= len(model.spaces[d].snapshots):
            return 0
        need = self.readers[d]
        for s in self.mine[d]:
            reads, writes = self._stimulus_reads(s, lid)
            need |= reads | writes
        post = self._post(d, lid)
        for k in range(len(model.links)):
            for t, ev in self._into(k):
                if t == d and not all(self._inert(d, here, ev, k) for here in post):
                    need |= self.up[k]
        return need & ~(1 << d)

    def _visible(self, invariants: list[GlobalExpr]) -> tuple[tuple[int, ...] | None, ...]:
        """Per device: per local id, which of the invariants' ``In()`` atoms over it hold."""
        model = self.model
        atoms: list[list[str]] = [[] for _ in range(self.n)]
        for expr in invariants:
            for device, state in expr.refs:
                if device in model.position and state not in atoms[model.position[device]]:
                    atoms[model.position[device]].append(state)
        out: list[tuple[int, ...] | None] = []
        for d, mine in enumerate(atoms):
            if not mine:
                out.append(None)
                continue
            tables = [model.padded(d, model.spaces[d].states_in(a)) for a in mine]
            out.append(
                tuple(
                    sum(1 << j for j, t in enumerate(tables) if t[lid])
                    for lid in range(model.mask[d] + 1)
                )
            )
        return tuple(out)

    # -- per state ---------------------------------------------------------------------

    def clusters(self, lids: list[int], moved: int) -> Iterator[int]:
        """Closed clusters smaller than the cell with some stimulus possible (at most
        :data:`TRIES`), each computed only when the one before would not do: first those
        of the devices in the bit set ``moved`` (those the step into this state changed:
        a device that left its cycle goes round it before another one leaves, so the
        others' states are not multiplied), a device alone before a larger cluster."""
        needs, maybe = self.needs, self.maybe
        seeds = [d for d in range(self.n) if maybe[d][lids[d]]]
        first = [d for d in seeds if moved >> d & 1] + [d for d in seeds if not moved >> d & 1]
        tried = 0
        for d in sorted(first, key=lambda d: bool(needs[d][lids[d]]) + 2 * (not moved >> d & 1)):
            members = self._closure(d, lids)
            if members:
                yield members
                tried += 1
                if tried == TRIES:
                    return

    def _closure(self, d: int, lids: list[int]) -> int:
        """The cluster of device ``d`` (rule 1) as a bit set; 0 if it is the whole cell."""
        needs = self.needs
        full = (1 << self.n) - 1
        members = 1 << d
        todo = [d]
        while todo:
            e = todo.pop()
            more = needs[e][lids[e]] & ~members
            members |= more
            while more:
                low = more & -more
                todo.append(low.bit_length() - 1)
                more ^= low
        return 0 if members == full else members

    def successors(self, g: int, lids: list[int], members: int) -> list[int]:
        """The states the ample set of cluster ``members`` leads to from ``g``."""
        model, tables = self.model, self.tables
        out: list[int] = []
        for d in range(self.n):
            if not members >> d & 1:
                continue
            lid = lids[d]
            out.extend(g ^ delta for delta in tables.simple[d][lid])
            for _i, s in tables.complex[d][lid]:
                if model.offered(s, g):
                    out.extend(h for h, _bad, _livelock in model.successors(g, s))
        return out

    def acceptable(self, walk: Walk, head: int, lids: list[int], hs: list[int]) -> list[int] | None:
        """C0, C2 and C3 (rule 2) for the ample successors ``hs`` of state ``head``: the
        states stored before it through a cluster that they lead back to (to expand in
        full), or ``None`` when the cluster will not do."""
        if not hs:
            return None
        index, model, visible, partial = walk.index, self.model, self.visible, self.members
        assert isinstance(index, dict), "a walk under the reduction numbers its states"
        back: list[int] = []
        for h in hs:
            j = index.get(h)
            if j == head:
                return None
            if j is not None and j < head and partial[j]:
                back.append(j)
            for d, vis in enumerate(visible):
                if vis is not None and vis[lids[d]] != vis[(h >> model.shift[d]) & model.mask[d]]:
                    return None
        return back

    def expand(self, walk: Walk, g: int, head: int) -> bool:
        """Expand state number ``head`` through a cluster if one is acceptable; ``False``
        when the state must be expanded in full (nothing was stored then)."""
        model = self.model
        lids = [(g >> model.shift[d]) & model.mask[d] for d in range(self.n)]
        p = walk.parent[head]
        diff = g ^ walk.states[p] if p >= 0 else 0
        moved = 0
        for d in range(self.n):
            if diff >> model.shift[d] & model.mask[d]:
                moved |= 1 << d
        for members in self.clusters(lids, moved):
            hs = self.successors(g, lids, members)
            back = self.acceptable(walk, head, lids, hs)
            if back is not None:
                self.reduced += 1
                self.members.append(members)
                walk.expand_cluster(g, head, lids, members)
                for j in back:
                    if self.members[j] and walk.complete:
                        self.reduced -= 1
                        walk.expand_rest(j, self.members[j])
                        self.members[j] = 0
                return True
        self.members.append(0)
        return False
