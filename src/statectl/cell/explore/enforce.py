"""What ``verify`` assumes, a running cell enforces: environment ``when`` and invariants.

Rules:
1. An event from outside to a cell's device is an environment command when the
   cell lists ``send: EVENT, to: DEVICE``. If every such entry has a ``when`` and
   none holds in the global state the event arrives in, the event is refused
   (:class:`Refused`, saying which condition is false and the devices' states),
   as verify never offers it there. An event the environment does not list is
   not refused here (a driver's completion, a test's poke); ``statectl run`` counts
   those as it always did.
2. Invariants are watched after every step of every device: when one turns false
   the monitor records a :class:`Violation` (time, name, global state) and hands
   back the events the invariant's ``on_violation`` sends (an emergency stop to
   named devices). It reports it again only after the invariant held again.
3. Both read the explorer's packed global state (:class:`CellLinks`), so the
   runtime judges with the very predicates the explorer compiled.
"""

from __future__ import annotations

from dataclasses import dataclass

from statectl.cell.explore.compose import Predicate
from statectl.cell.explore.replay import CellLinks
from statectl.cell.model import Cell, EnvInput, InputKind
from statectl.kernel.errors import StatectlError

__all__ = ["CellRules", "Refused", "Violation"]


class Refused(StatectlError):
    """An environment command whose every ``when`` is false now (rule 1)."""


@dataclass(frozen=True, slots=True)
class Violation:
    """An invariant seen turning false by a running cell (rule 2)."""

    time: float
    name: str
    holds: str
    state: str
    sends: tuple[tuple[str, str], ...]

    def __str__(self) -> str:
        text = f"invariant {self.name} violated: {self.holds} is false in {self.state}"
        if self.sends:
            text += "; sending " + ", ".join(f"{d}: {e}" for d, e in self.sends)
        return text


class CellRules:
    """Rules 1-2 over a running cell's links (its subjects and compiled model)."""

    def __init__(self, cell: Cell, links: CellLinks) -> None:
        self.cell = cell
        self.links = links
        model = links.model
        self._commands: dict[tuple[str, str], list[tuple[EnvInput, Predicate | None]]] = {}
        for e, when in zip(cell.environment, model.when, strict=True):
            if e.kind is InputKind.COMMAND:
                self._commands.setdefault((e.device, e.event), []).append((e, when))
        self._invariants = [(inv, model.predicate(inv.expr)) for inv in cell.invariants]
        self._broken: set[str] = set()
        self.violations: list[Violation] = []
        #: whether there is any invariant to watch (a step need not pack the state)
        self.watching = bool(self._invariants)

    def guarded(self, device: str, event: str) -> bool:
        """Whether rule 1 may refuse ``event`` to ``device`` (every entry for it has a when)."""
        entries = self._commands.get((device, event), [])
        return bool(entries) and all(when is not None for _, when in entries)

    def admit(self, device: str, event: str) -> None:
        """Rule 1: raise :class:`Refused` if the cell's environment may not send this now."""
        entries = self._commands.get((device, event))
        if not entries or any(when is None for _, when in entries):
            return
        g = self.links.state()
        if any(when is not None and when(g) for _, when in entries):
            return
        conditions = " or ".join(repr(e.when.source) for e, _ in entries if e.when is not None)
        raise Refused(
            f"{device}: {event} refused: the cell's environment sends it only when "
            f"{conditions}, which is false in {self.links.model.describe(g)} "
            f"({self.cell.path}:{entries[0][0].where.line})"
        )

    def check(self, now: float) -> list[Violation]:
        """Rule 2: the invariants that turned false since the last call."""
        if not self._invariants:
            return []
        g = self.links.state()
        found: list[Violation] = []
        for inv, holds in self._invariants:
            if holds(g):
                self._broken.discard(inv.name)
            elif inv.name not in self._broken:
                self._broken.add(inv.name)
                found.append(
                    Violation(
                        now,
                        inv.name,
                        inv.expr.source,
                        self.links.model.describe(g),
                        inv.on_violation,
                    )
                )
        self.violations.extend(found)
        return found
