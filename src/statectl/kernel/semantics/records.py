"""The values the kernel passes around: snapshots, steps, plans, queued events.

A :class:`Snapshot` is all the semantics remembers between steps; a :class:`Step`
is the decision for one event. :class:`Run` is the only mutable record: the
scratch of one interpretation, which :func:`~statectl.kernel.semantics.step` never lets
escape and an SCXML session keeps for its whole life.
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Action, Notify, State, Transition

__all__ = [
    "MAX_GUARD_PATHS",
    "MAX_MICROSTEPS",
    "MEMO_LIMIT",
    "Consult",
    "Event",
    "Executor",
    "GuardOracle",
    "LivelockError",
    "Microstep",
    "Outcome",
    "Plan",
    "PlanTable",
    "Run",
    "Snapshot",
    "Step",
    "Unhandled",
]

#: Bound on microsteps in one macrostep; a chart that exceeds it loops forever.
MAX_MICROSTEPS = 10_000
#: Bound on memoised steps (and interned snapshots) per machine.
MEMO_LIMIT = 100_000
#: Bound on the guard outcomes memoised for one (snapshot, event) of a data-guarded step.
MAX_GUARD_PATHS = 64

History = tuple[tuple[str, tuple[str, ...]], ...]


class LivelockError(StatectlError):
    """Eventless or raised transitions that never settle."""


class Outcome(enum.StrEnum):
    """What an event did: :attr:`HANDLED`, or why it changed nothing.

    The one answer the runtime, explorer, C++ and journal give. A ``str`` enum: its value
    is what records, reports and journals show and store (``"handled"``, ``"guard
    false"``...), so it compares equal to those strings.
    """

    HANDLED = "handled"  # a transition was taken for the event
    DECLARED_IGNORED = "declared ignored"  # the state table lists it in an active state
    GUARD_FALSE = "guard false"  # a transition exists for it, but no guard held
    NO_TRANSITION = "no transition"  # no transition and not declared ignored
    UNKNOWN_EVENT = "unknown event"  # not an event of the chart (decided by the host)
    GUARD_ERROR = "guard error"  # a guard raised: refused, never a silent false (eventview)


#: Why an event changed nothing: an :class:`Outcome` other than ``HANDLED`` (the name
#: the kernel's ``Step.unhandled``, records and reports use for the reasons).
Unhandled = Outcome


@dataclass(frozen=True, slots=True)
class Snapshot:
    """All the semantics remembers between steps: active states, history, previous state.

    ``previous`` is the atomic state left by the last transition that changed the
    configuration; device tables use it in guards ("the previous state was Moving").
    """

    active: frozenset[str]
    history: History = ()
    previous: str | None = None


@dataclass(frozen=True, slots=True)
class Microstep:
    event: str | None
    transitions: tuple[Transition, ...]
    exited: tuple[str, ...]
    entered: tuple[str, ...]
    actions: tuple[Action, ...]


@dataclass(frozen=True, slots=True)
class Step:
    """The decision for one external event (or for start-up, ``event=None``).

    ``entered`` and ``exited`` are the states each microstep entered and exited, in
    order (exit order, then document order per microstep); ``unhandled`` is why an
    event changed nothing (``None`` when it was handled).
    """

    event: str | None
    source: Snapshot
    target: Snapshot
    microsteps: tuple[Microstep, ...]
    handled: bool  # a transition was taken for the external event
    ignored: bool  # unhandled, but declared ignored in an active state
    final: bool  # a top-level final state was reached
    guarded: bool = False  # a guard over data (or a forced one) was consulted
    unhandled: Unhandled | None = None  # why not handled; None when handled
    failure: Any = None  # the GuardFailure of a GUARD_ERROR step (semantics.eventview)

    @property
    def actions(self) -> tuple[Action, ...]:
        return tuple(a for m in self.microsteps for a in m.actions)

    @property
    def transitions(self) -> tuple[Transition, ...]:
        return tuple(t for m in self.microsteps for t in m.transitions)

    @property
    def exited(self) -> tuple[str, ...]:
        """States exited, per microstep in exit order (children before parents)."""
        return tuple(s for m in self.microsteps for s in m.exited)

    @property
    def entered(self) -> tuple[str, ...]:
        """States entered, per microstep in document order (parents before children)."""
        return tuple(s for m in self.microsteps for s in m.entered)


@dataclass(frozen=True, slots=True)
class Event:
    """An event on a queue, with the fields SCXML's ``_event`` exposes."""

    name: str
    data: Any = None
    type: str = "internal"  # "internal", "external" or "platform"
    sendid: str = ""
    origin: str = ""
    origintype: str = ""
    invokeid: str = ""


class Executor(Protocol):
    """What a host supplies to run executable content at the spec's points."""

    def condition(self, run: Run, transition: Transition) -> bool:
        """Evaluate ``transition.guard``; a failure is false (and the host's error event)."""
        ...

    def execute(self, run: Run, actions: tuple[Action, ...]) -> None:
        """Perform one block of executable content; raise events into ``run.internal``."""
        ...

    def state_entered(self, run: Run, state: State) -> None:
        """Called after ``state`` joins the configuration, before its onentry."""
        ...

    def state_exited(self, run: Run, state: State) -> None:
        """Called after ``state``'s onexit, before it leaves the configuration."""
        ...

    def done_data(self, run: Run, state: State) -> Any:
        """The data of the ``done.state`` event for entering the final ``state``."""
        ...


@dataclass(slots=True)
class Run:
    """The mutable state of one interpretation: configuration, history, internal queue.

    :func:`step` makes one per macrostep and never lets it escape; a host with an
    :class:`Executor` keeps one for a whole session and drives it with
    :func:`enter_initial_states`, :func:`macrostep` and :func:`process_event`.
    """

    active: set[str]
    history: dict[str, tuple[str, ...]]
    previous: str | None
    data: Mapping[str, Any]
    event: str | None = None
    guarded: bool = False
    internal: deque[Event] = field(default_factory=deque)
    final: bool = False  # a top-level final state was entered (the session stops running)
    final_state: str | None = None
    current: Event | None = None  # the event being processed: SCXML's ``_event``
    executor: Executor | None = None
    oracle: GuardOracle | None = None
    # the guards over data consulted, in order, with what they saw (see machine.GuardTrie)
    consulted: list[Consult] | None = None
    failures: list[Any] | None = None  # guards that raised (semantics.eventview rule 3)

    def failed(self, failure: Any) -> None:
        """Note a guard that raised; the step it is part of is refused."""
        if self.failures is None:
            self.failures = []
        self.failures.append(failure)

    def raise_event(self, event: Event) -> None:
        """Append to the internal queue (``<raise>``, ``error.*``, ``done.state.*``)."""
        self.internal.append(event)


@dataclass(frozen=True, slots=True, eq=False)
class Plan:
    """A memoised step of a declared event, compiled for the host that performs it.

    ``target`` is interned and ``table`` is its own plan table (shared, filled as
    steps are memoised). ``notifies`` is every ``Notify`` of the step in order, each
    with a machine-wide slot number under which a host may cache what it builds for
    it (a notification without data, say). ``entered``, ``exited`` and ``unhandled``
    are the step's, kept here so a host hooking state changes reads a tuple.
    """

    step: Step
    target: Snapshot
    table: dict[str, Plan]
    notifies: tuple[tuple[int, Notify], ...]
    handled: bool
    final: bool
    entered: tuple[str, ...] = ()  # the step's ``entered``, computed once
    exited: tuple[str, ...] = ()  # the step's ``exited``, computed once
    unhandled: Unhandled | None = None  # the step's reason when not handled


PlanTable = dict[str, Plan]

#: Forces guard outcomes through the kernel: ``oracle(run, transition)`` returns the
#: guard's value, or ``None`` to let the kernel evaluate it as usual. A step taken
#: with an oracle is never memoised (an explorer or a code generator asks "what if").
#: An oracle that raises is a guard that raised: the step is refused as
#: :attr:`Unhandled.GUARD_ERROR`, as when the kernel evaluates the guard itself.
GuardOracle = Callable[[Run, Transition], "bool | None"]


@dataclass(frozen=True, slots=True)
class Consult:
    """A guard over data evaluated during a step, with the context it was evaluated in.

    The configuration, ``previous`` and event name at that point follow from the
    source snapshot and the outcomes of the earlier consults, so a memoised step
    re-evaluates its consults in order and needs no rebuilding.
    """

    guard: str
    previous: str | None
    active: frozenset[str]
    event: str | None
    external: bool  # the event is the step's external one: its data is ``_event.data``
    data: Any  # otherwise the (internal) event's data
    value: bool
