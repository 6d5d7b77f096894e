"""The flat tables' values: configurations, outcomes, effects, decision trees over runtime
guards and the FlatChart that holds them. Split from :mod:`statectl.codegen.flatten` so
the C++ writer reads the values without the explorer that finds them.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from statectl.model import (
    Chart,
    Transition,
)
from statectl.semantics import (
    Snapshot,
    Unhandled,
)


class EffectKind(enum.Enum):
    EXIT = "exit"
    TAKE = "take"
    ENTER = "enter"
    INVOKE = "invoke"
    ASSIGN = "assign"  # index: an Assignments group (codegen.assign)


@dataclass(frozen=True, slots=True)
class Effect:
    """One traced thing a step does; ``index`` is a state, transition or invoke number."""

    kind: EffectKind
    index: int


@dataclass(frozen=True, slots=True)
class Outcome:
    handled: bool
    target: int  # configuration index; the source itself when not handled
    effects: tuple[Effect, ...]
    unhandled: Unhandled | None = None  # the kernel's reason; None when handled
    final: bool = False  # a top-level final state was reached


@dataclass(frozen=True, slots=True)
class Decision:
    """Evaluate runtime guard ``guard``; continue in ``if_true`` or ``if_false``."""

    guard: int
    if_true: Tree
    if_false: Tree


Tree = Outcome | Decision


@dataclass(frozen=True, slots=True)
class Configuration:
    index: int
    snapshot: Snapshot
    active: tuple[str, ...]  # document order

    @property
    def label(self) -> str:
        previous = self.snapshot.previous or "-"
        text = ", ".join(self.active) + f" (previous {previous})"
        if self.snapshot.history:
            text += " history " + "; ".join(f"{h}={'+'.join(v)}" for h, v in self.snapshot.history)
        return text


@dataclass(frozen=True, slots=True)
class RuntimeGuard:
    """A guard specialised to where it is evaluated; ``cpp`` is its C++ expression."""

    index: int
    source: str
    previous: str | None
    cpp: str


@dataclass(frozen=True, slots=True)
class ContextField:
    name: str
    ident: str  # the C++ member name
    initial: int


@dataclass(frozen=True, slots=True)
class FlatChart:
    chart: Chart
    states: tuple[str, ...]  # every chart state, document order
    events: tuple[str, ...]  # external events, the chart's order
    transitions: tuple[Transition, ...]
    configurations: tuple[Configuration, ...]
    start: Tree
    dispatch: tuple[tuple[Tree, ...], ...]  # [configuration][event]
    guards: tuple[RuntimeGuard, ...]
    context: tuple[ContextField, ...]
    assignments: tuple[Assignments, ...] = ()  # the ASSIGN effects' groups


@dataclass(frozen=True, slots=True)
class Assignments:
    """One transition's data assignments as C++: every value computed, then all stored.

    ``stores`` pairs a context field's C++ name with the C++ expression of its new
    value over the context before the step (``c.indexed + 1``).
    """

    index: int
    source: str  # ``indexed = indexed + 1; ...`` as the table wrote it
    stores: tuple[tuple[str, str], ...]
