"""The flat tables' values: configurations, outcomes, effects, decision trees over runtime
guards and the FlatChart that holds them. Split from :mod:`statectl.out.codegen.flatten` so
the C++ writer reads the values without the explorer that finds them.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import overload

from statectl.kernel.model import (
    Chart,
    Transition,
)
from statectl.kernel.semantics import (
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
class FlatStep:
    """A kernel step as the flat tables hold it (a row of the C++ ``kOutcomes``): not the
    kernel's :class:`~statectl.kernel.semantics.Outcome` enum, which ``unhandled`` carries."""

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


Tree = FlatStep | Decision


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


class Row(Sequence[Tree]):
    """One configuration's dispatch row, sparse: the kernel's tree for every event some
    active state could take, and the unhandled outcome, computed without a kernel step,
    for every other event (declared ignored or deferred in ``ignored``, else no transition).

    Indexing gives each event's tree as before (``row[event]``); generators that must
    stay linear in the chart read ``explicit`` and ``ignored`` instead of every cell.
    """

    __slots__ = ("explicit", "ignored", "size", "source")

    def __init__(
        self, source: int, size: int, explicit: Mapping[int, Tree], ignored: frozenset[int]
    ) -> None:
        self.source = source  # this configuration's index
        self.size = size  # the chart's external events
        self.explicit = explicit  # event index -> the kernel's tree, ascending events
        self.ignored = ignored  # event indices declared ignored here, none in explicit

    def unhandled(self, event: int) -> FlatStep:
        """The outcome of an event no active state has a transition for."""
        reason = Unhandled.DECLARED_IGNORED if event in self.ignored else Unhandled.NO_TRANSITION
        return FlatStep(False, self.source, (), reason)

    @overload
    def __getitem__(self, index: int) -> Tree: ...
    @overload
    def __getitem__(self, index: slice) -> Sequence[Tree]: ...
    def __getitem__(self, index: int | slice) -> Tree | Sequence[Tree]:
        if isinstance(index, slice):
            return [self[i] for i in range(self.size)[index]]
        if index < 0:
            index += self.size
        if not 0 <= index < self.size:
            raise IndexError(index)
        found = self.explicit.get(index)
        return found if found is not None else self.unhandled(index)

    def __len__(self) -> int:
        return self.size

    def __iter__(self) -> Iterator[Tree]:
        return (self[i] for i in range(self.size))


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
    dispatch: tuple[Row, ...]  # [configuration][event]
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
