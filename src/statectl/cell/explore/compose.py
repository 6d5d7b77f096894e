"""The composed model of a cell: global states as packed integers, stimuli and cascades.

Rules:
1. A global state is the tuple of the devices' local ids, packed into one int
   (``bits`` per device, device 0 in the low bits); a step replaces one field.
2. One global step is one *stimulus* (an environment command, a fault in a
   monitored state, or a device's completion) and everything it causes: the
   stimulated device steps; every link whose trigger matches that step and
   whose guard holds in the resulting global state queues its event; queued
   events are delivered first in, first out, each one a device step that may
   fire links in turn, until nothing is queued (run-to-completion of the cell).
3. A stimulus is *enabled* in a global state when its ``when`` holds, it is a
   fault an active monitor of the device raises (``observers.extract``, as the
   runtime's monitors; or it is a command or a completion), and the device has a
   row for it there; it *happens* when some
   outcome handles it. Free choices give several successors. A completion is the
   device's own report (``REPORT``): offered only while an API call it completes
   is pending on the device (:mod:`statectl.kernel.semantics.calls`, the twin's
   model), and it settles that call; a timeout while its state is active; an
   ``unasked`` completion wherever the device handles it.
4. An event a link delivers to a device state that neither handles nor ignores
   it is reported (the event is then dropped, as the runtime drops it). A
   cascade longer than :data:`MAX_DELIVERIES` is a link livelock.
5. Global expressions compile to plain functions of the packed state; the
   source was checked by :func:`statectl.cell.model.parse_global`, and only ``In()``
   calls are rewritten into table lookups.
"""

from __future__ import annotations

import ast
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from statectl.cell.explore.conditions import UNTRACKED, assumptions, foreign_leaf, under_link
from statectl.cell.explore.deferred import DEFERRED
from statectl.cell.explore.local import LocalSpace, Reaction
from statectl.cell.explore.nodes import crossing, peer_lost
from statectl.cell.explore.timeouts import timeout_events, timing_out
from statectl.cell.links import CellLinkRules, Triggers
from statectl.cell.model import Cell, GlobalExpr, InputKind
from statectl.kernel.model import EventKind
from statectl.kernel.semantics import Unhandled

__all__ = ["MAX_DELIVERIES", "REPORT", "Branch", "Composed", "Delivery", "Predicate", "Stimulus"]

MAX_DELIVERIES = 256
#: The ``link`` argument of :meth:`Composed.outcomes` for a device's own report (rule 3).
REPORT = -2

Predicate = Callable[[int], bool]


@dataclass(frozen=True, slots=True)
class Stimulus:
    """Something from outside the cell's links: ``kind`` to ``device`` with ``event``."""

    kind: InputKind
    device: int
    event: str
    when: int = -1  # index of the environment entry whose ``when`` guards it, else -1

    def label(self, names: Sequence[str]) -> str:
        return f"{self.kind.value}: {names[self.device]}.{self.event}"


@dataclass(frozen=True, slots=True)
class Delivery:
    """One event reaching one device, and what the device did with it."""

    sender: str  # a device name, or "environment"
    receiver: str
    event: str
    via: str  # "environment", "fault", "completion" or the link's label
    before: str
    after: str
    unhandled: Unhandled | None  # None: handled
    notifies: tuple[str, ...] = ()
    choices: tuple[tuple[str, bool], ...] = ()
    #: "lost": a lossy link's event never arrived; "overtaken": a delayed link's event
    #: was put behind the events queued after it (docs/cells.md, distribution)
    fate: str = ""
    #: what taking this way assumes beyond the model (conditions.assumptions): a trace
    #: with any such delivery may not be reproducible on the devices
    assumed: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Branch:
    """One way a stimulus can play out: the state reached and what went wrong on the way."""

    state: int
    deliveries: tuple[Delivery, ...]
    #: (device, local id, event, link); ``~link`` (negative) when the delivery's guard
    #: raised (a guard error) instead of finding no transition
    unhandled: tuple[tuple[int, int, str, int], ...]
    livelock: bool = False


