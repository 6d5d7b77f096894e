"""One device's local state space, stepped once with the kernel and then looked up.

Rules:
1. Every step is decided by :func:`statectl.kernel.semantics.step` on the device's own
   :class:`~statectl.kernel.semantics.Machine`; the explorer never re-implements it.
   The reachable snapshots of a device alone (under every event it knows and
   every free choice) are numbered once; the composed search then only looks up
   ``(local id, event) -> outcomes``.
2. A guard part that reads data the model does not track (``_event``, a data
   item declared without a value, or one assigned from event data) is a *free
   choice*: both outcomes are explored. Data assigned by event rows is part of
   the local state (:mod:`statectl.cell.explore.data`), bounded (C412). Parts over
   tracked data (``previous``, ``In()``, data with a value) are evaluated as the
   runtime would. The choice is forced through the
   kernel's guard oracle (``step(..., oracle=...)``): the explorer keeps its own
   copy of each such guard with the untracked parts replaced by calls of a
   chooser, evaluates it over the kernel's guard env and hands the kernel the
   value; the Machine's guards are never rewritten.
3. ``previous`` is kept in the snapshot only when some guard reads it, so local
   states that no guard can tell apart are one state.
4. With ``calls`` (a cell whose devices report their completions), the API calls
   the device was issued and has not completed are part of its local state, as
   :mod:`statectl.kernel.semantics.calls` (the twin's own model) keeps them: every
   outcome's target carries the calls after its notifications, and
   :meth:`LocalSpace.reports` are the device's own completions, each settling one
   pending call it completes. A report the device's state ignores still settles
   its call (``Reaction.settles``): the twin did report it.
5. Each outcome says how the device reacted: handled, or the kernel's
   :class:`~statectl.kernel.semantics.Unhandled` reason (declared ignored, guard false,
   no transition: the missed transition the cell checks for, guard error: a guard
   raised, e.g. ``10 / scale`` with ``scale`` 0; the runtime refuses that event, so
   the explorer never reads it as false and the cell reports it).
"""

from __future__ import annotations

import ast
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from statectl.cell.explore.data import MAX_LOCAL_STATES, DataTracker
from statectl.cell.explore.deferred import released
from statectl.cell.links import triggers
from statectl.cell.options import foreign_in
from statectl.front.observers import extract
from statectl.kernel.errors import Location
from statectl.kernel.expr import Expression
from statectl.kernel.model import Chart, ControlKind, EventKind, Notify, Transition
from statectl.kernel.semantics import (
    Machine,
    Run,
    Snapshot,
    Step,
    Unhandled,
    guard_env,
    initial,
    step,
)
from statectl.kernel.semantics.calls import DeviceCalls, Pending

__all__ = ["FreeGuard", "LocalSpace", "Reaction"]

ORACLE = "_statectl_choose"
Choices = tuple[tuple[str, bool], ...]
TRACKED = frozenset({"previous", "In"})


@dataclass(frozen=True, slots=True)
class Reaction:
    """One way a device can react to one event in one local state (JSON reports' ``reaction``).

    Not the kernel's :class:`~statectl.kernel.semantics.Outcome` enum: ``unhandled`` holds
    that answer; this adds what the explorer needs of the step (target, entered, choices).
    """

    target: int
    unhandled: Unhandled | None  # None: handled
    entered: frozenset[str]
    events: frozenset[str]  # events on which transitions were taken (external and raised)
    exited: tuple[str, ...] = ()
    entered_order: tuple[str, ...] = ()
    notifies: tuple[str, ...] = ()  # observer methods called, in order
    choices: tuple[tuple[str, bool], ...] = ()  # free guard parts and the value taken
    failure: str = ""  # a GUARD_ERROR step: the guard, its row and why it raised
    #: the device's own report, ignored by its state, that settled a pending call
    settles: bool = False
    #: what verify assumed to take this way, beyond what it tracks ("deferred": kept
    #: events released, explore/deferred.py); empty: a step the device surely can take
    assumed: tuple[str, ...] = ()

    @property
    def handled(self) -> bool:
        return self.unhandled is None

    @property
    def happens(self) -> bool:
        """Whether the step changes the device: handled, or a report that settled a call."""
        return self.unhandled is None or self.settles


