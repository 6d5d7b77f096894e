"""Breadth-first search of a cell's global states, and the checks made over it.

Rules:
1. States are explored in breadth-first order from the initial global states,
   so the first time a property fails is at a shortest trace; each state keeps
   only its parent's number, and traces are rebuilt by re-running the one
   stimulus that links parent to child.
2. A stimulus whose every outcome fires no link and that has no ``when`` is a
   precomputed xor on the packed state; the rest run the cascade of
   :meth:`Composed.branches`.
3. A deadlock is a global state in which no stimulus happens (rule 3 of
   :mod:`statectl.cell.explore.compose`): every input would be ignored or refused.
4. Recovery is checked over the explored graph: a backward search from the goal
   states; a state where ``from`` holds that the search does not reach fails.
   With ``--max-states`` reached, deadlocks and recovery are not judged.
5. A step the kernel refuses because a guard raised (``Unhandled.GUARD_ERROR``,
   as the runtime refuses it) is a failure, whether a stimulus or a link delivers
   the event: never read as the guard being false.
6. ``max_states`` bounds the stored states; the report then says incomplete.
   ``statectl verify`` bounds it by :data:`DEFAULT_MAX_STATES` unless told otherwise,
   so a cell whose product is too big for memory ends with a report, not the OOM killer.
7. Unless told ``por=False``, the search uses partial-order reduction
   (:mod:`statectl.cell.explore.ample`) where the cell allows it; the verdicts are those
   of the full search. When the reduced search finds a failure, the cell is searched
   again in full, so that traces are shortest and counts are over every state; if that
   search stops at the bound before meeting every failure, the reduced report stands
   and says its traces are not shortest.
8. Unless told ``symmetry=False``, devices the cell cannot tell apart are stored once
   per orbit (:mod:`statectl.cell.explore.symmetry`); the verdicts are the full
   search's, traces stay shortest and concrete, per-device findings name one member
   of a group, and the report gives the full search's state count. A cell with such
   devices is reduced by symmetry alone: the two reductions are not combined (yet);
   when no link touches those devices, partial-order reduction is used instead (linear
   in their number where orbits grow as a polynomial).
"""

from __future__ import annotations

import resource
import time
from array import array
from collections.abc import Callable, Sequence
from dataclasses import replace
from itertools import pairwise
from math import prod

from statectl.cell.explore.ample import Ample, reducible
from statectl.cell.explore.compose import Branch, Composed, Predicate, Stimulus
from statectl.cell.explore.report import Finding, Kind, Report, Trace, TraceStep, Unanticipated
from statectl.cell.explore.symmetry import Symmetry, find_symmetry
from statectl.cell.explore.walk import Progress, Walk
from statectl.cell.model import Cell
from statectl.kernel.semantics import Unhandled

__all__ = ["DEFAULT_MAX_STATES", "Progress", "explore", "trace_to"]

#: The states ``statectl verify`` stores unless ``--max-states`` says otherwise: about
#: 2 GiB at some 110 bytes a state (a 12-Motor cell has 6**12, far past any memory).
DEFAULT_MAX_STATES = 20_000_000


def _peak_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


class _Tables:
    """Per device and local id: xor deltas, liveness, cascading and unanticipated stimuli."""

    def __init__(self, model: Composed) -> None:
        self.simple: list[tuple[tuple[int, ...], ...]] = []
        self.live: list[tuple[bool, ...]] = []
        self.complex: list[tuple[tuple[tuple[int, Stimulus], ...], ...]] = []
        self.unant: list[tuple[tuple[tuple[int, Stimulus], ...], ...]] = []
        # per device and local id: the stimuli some of whose outcomes are guard errors
        self.errors: list[tuple[tuple[Stimulus, ...], ...]] = []
        for d, space in enumerate(model.spaces):
            mine = [(i, s) for i, s in enumerate(model.stimuli) if s.device == d]
            simple: list[tuple[int, ...]] = []
            live: list[bool] = []
            cx: list[tuple[tuple[int, Stimulus], ...]] = []
            un: list[tuple[tuple[int, Stimulus], ...]] = []
            errs: list[tuple[Stimulus, ...]] = []
            for lid in range(model.mask[d] + 1):
                deltas: list[int] = []
                alive = False
                cxs: list[tuple[int, Stimulus]] = []
                uns: list[tuple[int, Stimulus]] = []
                err: list[Stimulus] = []
                if lid < len(space.snapshots):
                    for i, s in mine:
                        if not model.enabled_locally(s, lid):
                            continue
                        outs = model.outcomes(d, lid, s.event, model.via(s))
                        if any(o.unhandled is Unhandled.GUARD_ERROR for o in outs):
                            err.append(s)
                        handled = [o for o in outs if o.happens]
                        if not handled:
                            if outs and all(o.unhandled is Unhandled.NO_TRANSITION for o in outs):
                                uns.append((i, s))
                            continue
                        if (
                            s.when >= 0
                            or any(model.fires(d, o) for o in handled)
                            or any(model.condition(d, o) is not None for o in outs)
                        ):
                            cxs.append((i, s))
                            continue
                        alive = True
                        for o in handled:
                            if o.target != lid:
                                deltas.append((lid ^ o.target) << model.shift[d])
                simple.append(tuple(dict.fromkeys(deltas)))
                live.append(alive)
                cx.append(tuple(cxs))
                un.append(tuple(uns))
                errs.append(tuple(err))
            self.simple.append(tuple(simple))
            self.live.append(tuple(live))
            self.complex.append(tuple(cx))
            self.unant.append(tuple(un))
            self.errors.append(tuple(errs))


