"""Symmetry reduction: devices a cell cannot tell apart are stored once per orbit.

A cell of identical stations reaches every permutation of the stations' states;
the search need store only one of them. Rules:

1. Two devices are *interchangeable* when swapping their names maps the cell onto
   itself: the same device file (equal charts, equal local spaces); the links, the
   environment's entries (with their ``when``), every invariant and recovery goal
   (each onto itself, compared as normalised expressions: ``and``/``or`` operands
   sorted), and the link guards all map onto themselves; each of the two devices'
   own links, in the cell file's order, onto the other's. Swaps compose, so the
   devices fall into groups, every permutation of a group an automorphism.
2. A device some chart reads with ``In('device.State')`` (a cross-device guard) is
   never in a group: the same file reads the same name from every member.
3. Links fired by one step are sent in the cell file's order. A device outside the
   group whose links to members are not in the same order for every member (a
   supervisor listing ``s0`` before ``s1``) keeps the group only when the order
   cannot show: no member's reaction to a link-delivered event fires a link, the
   members' charts read no other device, and no guard of that device's links reads
   a member. Otherwise the group is not reduced.
4. Cells that spread over nodes or have lossy or delayed links are not reduced.
5. The canonical representative of a global state sorts each group's local ids
   (a local id holds the device's whole state: configuration, data, pending calls;
   a cascade's queue never outlives a global step, so no stored part names a
   device). BFS over representatives keeps shortest lengths; a trace is mapped
   back to a concrete run (:meth:`Symmetry.align`), so it replays on the twins.
6. The full state count is the sum of the stored representatives' orbit sizes:
   exact when the search was complete.
"""

from __future__ import annotations

import ast
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from math import factorial
from typing import TYPE_CHECKING

from statectl.cell.explore.conditions import foreign_leaf
from statectl.cell.model import Cell, GlobalExpr, Link

if TYPE_CHECKING:
    from statectl.cell.explore.compose import Composed

__all__ = ["Group", "Symmetry", "find_symmetry"]

Rename = Mapping[str, str]


@dataclass(frozen=True, slots=True)
class Group:
    """Devices (positions in the cell, ascending) any permutation of which is an automorphism."""

    devices: tuple[int, ...]
    names: tuple[str, ...]
    #: rule 3 applied: the order of a device outside the group's links could not show
    relaxed: bool = False


class Symmetry:
    """The groups of a cell and what the search does with them: canonical keys, orbit sizes."""

    def __init__(self, model: Composed, groups: Sequence[Group]) -> None:
        self.groups = tuple(groups)
        self._layout: list[tuple[tuple[int, ...], int, int]] = []
        for grp in self.groups:
            shifts = tuple(model.shift[d] for d in grp.devices)
            mask = model.mask[grp.devices[0]]
            clear = ~sum(mask << s for s in shifts)
            self._layout.append((shifts, mask, clear))

    def canon(self, g: int) -> int:
        """The orbit's representative: each group's local ids sorted (rule 5)."""
        for shifts, mask, clear in self._layout:
            values = sorted([(g >> s) & mask for s in shifts])
            g &= clear
            for s, v in zip(shifts, values, strict=True):
                g |= v << s
        return g

    def orbit(self, g: int) -> int:
        """How many global states ``g``'s orbit has (rule 6)."""
        size = 1
        for shifts, mask, _ in self._layout:
            counts = Counter((g >> s) & mask for s in shifts)
            size *= _multinomial(len(shifts), tuple(sorted(counts.values())))
        return size

    def full_states(self, states: Sequence[int]) -> int:
        """The states the full search stores: every stored orbit, counted out (rule 6)."""
        return sum(self.orbit(g) for g in states)

    def align(self, g: int, target: int) -> Callable[[int], int]:
        """A renaming of the group members that maps ``g`` onto ``target`` (same orbit)."""
        moves: list[tuple[tuple[int, ...], int, int, tuple[int, ...]]] = []
        for shifts, mask, clear in self._layout:
            free: dict[int, list[int]] = {}
            for s in shifts:
                free.setdefault((g >> s) & mask, []).append(s)
            source = tuple(free[(target >> s) & mask].pop(0) for s in shifts)
            moves.append((shifts, mask, clear, source))

        def rename(h: int) -> int:
            for shifts, mask, clear, source in moves:
                values = [(h >> s) & mask for s in source]
                h &= clear
                for s, v in zip(shifts, values, strict=True):
                    h |= v << s
            return h

        return rename

    def reached(self, d: int) -> tuple[int, ...]:
        """The devices whose local states device ``d`` may stand for (its group, or itself)."""
        for grp in self.groups:
            if d in grp.devices:
                return grp.devices
        return (d,)

    def describe(self) -> str:
        """The reduction as the report names it."""
        parts = []
        for grp in self.groups:
            shown = (
                ", ".join(grp.names)
                if len(grp.names) <= 6
                else (f"{', '.join(grp.names[:3])}, ..., {grp.names[-1]}")
            )
            parts.append(f"{len(grp.names)} interchangeable devices ({shown})")
        return " and ".join(parts)