@dataclass(frozen=True, slots=True)
class FreeGuard:
    """A guard with parts over untracked data, explored both ways."""

    device: str
    guard: str
    parts: tuple[str, ...]
    where: Location


class _Chooser:
    """Answers free guard parts from a forced prefix, then ``False``; records what it was asked."""

    def __init__(self, prefix: tuple[bool, ...]) -> None:
        self.prefix = prefix
        self.asked: list[tuple[int, bool]] = []

    def __call__(self, leaf: int) -> bool:
        n = len(self.asked)
        value = self.prefix[n] if n < len(self.prefix) else False
        self.asked.append((leaf, value))
        return value


class _Oracle:
    """The kernel's guard oracle: guards with free parts are evaluated here, others unforced."""

    def __init__(self, free: dict[str, Expression], choose: _Chooser) -> None:
        self.free = free
        self.choose = choose

    def __call__(self, run: Run, t: Transition) -> bool | None:
        expr = self.free.get(t.guard or "")
        if expr is None:
            return None
        current = run.current
        env = guard_env(run, current.data if current is not None else None)
        env[ORACLE] = self.choose
        # a part over tracked data may raise (10 / scale with scale 0): not caught here,
        # the kernel refuses the step as GUARD_ERROR, as the runtime does (GuardOracle)
        return bool(expr.evaluate(env))


def _untracked(node: ast.AST, tracked_data: frozenset[str], chart: Chart | None = None) -> bool:
    return any(
        isinstance(n, ast.Name) and n.id not in TRACKED and n.id not in tracked_data
        for n in ast.walk(node)
    ) or (chart is not None and _foreign(node, chart))


def _foreign(node: ast.AST, chart: Chart) -> bool:
    """``In('device.State')`` naming no state of ``chart``: another device of a cell reads it."""
    return any(foreign_in(n, chart) is not None for n in ast.walk(node))


class _Rewriter(ast.NodeTransformer):
    """Replace each untracked boolean part of a guard by ``_statectl_choose(k)``."""

    def __init__(
        self, leaves: list[str], tracked_data: frozenset[str], chart: Chart | None = None
    ) -> None:
        self.leaves = leaves
        self.tracked = tracked_data
        self.chart = chart

    def part(self, node: ast.expr) -> ast.expr:
        if isinstance(node, ast.BoolOp):
            node.values = [self.part(v) for v in node.values]
            return node
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            node.operand = self.part(node.operand)
            return node
        if not _untracked(node, self.tracked, self.chart):
            return node
        self.leaves.append(ast.unparse(node))
        call = ast.Call(ast.Name(ORACLE, ast.Load()), [ast.Constant(len(self.leaves) - 1)], [])
        return ast.copy_location(call, node)


def _failure(result: Step) -> str:
    f = result.failure
    if f is None:
        return ""
    return f"the guard {f.guard!r} ({f.origin}) raised {f.reason}"


def _literal(text: str | None) -> Any:
    if text is None:
        return None
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return None