def trace_to(
    model: Composed,
    parent: array[int],
    states: Sequence[int],
    i: int,
    last: Stimulus | None = None,
    match: Callable[[object], bool] | None = None,
    sym: Symmetry | None = None,
) -> Trace:
    """The trace from the initial state to state ``i`` (then ``last``, if given)."""
    path: list[int] = []
    while i >= 0:
        path.append(states[i])
        i = parent[i]
    path.reverse()
    if sym is not None:
        path = _concrete(model, sym, path)
    steps: list[TraceStep] = []
    for g, h in pairwise(path):
        steps.append(_step_between(model, g, lambda br, h=h: br.state == h))
    if last is not None:
        steps.append(_step_between(model, path[-1], match or (lambda br: True), last))
    return Trace(model.names, model.labels(path[0]), tuple(steps))


def _concrete(model: Composed, sym: Symmetry, reps: list[int]) -> list[int]:
    """A run through the orbits of ``reps`` that ends in ``reps[-1]`` itself (rule 8):
    each step from the concrete state to one in the next orbit, then every state
    renamed so the last is the stored one (a renaming of a run is a run)."""
    run = [reps[0]]
    for rep in reps[1:]:
        g = run[-1]
        run.append(
            next(
                h
                for s in model.enabled(g)
                for h, _, _ in model.successors(g, s)
                if sym.canon(h) == rep
            )
        )
    rename = sym.align(run[-1], reps[-1])
    return [rename(g) for g in run]


def _step_between(
    model: Composed, g: int, ok: Callable[..., bool], only: Stimulus | None = None
) -> TraceStep:
    for s in model.enabled(g) if only is None else [only]:
        for br in model.branches(g, s, detail=True):
            if ok(br):
                return TraceStep(
                    s.kind, model.names[s.device], s.event, br.deliveries, model.labels(br.state)
                )
    raise AssertionError("no stimulus links two states of the explored graph")


def explore(
    cell: Cell,
    *,
    max_states: int | None = None,
    progress: Callable[[Progress], None] | None = None,
    model: Composed | None = None,
    por: bool = True,
    symmetry: bool = True,
) -> Report:
    """Explore the reachable global states of ``cell`` and check its properties (rule 7:
    through partial-order reduction unless ``por`` is false; rule 8: one state per
    orbit of interchangeable devices unless ``symmetry`` is false)."""
    model = model or Composed(cell)
    sym = find_symmetry(model) if symmetry else None
    if sym is not None and por and not reducible(cell) and _unlinked(cell, sym):
        sym = None  # devices no link touches: one order of their steps is linear, orbits are not
    reduce = por and sym is None and not reducible(cell)
    report = _search(cell, model, max_states, progress, reduce, sym)
    if not reduce or not report.failures or not report.reductions:
        return report
    full = _search(cell, model, max_states, progress, False, None)
    met = {(f.kind, f.name) for f in full.failures}
    if full.complete or met >= {(f.kind, f.name) for f in report.failures}:
        again = (
            f"partial-order reduction: the reduced search met a failure in "
            f"{report.states:,} states ({report.seconds:.2f} s); searched again in full "
            "for shortest traces"
        )
        return replace(full, reductions=(again,), seconds=report.seconds + full.seconds)
    return report


