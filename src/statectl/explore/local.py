"""One device's local state space, stepped once with the kernel and then looked up.

Rules:
1. Every step is decided by :func:`statectl.semantics.step` on the device's own
   :class:`~statectl.semantics.Machine`; the explorer never re-implements it.
   The reachable snapshots of a device alone (under every event it knows and
   every free choice) are numbered once; the composed search then only looks up
   ``(local id, event) -> outcomes``.
2. A guard part that reads data the model does not track (``_event``, or a data
   item declared without a value) is a *free choice*: both outcomes are
   explored. Parts over tracked data (``previous``, ``In()``, data with a value)
   are evaluated as the runtime would. The choice is forced by rewriting the
   untracked part into a call of an oracle that the evaluation env carries;
   nothing in the kernel changes (the kernel hook that would replace this is
   described in ``docs/cells.md``).
3. ``previous`` is kept in the snapshot only when some guard reads it, so local
   states that no guard can tell apart are one state.
4. Each outcome says how the device reacted: handled, declared ignored, refused
   by a false guard, or unhandled (no row and not ignored), which is the missed
   transition the cell checks for.
"""

from __future__ import annotations

import ast
import enum
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from statectl.errors import Location
from statectl.expr import Expression
from statectl.model import Chart, ControlKind, EventKind, Notify
from statectl.semantics import Machine, Snapshot, Step, initial, step

__all__ = ["FreeGuard", "LocalSpace", "Outcome", "Reaction"]

ORACLE = "_statectl_choose"
Choices = tuple[tuple[str, bool], ...]
TRACKED = frozenset({"previous", "In"})


class Reaction(enum.Enum):
    HANDLED = "handled"
    IGNORED = "ignored"  # the state table declares the event ignored
    GUARD_FALSE = "guard false"  # a row exists but its guard did not hold
    UNHANDLED = "unhandled"  # no row and not declared ignored


@dataclass(frozen=True, slots=True)
class Outcome:
    """One way a device can react to one event in one local state."""

    target: int
    reaction: Reaction
    entered: frozenset[str]
    events: frozenset[str]  # events on which transitions were taken (external and raised)
    exited: tuple[str, ...] = ()
    entered_order: tuple[str, ...] = ()
    notifies: tuple[str, ...] = ()  # observer methods called, in order
    choices: tuple[tuple[str, bool], ...] = ()  # free guard parts and the value taken

    @property
    def handled(self) -> bool:
        return self.reaction is Reaction.HANDLED


@dataclass(frozen=True, slots=True)
class FreeGuard:
    """A guard with parts over untracked data, explored both ways."""

    device: str
    guard: str
    parts: tuple[str, ...]
    where: Location


class _Oracle:
    """Answers free guard parts from a forced prefix, then ``False``; records what it was asked."""

    def __init__(self, leaves: list[str], prefix: tuple[bool, ...]) -> None:
        self.leaves = leaves
        self.prefix = prefix
        self.asked: list[tuple[int, bool]] = []

    def __call__(self, leaf: int) -> bool:
        n = len(self.asked)
        value = self.prefix[n] if n < len(self.prefix) else False
        self.asked.append((leaf, value))
        return value


def _untracked(node: ast.AST, tracked_data: frozenset[str]) -> bool:
    return any(
        isinstance(n, ast.Name) and n.id not in TRACKED and n.id not in tracked_data
        for n in ast.walk(node)
    )


class _Rewriter(ast.NodeTransformer):
    """Replace each untracked boolean part of a guard by ``_statectl_choose(k)``."""

    def __init__(self, leaves: list[str], tracked_data: frozenset[str]) -> None:
        self.leaves = leaves
        self.tracked = tracked_data

    def part(self, node: ast.expr) -> ast.expr:
        if isinstance(node, ast.BoolOp):
            node.values = [self.part(v) for v in node.values]
            return node
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            node.operand = self.part(node.operand)
            return node
        if not _untracked(node, self.tracked):
            return node
        self.leaves.append(ast.unparse(node))
        call = ast.Call(ast.Name(ORACLE, ast.Load()), [ast.Constant(len(self.leaves) - 1)], [])
        return ast.copy_location(call, node)


def _literal(text: str | None) -> Any:
    if text is None:
        return None
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return None


