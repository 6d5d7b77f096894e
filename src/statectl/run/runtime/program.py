"""A step as a program: the ordered effects the runtime performs for one kernel decision.

Rules:
1. The kernel decides a step (:class:`~statectl.kernel.semantics.Step`); a
   :class:`Program` is that decision compiled once for performing it: its outcome,
   its target and the target's plan table, and its effects in the order they happen.
   Per microstep: one :class:`Transit` (what it exited, the transitions it took, what
   it entered), then an :class:`Exit` per state exited, an :class:`Enter` per state
   entered (a monitor or a timer of that state starts or stops there), then the
   microstep's notifications (the kernel's ``Notify``, with its invoke number).
2. A program holds no wiring: every device running the chart shares it. Programs are
   kept per kernel step, so a plan (one per snapshot and event) compiles once; the
   engine binds a program to a device's sinks (:mod:`statectl.run.runtime.engine`).
3. An event that changed nothing is a program too: its outcome says why and it has no
   effects. A program also keeps the builder of its step's typed records
   (:class:`~statectl.run.runtime.records.Builder`), made when they are first read.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import msgspec

from statectl.kernel.model import Notify
from statectl.kernel.semantics import Outcome, PlanTable, Snapshot, Step
from statectl.run.runtime.records import Builder, Taken, taken

__all__ = ["Effect", "Enter", "Exit", "Program", "Transit", "program_of", "unstepped"]


@dataclass(frozen=True, slots=True)
class Transit:
    """One microstep's transition: the states it ``exited``, the transitions it took, the
    states it ``entered`` (what a ``MicrostepTaken`` record says)."""

    event: str | None
    exited: tuple[str, ...]
    taken: tuple[Taken, ...]
    entered: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Exit:
    """A state left: its watchers (a monitor, a timer) hear ``exited``."""

    state: str


@dataclass(frozen=True, slots=True)
class Enter:
    """A state entered: its watchers (a monitor, a timer) hear ``entered``."""

    state: str


#: One effect of a step, in the order it happens (rule 1).
Effect = Transit | Exit | Enter | Notify


class Program(msgspec.Struct, frozen=True, eq=False):
    """One step compiled for performing (rule 1): compared by identity, shared (rule 2).

    A frozen struct, not a frozen dataclass: a device makes one for each event that
    changed nothing the first time it meets it, and a frozen dataclass is built field
    by field through ``object.__setattr__`` (about seven times as long)."""

    event: str | None
    step: Step | None  # None for an event the chart does not know
    outcome: Outcome
    target: Snapshot
    table: PlanTable  # the target's plans
    effects: tuple[Effect, ...]
    invokes: int  # notifications among the effects
    final: bool  # the step reaches a top-level final state
    records: Builder = msgspec.field(default_factory=Builder)  # the typed records, when read


def _effects(step: Step) -> tuple[Effect, ...]:
    out: list[Effect] = []
    for micro in step.microsteps:
        out.append(Transit(micro.event, micro.exited, taken(micro), micro.entered))
        out.extend(Exit(s) for s in micro.exited)
        out.extend(Enter(s) for s in micro.entered)
        out.extend(a for a in micro.actions if isinstance(a, Notify))
    return tuple(out)


#: Programs of handled kernel steps (by identity, the step kept to check it): plans and
#: the kernel's memo keep their steps, so a step compiles once. Bounded: it starts again
#: when full. An unhandled step's program (no effects) is made when asked for.
_PROGRAMS: dict[int, tuple[Step, Program]] = {}
_PROGRAMS_MAX = 16_384
_compiling = threading.Lock()


def program_of(step: Step, table: PlanTable) -> Program:
    """The program of a kernel ``step`` whose target's plan table is ``table``."""
    if not step.handled:
        reason = step.unhandled or Outcome.NO_TRANSITION
        return Program(step.event, step, reason, step.target, table, (), 0, False)
    hit = _PROGRAMS.get(id(step))
    if hit is not None and hit[0] is step:
        return hit[1]
    effects = _effects(step)
    invokes = sum(type(e) is Notify for e in effects)
    made = Program(
        step.event, step, Outcome.HANDLED, step.target, table, effects, invokes, step.final
    )
    with _compiling:  # one program per step, whichever thread compiles it first
        hit = _PROGRAMS.get(id(step))
        if hit is not None and hit[0] is step:
            return hit[1]
        if len(_PROGRAMS) >= _PROGRAMS_MAX:
            _PROGRAMS.clear()
        _PROGRAMS[id(step)] = (step, made)
    return made


def unstepped(event: str, snapshot: Snapshot, table: PlanTable) -> Program:
    """The program of an event the chart does not know: nothing happens, and why."""
    return Program(event, None, Outcome.UNKNOWN_EVENT, snapshot, table, (), 0, False)