def _unlinked(cell: Cell, sym: Symmetry) -> bool:
    """Whether no link touches any interchangeable device: then partial-order reduction
    alone stores a number of states linear in the group, where symmetry stores a polynomial."""
    members = {name for grp in sym.groups for name in grp.names}
    return not any(k.source in members or k.target in members for k in cell.links)


def _search(
    cell: Cell,
    model: Composed,
    max_states: int | None,
    progress: Callable[[Progress], None] | None,
    reduce: bool,
    sym: Symmetry | None = None,
) -> Report:
    """One search of ``cell``, reduced or full, and the report read off it."""
    t0 = time.perf_counter()
    invariants: list[tuple[str, Predicate]] = [
        (inv.name, model.predicate(inv.expr)) for inv in cell.invariants
    ]
    tables = _Tables(model)
    ample = Ample(model, tables, [inv.expr for inv in cell.invariants]) if reduce else None
    walk = Walk(
        model,
        tables,
        invariants,
        keep_edges=bool(cell.recovery),
        max_states=max_states,
        ample=ample,
        symmetry=sym,
    )
    walk.run(progress, t0)
    seconds = time.perf_counter() - t0

    findings: list[Finding] = []
    properties: list[tuple[str, str]] = []
    _judge_deadlock_and_invariants(cell, walk, findings, properties)
    _judge_deliveries(walk, findings, properties)
    _judge_recovery(cell, walk, findings, properties)
    unreached, bound = _unreached(walk, sym)
    findings.extend(unreached)
    states, parent = walk.states, walk.parent
    full = sym.full_states(states) if sym is not None else None  # rule 8
    unants = tuple(
        Unanticipated(
            model.names[d],
            model.spaces[d].state_of(lid),
            event,
            kind,
            walk.unant_count[(d, lid, event, kind)],
            trace_to(model, parent, states, first, sym=sym),
        )
        for (d, lid, event, kind), first in walk.unant_first.items()
    )
    reductions = _reductions(walk, bound)
    return Report(
        cell=cell.name,
        path=cell.path,
        devices=tuple(
            (nm, len(sp.snapshots)) for nm, sp in zip(model.names, model.spaces, strict=True)
        ),
        states=len(states),
        transitions=walk.transitions,
        depth=walk.depth,
        complete=walk.complete,
        seconds=seconds,
        peak_bytes=_peak_bytes(),
        findings=tuple(findings),
        unanticipated=unants,
        unanticipated_states=walk.unant_states,
        free_guards=tuple(g for sp in model.spaces for g in sp.free_guards),
        properties=tuple(properties),
        relies=_relies(model, properties, findings),
        reductions=reductions + _symmetry_line(walk, full),
        shortest=not reductions,  # the unanticipated inputs' traces too (JSON)
        full_states=full,
    )


def _reductions(walk: Walk, bound: int) -> tuple[str, ...]:
    """The report's line on the reduction used, if a state was expanded in part."""
    if walk.ample is None or not walk.ample.reduced:
        return ()
    return (
        f"partial-order reduction: {walk.ample.reduced:,} of {len(walk.states):,} stored "
        f"states expanded through one cluster of devices; the full search stores at most "
        f"{bound:,} states (the product of each device's local states reached)",
    )


def _symmetry_line(walk: Walk, full: int | None) -> tuple[str, ...]:
    """The report's line on the symmetry reduction (rule 8), if one was used."""
    sym = walk.symmetry
    if sym is None or full is None:
        return ()
    return (
        f"symmetry: {len(walk.states):,} states stored, one per orbit of "
        f"{sym.describe()}; the full search stores {'' if walk.complete else 'at least '}"
        f"{full:,}; a finding about one device names one device of its group, its count "
        "is of stored states",
    )


def _verdict(walk: Walk, failed: bool) -> str:
    """A property fails on a witness; it holds only if the walk was complete."""
    if failed:
        return "fails"
    return "holds" if walk.complete else "unknown"