class LocalSpace:
    """A device instance: its machine, numbered snapshots and the outcome table."""

    def __init__(self, name: str, chart: Chart) -> None:
        self.name = name
        self.chart = chart
        self.machine = Machine(chart)
        self.data: dict[str, Any] = {d.name: _literal(d.expr) for d in chart.data}
        tracked_data = frozenset(k for k, v in self.data.items() if v is not None)
        self.leaves: list[str] = []
        free: list[FreeGuard] = []
        reads_previous = False
        seen: set[str] = set()
        for t in chart.transitions:
            if not t.guard or t.guard in seen or t.guard not in self.machine.guards:
                continue
            seen.add(t.guard)
            tree = ast.parse(t.guard.strip(), mode="eval")
            first = len(self.leaves)
            tree.body = _Rewriter(self.leaves, tracked_data).part(tree.body)
            ast.fix_missing_locations(tree)
            parts = tuple(self.leaves[first:])
            reads_previous |= any(
                isinstance(n, ast.Name) and n.id == "previous" for n in ast.walk(tree)
            )
            if parts:
                free.append(FreeGuard(name, t.guard, parts, t.origin))
                old = self.machine.guards[t.guard]
                code = compile(tree, f"<free guard {t.origin}>", "eval")
                self.machine.guards[t.guard] = Expression(old.source, code, old.names)
        self.free_guards = tuple(free)
        self.keep_previous = reads_previous
        self.events: tuple[str, ...] = chart.event_names
        self.kind: dict[str, EventKind] = {
            e: (d.kind if (d := chart.event(e)) is not None else EventKind.COMMAND)
            for e in self.events
        }
        self.snapshots: list[Snapshot] = []
        self.index: dict[Snapshot, int] = {}
        self.table: dict[tuple[int, str], tuple[Outcome, ...]] = {}
        self.initial: tuple[Outcome, ...] = self._close()
        self.monitored: tuple[bool, ...] = tuple(
            any(ControlKind.MONITORING in chart.state(s).controls for s in snap.active)
            for snap in self.snapshots
        )
        order = self.machine.order
        self.labels: tuple[str, ...] = tuple(
            "+".join(sorted((s for s in snap.active if self.machine.is_atomic(s)),
                            key=order.__getitem__))
            for snap in self.snapshots
        )

    # -- stepping under forced choices ----------------------------------------------------

    def _canon(self, snap: Snapshot) -> Snapshot:
        if not self.keep_previous and snap.previous is not None:
            return Snapshot(snap.active, snap.history, None)
        return snap

    def _id(self, snap: Snapshot, queue: deque[int]) -> int:
        snap = self._canon(snap)
        found = self.index.get(snap)
        if found is None:
            found = self.index[snap] = len(self.snapshots)
            self.snapshots.append(snap)
            queue.append(found)
        return found

    def _runs(self, event: str | None, snap: Snapshot) -> list[tuple[Step, Choices]]:
        """Every step the kernel can take, one per combination of free choices consulted."""
        out: list[tuple[Step, Choices]] = []
        pending: list[tuple[bool, ...]] = [()]
        while pending:
            prefix = pending.pop()
            oracle = _Oracle(self.leaves, prefix)
            data = {**self.data, ORACLE: oracle}
            result = initial(self.machine, data) if event is None else step(
                self.machine, snap, event, data
            )
            for i in range(len(prefix), len(oracle.asked)):
                pending.append((*(v for _, v in oracle.asked[:i]), True))
            out.append((result, tuple((self.leaves[k], v) for k, v in oracle.asked)))
        return out

    def _outcome(
        self, result: Step, choices: Choices, queue: deque[int]
    ) -> Outcome:
        target = self._id(result.target, queue)
        if result.handled:
            reaction = Reaction.HANDLED
        elif result.ignored:
            reaction = Reaction.IGNORED
        elif result.event is not None and self._has_row(result.source, result.event):
            reaction = Reaction.GUARD_FALSE
        else:
            reaction = Reaction.UNHANDLED
        events = frozenset(m.event for m in result.microsteps if m.event and m.transitions)
        notifies = tuple(a.method for a in result.actions if isinstance(a, Notify))
        return Outcome(target, reaction, frozenset(result.entered), events, result.exited,
                       result.entered, notifies, choices)

    def _has_row(self, snap: Snapshot, event: str) -> bool:
        m = self.machine
        return any(m.candidates(s, event) for s in snap.active if m.is_atomic(s))

    def _close(self) -> tuple[Outcome, ...]:
        """Number every snapshot reachable from the initial ones under every event."""
        queue: deque[int] = deque()
        starts = tuple(
            self._outcome(r, c, queue) for r, c in self._runs(None, Snapshot(frozenset()))
        )
        while queue:
            lid = queue.popleft()
            snap = self.snapshots[lid]
            for event in self.events:
                outs = dict.fromkeys(self._outcome(r, c, queue) for r, c in self._runs(event, snap))
                self.table[lid, event] = tuple(outs)
        return starts

    # -- reading -----------------------------------------------------------------------------

    def lookup(self, snap: Snapshot) -> int | None:
        """The local id of a runtime snapshot, or ``None`` if the device alone never reaches it."""
        return self.index.get(self._canon(snap))

    def outcomes(self, lid: int, event: str) -> tuple[Outcome, ...]:
        return self.table.get((lid, event), ())

    def active(self, lid: int) -> frozenset[str]:
        return self.snapshots[lid].active

    def state_of(self, lid: int) -> str:
        return self.labels[lid]

    def states_in(self, state: str) -> tuple[bool, ...]:
        """Per local id: is ``state`` active."""
        return tuple(state in snap.active for snap in self.snapshots)

    def describe(self) -> Mapping[str, int]:
        return {"local_states": len(self.snapshots), "free_guards": len(self.free_guards)}