@lru_cache(maxsize=4096)
def _multinomial(n: int, counts: tuple[int, ...]) -> int:
    out = factorial(n)
    for c in counts:
        out //= factorial(c)
    return out


# -- detection -------------------------------------------------------------------------------


def find_symmetry(model: Composed) -> Symmetry | None:
    """The interchangeable groups of ``model``'s cell (rules 1-4); ``None`` when there are none."""
    cell = model.cell
    if cell.nodes is not None or model.distributed:
        return None  # rule 4
    names = model.names
    read = _read_by_charts(model)
    shape = _Shape(cell)
    candidates: dict[int, list[int]] = {}
    for d, ref in enumerate(cell.devices):
        if ref.name in read:
            continue  # rule 2
        key = next(
            (k for k, ds in candidates.items() if _same_device(model, ds[0], d)),
            d,
        )
        candidates.setdefault(key, []).append(d)
    groups: list[Group] = []
    for members in candidates.values():
        classes: list[list[int]] = []
        for d in members:
            for cls in classes:
                if shape.swaps(names[cls[0]], names[d]):
                    cls.append(d)
                    break
            else:
                classes.append([d])
        for cls in classes:
            if len(cls) < 2:
                continue
            ordered = shape.ordered(tuple(names[d] for d in cls))
            hidden = not ordered and shape.per_target(tuple(names[d] for d in cls))
            if ordered or (hidden and _order_hidden(model, cls)):
                groups.append(Group(tuple(cls), tuple(names[d] for d in cls), not ordered))
    return Symmetry(model, groups) if groups else None


def _same_device(model: Composed, a: int, b: int) -> bool:
    """Rule 1's first part: the same device file, numbered into the same local states."""
    da, db = model.cell.devices[a], model.cell.devices[b]
    if da.chart is not db.chart and da.chart != db.chart:
        return False
    sa, sb = model.spaces[a], model.spaces[b]
    return (
        sa.snapshots == sb.snapshots
        and sa.valuations == sb.valuations
        and sa.pending == sb.pending
        and model.bits[a] == model.bits[b]
    )


def _read_by_charts(model: Composed) -> frozenset[str]:
    """Rule 2: every device some device chart's guard reads with ``In('device.State')``."""
    out: set[str] = set()
    for space in model.spaces:
        for leaf in space.leaves:
            ref = foreign_leaf(leaf)
            if ref is not None:
                out.add(ref[0])
    return frozenset(out)


def _order_hidden(model: Composed, members: Sequence[int]) -> bool:
    """Rule 3: whether the order in which members get link events cannot show."""
    cell = model.cell
    mine = {model.names[d] for d in members}
    for d in members:
        if any(foreign_leaf(leaf) is not None for leaf in model.spaces[d].leaves):
            return False
    for i, k in enumerate(cell.links):
        if k.source not in mine and k.guard is not None and any(r[0] in mine for r in k.guard.refs):
            return False
        if k.target not in mine:
            continue
        t = model.position[k.target]
        for lid in range(len(model.spaces[t].snapshots)):
            for o in model.outcomes(t, lid, k.event, i):
                if o.handled and model.fires(t, o):
                    return False
    return True