#: One outcome of a device step: target local id, handled, why not handled (the
#: kernel's reason; None: handled), the links whose trigger it matches (their guards
#: still to be asked, :meth:`Composed.sends`), and the condition on the global state
#: before the step under which the outcome is possible (another device's state a
#: guard read; None: always).
Move = tuple[int, bool, Unhandled | None, tuple[int, ...], Predicate | None]


class _InRewriter(ast.NodeTransformer):
    def __init__(self, model: Composed) -> None:
        self.model = model
        self.tables: dict[str, tuple[bool, ...]] = {}

    def visit_Call(self, node: ast.Call) -> ast.AST:
        arg = node.args[0]
        assert isinstance(arg, ast.Constant)
        device, _, state = str(arg.value).partition(".")
        d = self.model.position[device]
        table = self.model.padded(d, self.model.spaces[d].states_in(state))
        key = f"t{len(self.tables)}"
        self.tables[key] = table
        lookup = ast.parse(
            f"{key}[(g >> {self.model.shift[d]}) & {self.model.mask[d]}]", mode="eval"
        ).body
        return ast.copy_location(lookup, node)


class Composed:
    """The cell compiled for search: local spaces, packing, stimuli and link tables."""

    def __init__(self, cell: Cell) -> None:
        self.cell = cell
        self.names: tuple[str, ...] = tuple(d.name for d in cell.devices)
        self.position = {n: i for i, n in enumerate(self.names)}
        by_chart: dict[int, LocalSpace] = {}
        spaces: list[LocalSpace] = []
        for d in cell.devices:
            spaces.append(LocalSpace(d.name, d.chart, calls=cell.completions))
            by_chart[id(d.chart)] = spaces[-1]
        self.spaces = tuple(spaces)
        self.bits = tuple(max(1, (len(s.snapshots) - 1).bit_length()) for s in self.spaces)
        shifts, at = [], 0
        for b in self.bits:
            shifts.append(at)
            at += b
        self.shift = tuple(shifts)
        self.mask = tuple((1 << b) - 1 for b in self.bits)
        self.width = at
        self.links = cell.links
        self.rules = CellLinkRules(cell.links)  # whether a link fires: statectl.cell.links
        self.link_target = tuple(self.position[k.target] for k in cell.links)
        self.link_guard: tuple[Predicate | None, ...] = tuple(
            self.predicate(k.guard) if k.guard else None for k in cell.links
        )
        self.when: tuple[Predicate | None, ...] = tuple(
            self.predicate(e.when) if e.when else None for e in cell.environment
        )
        self._fires: dict[tuple[int, Reaction], tuple[int, ...]] = {}
        self._moves: dict[tuple[int, int, str, int], tuple[Move, ...]] = {}
        self._conds: dict[tuple[int, Reaction], Predicate | None] = {}
        self.harmless = tuple(k.ignore_if_unhandled for k in cell.links)
        # nodes: (cell/nodes.py): a link to another node with on_peer_down: drop may lose
        # its event, and then sends its `dropped` event to the source (explore/nodes.py)
        self.node_of, self.dropped = crossing(cell, self.position)
        self.lossy = tuple(k.lossy or i in self.dropped for i, k in enumerate(cell.links))
        self.delayed = tuple(k.delayed for k in cell.links)
        self.distributed = any(self.lossy) or any(self.delayed)
        self.stimuli = self._stimuli()
        self.initial = self._initial()

    # -- packing ---------------------------------------------------------------------------

    def padded(self, d: int, table: tuple[bool, ...]) -> tuple[bool, ...]:
        return table + (False,) * (self.mask[d] + 1 - len(table))

    def local(self, g: int, d: int) -> int:
        return (g >> self.shift[d]) & self.mask[d]

    def replace(self, g: int, d: int, lid: int) -> int:
        return (g & ~(self.mask[d] << self.shift[d])) | (lid << self.shift[d])

    def decode(self, g: int) -> tuple[int, ...]:
        return tuple(self.local(g, d) for d in range(len(self.names)))

    def labels(self, g: int) -> tuple[str, ...]:
        return tuple(self.spaces[d].state_of(self.local(g, d)) for d in range(len(self.names)))

    def describe(self, g: int) -> str:
        return ", ".join(f"{n}={s}" for n, s in zip(self.names, self.labels(g), strict=True))

    def predicate(self, expr: GlobalExpr) -> Predicate:
        """Compile a checked global expression into a function of the packed state."""
        tree = ast.parse(expr.source, mode="eval")
        rewriter = _InRewriter(self)
        body = rewriter.visit(tree.body)
        fn = ast.Expression(
            ast.Lambda(ast.arguments([], [ast.arg("g")], None, [], [], None, []), body)
        )
        ast.fix_missing_locations(fn)
        namespace: dict[str, object] = {"__builtins__": {}, **rewriter.tables}
        compiled: Predicate = eval(compile(fn, f"<{expr.source}>", "eval"), namespace)
        return compiled

    # -- stimuli and links -----------------------------------------------------------------

    def _stimuli(self) -> tuple[Stimulus, ...]:
        out: list[Stimulus] = []
        for i, e in enumerate(self.cell.environment):
            out.append(Stimulus(e.kind, self.position[e.device], e.event, i if e.when else -1))
        lost = peer_lost(self.cell, self.position, self.node_of)
        out.extend(Stimulus(InputKind.PEER_LOST, d, e) for d, e in lost)
        if self.cell.completions:
            for d, space in enumerate(self.spaces):
                for ev in space.events:
                    if space.kind[ev] is EventKind.COMPLETION:
                        out.append(Stimulus(InputKind.COMPLETION, d, ev))
        for d, space in enumerate(self.spaces):  # a state's timeout: the device raises it
            out.extend(Stimulus(InputKind.COMPLETION, d, ev) for ev in timeout_events(space.chart))
        return tuple(dict.fromkeys(out))

    def _initial(self) -> tuple[int, ...]:
        states = [0]
        for d, space in enumerate(self.spaces):
            states = [self.replace(g, d, o.target) for g in states for o in space.initial]
        return tuple(dict.fromkeys(states))

    def enabled_locally(self, s: Stimulus, lid: int) -> bool:
        """Rule 3 without ``when``: the device side of whether ``s`` can be offered."""
        space = self.spaces[s.device]
        if s.kind is InputKind.FAULT and s.event not in space.raises[lid]:
            return False  # no active monitor raises it (the runtime's monitors: observers)
        if s.kind is InputKind.COMPLETION:
            return any(o.happens for o in self.outcomes(s.device, lid, s.event, REPORT))
        return True

    @staticmethod
    def via(s: Stimulus) -> int:
        """The ``link`` argument of :meth:`outcomes` for stimulus ``s``."""
        return REPORT if s.kind is InputKind.COMPLETION else -1

    def _reported(self, d: int, lid: int, event: str) -> tuple[Reaction, ...]:
        """Rule 3: ``event`` as device ``d`` raises it itself in ``lid``."""
        space = self.spaces[d]
        if timing_out(space, lid, event):
            return space.outcomes(lid, event)
        if not self.cell.completions or space.kind[event] is not EventKind.COMPLETION:
            return ()
        reports = space.reports(lid, event)
        if space.unasked(event):
            return tuple(dict.fromkeys((*reports, *space.outcomes(lid, event))))
        return reports

    def fires(self, d: int, outcome: Reaction) -> tuple[int, ...]:
        """Indices of the links whose trigger matches device ``d``'s step ``outcome``
        (statectl.cell.links rules 1-4, as every host of the cell decides it)."""
        key = (d, outcome)
        found = self._fires.get(key)
        if found is None:
            found = ()
            if outcome.handled:
                offered = Triggers(outcome.entered, outcome.events)
                found = self.rules.matching(self.names[d], offered)
            self._fires[key] = found
        return found

    def sends(self, fired: tuple[int, ...], g: int) -> tuple[tuple[int, str, int], ...]:
        """The deliveries (target, event, link) the links ``fired`` queue in the state
        ``g`` after the step: those whose guards hold (statectl.cell.links rule 5)."""
        if not fired:
            return ()
        due = self.rules.holding(fired, self.link_guard, lambda: g)
        return tuple((self.link_target[i], self.links[i].event, i) for i in due)

    def _queue(self, g: int, d: int, outcome: Reaction) -> tuple[tuple[int, str, int], ...]:
        """The deliveries device ``d``'s step ``outcome`` queues, ``g`` the state after it."""
        return self.sends(self.fires(d, outcome), g)

    def condition(self, d: int, o: Reaction) -> Predicate | None:
        """When outcome ``o`` of device ``d`` is possible: the other devices' states its
        guards read (explore/conditions.py rule 1), as a function of the state before."""
        key = (d, o)
        if key in self._conds:
            return self._conds[key]
        parts: list[tuple[int, int, tuple[bool, ...], bool]] = []
        for leaf, value in o.choices:
            ref = foreign_leaf(leaf)
            if ref is None or ref[0] not in self.position:
                continue
            e = self.position[ref[0]]
            table = self.padded(e, self.spaces[e].states_in(ref[1]))
            parts.append((self.shift[e], self.mask[e], table, value))
        fn: Predicate | None = None
        if parts:
            frozen = tuple(parts)

            def fn(g: int) -> bool:
                return all(table[(g >> sh) & mk] is v for sh, mk, table, v in frozen)

        self._conds[key] = fn
        return fn

    def outcomes(self, d: int, lid: int, event: str, link: int = -1) -> tuple[Reaction, ...]:
        """Device ``d``'s outcomes; delivered by ``link``, those its data rules out dropped
        (explore/conditions.py rule 2)."""
        if link == REPORT:
            return self._reported(d, lid, event)
        outs = self.spaces[d].outcomes(lid, event)
        if link < 0 or self.links[link].forward_data or event != self.links[link].event:
            return outs
        data = self.links[link].data
        space = self.spaces[d]
        kept = (under_link(space, lid, o, event, data) for o in outs)
        return tuple(dict.fromkeys(o for o in kept if o is not None))

    def _pop(
        self, pending: tuple[tuple[int, str, int], ...]
    ) -> tuple[int, str, int, bool, tuple[tuple[int, str, int], ...]]:
        """The next queued delivery: target, event, link, overtaken, and the rest."""
        (t, event, link), rest = pending[0], pending[1:]
        return (t, event, link if link >= 0 else ~link, link < 0, rest)

    def _fates(
        self, pending: tuple[tuple[int, str, int], ...]
    ) -> list[tuple[str, tuple[tuple[int, str, int], ...]]]:
        """What distribution may do to the next delivery instead (lost, overtaken)."""
        (t, event, link), rest = pending[0], pending[1:]
        out: list[tuple[str, tuple[tuple[int, str, int], ...]]] = []
        real = link if link >= 0 else ~link
        if event != self.links[real].event:
            return out  # a `dropped` event: it stays on its own node
        if link >= 0 and self.delayed[real] and rest:
            out.append(("overtaken", (*rest, (t, event, ~link))))
        if self.lossy[real]:
            notify = self.dropped.get(real)
            # nodes: the link's `dropped` event takes the lost event's place in the queue
            out.append(("lost", rest if notify is None else ((*notify, link), *rest)))
        return out

    def branches(self, g: int, s: Stimulus, detail: bool = False) -> list[Branch]:
        """Every way stimulus ``s`` plays out from ``g`` (rule 2); empty if it does not happen."""
        d = s.device
        lid = self.local(g, d)
        out: list[Branch] = []
        Work = tuple[
            int,
            tuple[tuple[int, str, int], ...],
            tuple[Delivery, ...],
            tuple[tuple[int, int, str, int], ...],
            int,
        ]
        work: list[Work] = []
        for o in self.outcomes(d, lid, s.event, self.via(s)):
            if not o.happens:
                continue
            cond = self.condition(d, o)
            if cond is not None and not cond(g):
                continue
            g1 = self.replace(g, d, o.target)
            log: tuple[Delivery, ...] = ()
            if detail:
                log = (self._stimulus_delivery(s, lid, o),)
            work.append((g1, self._queue(g1, d, o), log, (), 1))
        while work:
            g1, pending, log, bad, count = work.pop()
            if not pending:
                out.append(Branch(g1, log, bad))
                continue
            if count > MAX_DELIVERIES:
                out.append(Branch(g1, log, bad, livelock=True))
                continue
            for fate, later in self._fates(pending):
                t0, ev0, l0 = pending[0]
                k0 = self.links[l0 if l0 >= 0 else ~l0]
                lost: tuple[Delivery, ...] = ()
                if detail and fate == "lost":
                    here = self.spaces[t0].state_of(self.local(g1, t0))
                    lost = (
                        Delivery(k0.source, k0.target, ev0, k0.label, here, here, None, fate=fate),
                    )
                work.append((g1, later, log + lost, bad, count + (fate == "lost")))
            t, event, link, overtaken, rest = self._pop(pending)
            tlid = self.local(g1, t)
            for o in self.outcomes(t, tlid, event, link):
                cond = self.condition(t, o)
                if cond is not None and not cond(g1):
                    continue
                g2 = self.replace(g1, t, o.target) if o.handled else g1
                more = self._queue(g2, t, o) if o.handled else ()
                bad2 = _bad(bad, t, tlid, event, link, o.unhandled, self.harmless[link])
                log2 = log
                if detail:
                    log2 = (*log, self._link_delivery(t, tlid, event, link, overtaken, o))
                work.append((g2, rest + more, log2, bad2, count + 1))
        if not detail:
            return out
        return list(dict.fromkeys(out))

    # Traces only (``branches(detail=True)``): what each delivery shows, kept out of
    # the cascade so the search's own calls never build one.

    def _stimulus_delivery(self, s: Stimulus, lid: int, o: Reaction) -> Delivery:
        """The stimulus itself as a trace's first delivery (from the environment, or from
        the device when it reports a completion)."""
        d = s.device
        space = self.spaces[d]
        sender = self.names[d] if s.kind is InputKind.COMPLETION else "environment"
        return Delivery(
            sender,
            self.names[d],
            s.event,
            s.kind.value,
            space.state_of(lid),
            space.state_of(o.target),
            o.unhandled,
            o.notifies,
            o.choices,
            assumed=assumptions(space, o, False),
        )

    def _link_delivery(
        self, t: int, tlid: int, event: str, link: int, overtaken: bool, o: Reaction
    ) -> Delivery:
        """A link's delivery to device ``t`` as a trace shows it; a link's ``dropped`` event
        goes back to its source."""
        k = self.links[link]
        tspace = self.spaces[t]
        back = event != k.event  # the link's `dropped` event, to its source
        return Delivery(
            k.target if back else k.source,
            self.names[t],
            event,
            f"{k.label} dropped" if back else k.label,
            tspace.state_of(tlid),
            tspace.state_of(o.target),
            o.unhandled,
            o.notifies,
            o.choices,
            "overtaken" if overtaken else "",
            assumptions(tspace, o, not k.forward_data and not back),
        )

    def moves(self, d: int, lid: int, event: str, link: int = -1) -> tuple[Move, ...]:
        """Device ``d``'s outcomes for ``event`` in ``lid``, with the links each would fire."""
        if link >= 0 and self.links[link].forward_data:
            link = -1
        key = (d, lid, event, link)
        found = self._moves.get(key)
        if found is None:
            found = tuple(
                (
                    o.target,
                    o.happens,
                    o.unhandled,
                    self.fires(d, o),
                    self.condition(d, o),
                )
                for o in self.outcomes(d, lid, event, link)
            )
            self._moves[key] = found
        return found

    def successors(
        self, g: int, s: Stimulus
    ) -> list[tuple[int, tuple[tuple[int, int, str, int], ...], bool]]:
        """:meth:`branches` without the delivery log, for the search's inner loop.

        The same ways in the same order, each as ``(state, unhandled, livelock)``;
        every step is a table lookup and integer arithmetic.
        """
        shift, mask = self.shift, self.mask
        harmless = self.harmless
        d = s.device
        lid = (g >> shift[d]) & mask[d]
        out: list[tuple[int, tuple[tuple[int, int, str, int], ...], bool]] = []
        work: list[
            tuple[int, tuple[tuple[int, str, int], ...], tuple[tuple[int, int, str, int], ...], int]
        ] = []
        for target, handled, _unhandled, fired, cond in self.moves(d, lid, s.event, self.via(s)):
            if handled and (cond is None or cond(g)):
                g1 = (g & ~(mask[d] << shift[d])) | (target << shift[d])
                pending = self.sends(fired, g1)
                work.append((g1, pending, (), 1))
        while work:
            g1, pending, bad, count = work.pop()
            if not pending:
                out.append((g1, bad, False))
                continue
            if count > MAX_DELIVERIES:
                out.append((g1, bad, True))
                continue
            if self.distributed:
                for fate, later in self._fates(pending):
                    work.append((g1, later, bad, count + (fate == "lost")))
            (t, event, link), rest = pending[0], pending[1:]
            if link < 0:
                link = ~link
            tlid = (g1 >> shift[t]) & mask[t]
            for target, handled, unhandled, fired, cond in self.moves(t, tlid, event, link):
                if cond is not None and not cond(g1):
                    continue
                if handled:
                    g2 = (g1 & ~(mask[t] << shift[t])) | (target << shift[t])
                    more = self.sends(fired, g2)
                else:
                    g2, more = g1, ()
                bad2 = _bad(bad, t, tlid, event, link, unhandled, harmless[link])
                work.append((g2, rest + more, bad2, count + 1))
        return out

    def assumes(self) -> tuple[str, ...]:
        """What the model assumes beyond what it tracks, anywhere (report rule 4)."""
        out: list[str] = []
        if any(space.free_guards for space in self.spaces):
            out.append(UNTRACKED)
        if any(space.chart.deferred for space in self.spaces):
            out.append(DEFERRED)
        return tuple(out)

    def offered(self, s: Stimulus, g: int) -> bool:
        """Whether ``s``'s ``when`` (if it has one) holds in ``g``. The search's inner
        loops test it inline, as this does, for speed."""
        when = self.when[s.when] if s.when >= 0 else None
        return when is None or bool(when(g))

    def enabled(self, g: int) -> list[Stimulus]:
        """The stimuli offered in ``g`` (rule 3), in the cell's order."""
        return [
            s
            for s in self.stimuli
            if self.enabled_locally(s, self.local(g, s.device)) and self.offered(s, g)
        ]


def _bad(
    bad: tuple[tuple[int, int, str, int], ...],
    t: int,
    lid: int,
    event: str,
    link: int,
    why: Unhandled | None,
    harmless: bool,
) -> tuple[tuple[int, int, str, int], ...]:
    """``bad`` and this delivery if it went wrong: a missed transition the link does not
    excuse, or a guard that raised (``~link``: no ``ignore_if_unhandled`` excuses it)."""
    if why is Unhandled.GUARD_ERROR:
        return (*bad, (t, lid, event, ~link))
    if why is Unhandled.NO_TRANSITION and not harmless:
        return (*bad, (t, lid, event, link))
    return bad