class LocalSpace:
    """A device instance: its machine, numbered snapshots and the outcome table."""

    def __init__(self, name: str, chart: Chart, *, calls: bool = False) -> None:
        self.name = name
        self.chart = chart
        self.machine = Machine(chart)
        #: rule 4: the twin's model of calls and completions, when they are tracked
        self.calls: DeviceCalls | None = DeviceCalls(chart, self.machine) if calls else None
        self.data: dict[str, Any] = {d.name: _literal(d.expr) for d in chart.data}
        self.tracker = DataTracker(chart, self.data)  # data changed by assign (explore.data)
        tracked_data = frozenset(
            k for k, v in self.data.items() if v is not None and k not in self.tracker.untracked
        )
        self.leaves: list[str] = []
        # guards with free parts, each with those parts replaced by the chooser's calls
        self.rewritten: dict[str, Expression] = {}
        free: list[FreeGuard] = []
        reads_previous = False
        seen: set[str] = set()
        for t in chart.transitions:
            if not t.guard or t.guard in seen or t.guard not in self.machine.guards:
                continue
            seen.add(t.guard)
            tree = ast.parse(t.guard.strip(), mode="eval")
            first = len(self.leaves)
            tree.body = _Rewriter(self.leaves, tracked_data, chart).part(tree.body)
            ast.fix_missing_locations(tree)
            parts = tuple(self.leaves[first:])
            reads_previous |= any(
                isinstance(n, ast.Name) and n.id == "previous" for n in ast.walk(tree)
            )
            shown = tuple(p for p in parts if not p.startswith("In("))  # not another device
            if shown:
                free.append(FreeGuard(name, t.guard, shown, t.origin))
            if parts:
                old = self.machine.guards[t.guard]
                code = compile(tree, f"<free guard {t.origin}>", "eval")
                self.rewritten[t.guard] = Expression(old.source, code, old.names)
        self.free_guards = tuple(free)
        self.keep_previous = reads_previous
        self.events: tuple[str, ...] = chart.event_names
        self.kind: dict[str, EventKind] = {
            e: (d.kind if (d := chart.event(e)) is not None else EventKind.COMMAND)
            for e in self.events
        }
        self.snapshots: list[Snapshot] = []
        self.valuations: list[tuple[Any, ...]] = []  # tracked data per local id (explore.data)
        self.pending: list[Pending] = []  # calls not completed per local id (rule 4)
        self.index: dict[tuple[Snapshot, tuple[Any, ...], Pending], int] = {}
        self.first: dict[tuple[Snapshot, tuple[Any, ...]], int] = {}  # any calls
        self.table: dict[tuple[int, str], tuple[Reaction, ...]] = {}
        self.report_table: dict[tuple[int, str], tuple[Reaction, ...]] = {}
        self.initial: tuple[Reaction, ...] = self._close()
        self.monitored: tuple[bool, ...] = tuple(
            any(ControlKind.MONITORING in chart.state(s).controls for s in snap.active)
            for snap in self.snapshots
        )
        # the faults the active monitors raise: the runtime's monitors, from one definition
        # (statectl.front.observers.extract, observers rule 6)
        raising = {m.state: frozenset(m.raises) for m in extract(chart).monitors}
        self.raises: tuple[frozenset[str], ...] = tuple(
            frozenset().union(*(raising.get(s, frozenset()) for s in snap.active))
            for snap in self.snapshots
        )
        order = self.machine.order
        self.labels: tuple[str, ...] = tuple(
            "+".join(
                sorted((s for s in snap.active if self.machine.is_atomic(s)), key=order.__getitem__)
            )
            for snap in self.snapshots
        )

    # -- stepping under forced choices ----------------------------------------------------

    def _canon(self, snap: Snapshot) -> Snapshot:
        if not self.keep_previous and snap.previous is not None:
            return Snapshot(snap.active, snap.history, None)
        return snap

    def _id(
        self, snap: Snapshot, values: tuple[Any, ...], queue: deque[int], pending: Pending = ()
    ) -> int:
        key = (self._canon(snap), values, pending)
        found = self.index.get(key)
        if found is None:
            if self.tracker.dynamic and len(self.snapshots) >= MAX_LOCAL_STATES:
                raise self.tracker.unbounded(self.name, MAX_LOCAL_STATES)
            found = self.index[key] = len(self.snapshots)
            self.first.setdefault(key[:2], found)
            self.snapshots.append(key[0])
            self.valuations.append(values)
            self.pending.append(pending)
            queue.append(found)
        return found

    def _runs(
        self, event: str | None, snap: Snapshot, values: tuple[Any, ...] = ()
    ) -> list[tuple[Step, Choices]]:
        """Every step the kernel can take, one per combination of free choices consulted."""
        out: list[tuple[Step, Choices]] = []
        pending: list[tuple[bool, ...]] = [()]
        m = self.machine
        data = self.tracker.values(self.data, values) if values else self.data
        while pending:
            prefix = pending.pop()
            chooser = _Chooser(prefix)
            oracle = _Oracle(self.rewritten, chooser) if self.rewritten else None
            if event is None:
                result = initial(m, data, oracle=oracle)
            else:
                result = step(m, snap, event, data, oracle=oracle)
            asked = chooser.asked
            for i in range(len(prefix), len(asked)):
                pending.append((*(v for _, v in asked[:i]), True))
            out.append((result, tuple((self.leaves[k], v) for k, v in asked)))
        return out

    def _outcome(
        self,
        result: Step,
        choices: Choices,
        queue: deque[int],
        values: tuple[Any, ...] = (),
        pending: Pending = (),
        settled: bool = False,
    ) -> Reaction:
        after = values
        if self.tracker.dynamic and result.handled:
            after = self.tracker.after(result, self.tracker.values(self.data, values))
        calls = tuple((a.method, a.event) for a in result.actions if isinstance(a, Notify))
        if self.calls is not None and calls and result.handled:
            pending = self.calls.after_calls(pending, calls)
        target = self._id(result.target, after, queue, pending)
        found = triggers(result.microsteps)  # what the step offers links (cell/links.py)
        notifies = tuple(c[0] for c in calls)
        return Reaction(
            target,
            result.unhandled,
            found.entered,
            found.events,
            result.exited,
            result.entered,
            notifies,
            choices,
            _failure(result),
            settled
            and result.unhandled is not None
            and result.unhandled is not Unhandled.GUARD_ERROR,
        )

    def _close(self) -> tuple[Reaction, ...]:
        """Number every snapshot reachable from the initial ones under every event."""
        queue: deque[int] = deque()
        first = self.tracker.initial
        starts = tuple(
            self._outcome(r, c, queue, first)
            for r, c in self._runs(None, Snapshot(frozenset()), first)
        )
        while queue:
            lid = queue.popleft()
            snap, values, pending = self.snapshots[lid], self.valuations[lid], self.pending[lid]
            for event in self.events:
                outs = dict.fromkeys(
                    self._outcome(r, c, queue, values, pending)
                    for r, c in self._runs(event, snap, values)
                )
                if self.chart.deferred:  # a kept event may come back (explore/deferred.py)
                    outs.update(dict.fromkeys(released(self, snap, tuple(outs), queue)))
                self.table[lid, event] = tuple(outs)
            if self.calls is not None and pending:
                self._reports(lid, queue)
        return starts

    def _reports(self, lid: int, queue: deque[int]) -> None:
        """Rule 4: the completions the device may report in ``lid``, each settling a call."""
        assert self.calls is not None
        snap, values, pending = self.snapshots[lid], self.valuations[lid], self.pending[lid]
        for event in dict.fromkeys(c for key in pending for c in self.calls.call(*key).completions):
            outs: dict[Reaction, None] = {}
            for rest in self.calls.settled_by(pending, event):
                for r, c in self._runs(event, snap, values):
                    outs[self._outcome(r, c, queue, values, rest, settled=True)] = None
            if self.chart.deferred:  # a kept event may come back (explore/deferred.py)
                outs.update(dict.fromkeys(released(self, snap, tuple(outs), queue)))
            self.report_table[lid, event] = tuple(outs)

    # -- reading -----------------------------------------------------------------------------

    def lookup(
        self,
        snap: Snapshot,
        data: Mapping[str, Any] | None = None,
        calls: Pending | None = None,
    ) -> int | None:
        """The local id of a runtime snapshot (and data, and the calls pending on its
        device: ``None`` takes the first id with that snapshot, for questions about
        states alone), or ``None`` if never reached."""
        values = tuple((data or self.data).get(n) for n in self.tracker.dynamic)
        if calls is None or self.calls is None:
            return self.first.get((self._canon(snap), values))
        return self.index.get((self._canon(snap), values, calls))

    def outcomes(self, lid: int, event: str) -> tuple[Reaction, ...]:
        return self.table.get((lid, event), ())

    def reports(self, lid: int, event: str) -> tuple[Reaction, ...]:
        """Rule 4: ``event`` reported by the device itself, settling a call; empty when no
        call pending in ``lid`` is completed by it."""
        return self.report_table.get((lid, event), ())

    def unasked(self, event: str) -> bool:
        """Whether the device may report ``event`` with no call pending (its table says so,
        or calls are not tracked: every completion is then offered where handled)."""
        return self.calls is None or event in self.calls.unasked

    def active(self, lid: int) -> frozenset[str]:
        return self.snapshots[lid].active

    def state_of(self, lid: int) -> str:
        return self.labels[lid]

    def states_in(self, state: str) -> tuple[bool, ...]:
        """Per local id: is ``state`` active."""
        return tuple(state in snap.active for snap in self.snapshots)

    def describe(self) -> Mapping[str, int]:
        return {"local_states": len(self.snapshots), "free_guards": len(self.free_guards)}