class _Shape:
    """The parts of a cell that name devices, compared under a renaming (rule 1)."""

    def __init__(self, cell: Cell) -> None:
        self.cell = cell
        self.base = self.parts({})

    def parts(self, rename: Rename) -> tuple[object, ...]:
        cell = self.cell

        def n(name: str) -> str:
            return rename.get(name, name)

        links = Counter(_link(k, rename) for k in cell.links)
        env = Counter(
            (e.kind, n(e.device), e.event, _norm(e.when, rename)) for e in cell.environment
        )
        invariants = {
            inv.name: (
                _norm(inv.expr, rename),
                tuple(sorted((n(d), e) for d, e in inv.on_violation)),
            )
            for inv in cell.invariants
        }
        recovery = {
            r.name: (_norm(r.target, rename), _norm(r.source, rename)) for r in cell.recovery
        }
        return (links, env, invariants, recovery)

    def _own(self, rename: Rename) -> dict[str, tuple[object, ...]]:
        """Each device's links in file order (renamed), keyed by the (renamed) source."""
        out: dict[str, list[object]] = {}
        for k in self.cell.links:
            out.setdefault(rename.get(k.source, k.source), []).append(_link(k, rename))
        return {s: tuple(v) for s, v in out.items()}

    def swaps(self, a: str, b: str) -> bool:
        """Whether swapping ``a`` and ``b`` maps the cell onto itself, their own links in
        order (rule 1; the order of other devices' links is rule 3's)."""
        rename = {a: b, b: a}
        if self.parts(rename) != self.base:
            return False
        mine, theirs = self._own({}), self._own(rename)
        return mine.get(a) == theirs.get(a) and mine.get(b) == theirs.get(b)

    def ordered(self, members: Sequence[str]) -> bool:
        """Whether every other device's links keep their order under every swap of members."""
        mine = self._own({})
        first = members[0]
        for other in members[1:]:
            theirs = self._own({first: other, other: first})
            for s, seq in mine.items():
                if s not in (first, other) and theirs.get(s) != seq:
                    return False
        return True

    def per_target(self, members: Sequence[str]) -> bool:
        """Rule 3: each other device sends every member the same events in the same order."""
        first = members[0]
        links = self.cell.links
        for other in members[1:]:
            swap = {first: other, other: first}
            for s in {k.source for k in links} - {first, other}:
                to_first = [_link(k, swap) for k in links if k.source == s and k.target == first]
                to_other = [_link(k, {}) for k in links if k.source == s and k.target == other]
                if to_first != to_other:
                    return False
        return True


def _link(k: Link, rename: Rename) -> tuple[object, ...]:
    """A link as a hashable signature with its device names renamed."""
    return (
        rename.get(k.source, k.source),
        k.trigger,
        k.what,
        rename.get(k.target, k.target),
        k.event,
        _norm(k.guard, rename),
        repr(k.data),
        k.forward_data,
        k.ignore_if_unhandled,
        k.lossy,
        k.delayed,
    )


def _norm(expr: GlobalExpr | None, rename: Rename) -> str:
    """A global expression renamed and normalised: equal texts mean equal functions."""
    if expr is None:
        return ""
    return _form(ast.parse(expr.source, mode="eval").body, rename)


def _form(node: ast.expr, rename: Rename) -> str:
    if isinstance(node, ast.BoolOp):
        op = "and" if isinstance(node.op, ast.And) else "or"
        parts: set[str] = set()
        for v in node.values:
            if isinstance(v, ast.BoolOp) and type(v.op) is type(node.op):
                parts.update(_form(v, rename)[len(op) + 1 : -1].split("\x00"))
            else:
                parts.add(_form(v, rename))
        return f"{op}(" + "\x00".join(sorted(parts)) + ")"
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        return f"not({_form(node.operand, rename)})"
    if isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
        device, _, state = str(node.args[0].value).partition(".")
        return f"In({rename.get(device, device)}.{state})"
    return ast.unparse(node)