def _judge_deadlock_and_invariants(
    cell: Cell, walk: Walk, findings: list[Finding], properties: list[tuple[str, str]]
) -> None:
    """Rule 3 and the cell's invariants: the first (shortest) witness of each, and a count."""
    model, parent, states = walk.model, walk.parent, walk.states
    deadlocks = walk.deadlocks
    properties.append(("no deadlock", _verdict(walk, bool(deadlocks))))
    if deadlocks:
        first = deadlocks[0]
        findings.append(
            Finding(
                Kind.DEADLOCK,
                "deadlock",
                f"no input can change {model.describe(states[first])}",
                trace_to(model, parent, states, first, sym=walk.symmetry),
                len(deadlocks),
            )
        )
    violated = walk.violated
    for inv in cell.invariants:
        properties.append(
            (f"invariant {inv.name}: {inv.expr.source}", _verdict(walk, inv.name in violated))
        )
        if inv.name in violated:
            at = violated[inv.name]
            findings.append(
                Finding(
                    Kind.INVARIANT,
                    inv.name,
                    f"{inv.expr.source} is false in {model.describe(states[at])}",
                    trace_to(model, parent, states, at, sym=walk.symmetry),
                    walk.violations[inv.name],
                )
            )


def _judge_deliveries(
    walk: Walk, findings: list[Finding], properties: list[tuple[str, str]]
) -> None:
    """What links meet: an event nobody handles, a raising guard (rule 5), a livelock."""
    model, parent, states = walk.model, walk.parent, walk.states
    unhandled = walk.unhandled
    properties.append(
        ("every link-delivered event is handled or ignored", _verdict(walk, bool(unhandled)))
    )
    for key, (at, s, target) in unhandled.items():
        t, label, event = key
        name = model.names[t]
        findings.append(
            Finding(
                Kind.UNHANDLED,
                f"{name}.{event}",
                f"a link delivers {event!r} to {name} in {label}, which neither handles nor "
                "ignores it (a missed transition that shows only in interaction)",
                trace_to(model, parent, states, at, s, _shows(model, key, target), walk.symmetry),
                walk.unhandled_count[key],
            )
        )
    properties.append(("no guard raises", _verdict(walk, bool(walk.errors))))
    findings.extend(_guard_errors(walk))
    properties.append(("no link livelock", _verdict(walk, bool(walk.livelocks))))
    for at, s in walk.livelocks.values():
        findings.append(
            Finding(
                Kind.LIVELOCK,
                s.label(model.names),
                f"links keep delivering events after {s.label(model.names)}; "
                "more than 256 deliveries in one step",
                trace_to(model, parent, states, at, sym=walk.symmetry),
            )
        )


def _judge_recovery(
    cell: Cell, walk: Walk, findings: list[Finding], properties: list[tuple[str, str]]
) -> None:
    """Rule 4 over the stored edges; only a complete walk has all of them to judge by."""
    model, parent, states = walk.model, walk.parent, walk.states
    for rec in cell.recovery:
        failed_at, count = (-1, 0)
        if walk.complete:
            failed_at, count = _recovery(
                model,
                model.predicate(rec.target),
                model.predicate(rec.source) if rec.source else None,
                states,
                walk.src,
                walk.dst,
            )
        text = f"recovery {rec.name}: always able to reach {rec.target.source}"
        if rec.source is not None:
            text += f" from {rec.source.source}"
        properties.append((text, _verdict(walk, failed_at >= 0)))
        if failed_at >= 0:
            findings.append(
                Finding(
                    Kind.RECOVERY,
                    rec.name,
                    f"from {model.describe(states[failed_at])} no sequence of inputs reaches "
                    f"{rec.target.source}",
                    trace_to(model, parent, states, failed_at, sym=walk.symmetry),
                    count,
                )
            )


def _unreached(walk: Walk, sym: Symmetry | None = None) -> tuple[list[Finding], int]:
    """Each device state no stored global state has active (within the bound, if hit),
    a member of a symmetric group reaching what any member of its group does; and the
    product of the local states reached, a bound on the full search's states."""
    model = walk.model
    n = len(model.names)
    shifts, masks = model.shift, model.mask
    reached: list[set[int]] = [set() for _ in range(n)]
    for g in walk.states:
        for d in range(n):
            reached[d].add((g >> shifts[d]) & masks[d])
    if sym is not None:
        reached = [set().union(*(reached[e] for e in sym.reached(d))) for d in range(n)]
    findings: list[Finding] = []
    for d, space in enumerate(model.spaces):
        seen = {s for lid in reached[d] for s in space.active(lid)}
        for st in space.chart.states:
            if st.name not in seen:
                findings.append(
                    Finding(
                        Kind.UNREACHED,
                        f"{model.names[d]}.{st.name}",
                        f"device {model.names[d]} never enters {st.name} in this cell"
                        + ("" if walk.complete else " (within the bound)"),
                    )
                )
    return findings, prod(len(r) for r in reached)


def _shows(model: Composed, key: tuple[int, str, str], target: int) -> Callable[[object], bool]:
    """Match the branch that reaches ``target`` delivering the unhandled event ``key``."""

    def match(br: object) -> bool:
        assert isinstance(br, Branch)
        return br.state == target and any(
            (u[0], model.spaces[u[0]].state_of(u[1]), u[2]) == key for u in br.unhandled
        )

    return match


def _guard_errors(walk: Walk) -> list[Finding]:
    """Rule 5: each device, state and event whose guard raised, with its shortest trace.

    A stimulus refused outright ends the trace in the state it was offered in (no
    branch shows a refused stimulus); a link delivery ends with the step that made it.
    """
    model, parent, states, sym = walk.model, walk.parent, walk.states, walk.symmetry
    errors, count = walk.errors, walk.error_count
    out: list[Finding] = []
    for key, (at, s, target, lid, link) in errors.items():
        t, label, event = key
        name = model.names[t]
        bad = next((o for o in model.outcomes(t, lid, event, link) if o.failure), None)
        why = bad.failure if bad is not None else f"a guard of {event!r} raised"
        if bad is not None and bad.choices:
            why += " when " + " and ".join(f"{p} is {v}" for p, v in bad.choices)
        if target < 0:
            trace = trace_to(model, parent, states, at, sym=sym)
            how = s.kind.value
        else:
            trace = trace_to(model, parent, states, at, s, _shows(model, key, target), sym)
            how = f"from a link, after {s.label(model.names)}"
        out.append(
            Finding(
                Kind.GUARD_ERROR,
                f"{name}.{event}",
                f"{name} in {label} gets {event!r} ({how}): {why}; the runtime refuses "
                "the event (guard error), the explorer never reads it as false",
                trace,
                count[key],
            )
        )
    return out


def _relies(
    model: Composed, properties: list[tuple[str, str]], findings: list[Finding]
) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """Report rule 4: what each verdict relies on beyond the model, where it does."""
    everywhere = model.assumes()
    out: list[tuple[str, tuple[str, ...]]] = []
    for text, verdict in properties:
        mine = [f for f in findings if f.failure and _about(f, text)]
        why: tuple[str, ...] = ()
        if verdict == "fails" and mine and all(f.assumed for f in mine):
            why = tuple(dict.fromkeys(a for f in mine for a in f.assumed))
        elif verdict == "holds" and (text == "no deadlock" or text.startswith("recovery ")):
            why = everywhere
        if why:
            out.append((text, why))
    return tuple(out)


def _about(f: Finding, text: str) -> bool:
    """Whether finding ``f`` is a counterexample to the property line ``text``."""
    if f.kind is Kind.DEADLOCK:
        return text == "no deadlock"
    if f.kind in (Kind.INVARIANT, Kind.RECOVERY):
        return text.startswith(f"{f.kind.value} {f.name}:")
    lines = {
        Kind.UNHANDLED: "every link-delivered event is handled or ignored",
        Kind.GUARD_ERROR: "no guard raises",
        Kind.LIVELOCK: "no link livelock",
    }
    return lines.get(f.kind) == text


def _recovery(
    model: Composed,
    target: Predicate,
    source: Predicate | None,
    states: Sequence[int],
    src: array[int],
    dst: array[int],
) -> tuple[int, int]:
    """First state (BFS order) where ``source`` holds and no path reaches ``target``; count."""
    n = len(states)
    count_in = array("q", bytes(8 * (n + 1)))
    for j in dst:
        count_in[j + 1] += 1
    for k in range(n):
        count_in[k + 1] += count_in[k]
    preds = array("q", bytes(8 * len(src)))
    fill = array("q", count_in)
    for a, b in zip(src, dst, strict=True):
        preds[fill[b]] = a
        fill[b] += 1
    good = bytearray(n)
    stack = [k for k in range(n) if target(states[k])]
    for k in stack:
        good[k] = 1
    while stack:
        k = stack.pop()
        for p in preds[count_in[k] : count_in[k + 1]]:
            if not good[p]:
                good[p] = 1
                stack.append(p)
    bad = [k for k in range(n) if not good[k] and (source is None or source(states[k]))]
    return (bad[0], len(bad)) if bad else (-1, 0)
