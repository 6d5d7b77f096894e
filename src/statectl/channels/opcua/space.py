"""What a device looks like over OPC UA, worked out from its chart alone (no asyncua, no I/O).

Rules:
1. A device's states are numbered 1.. in chart order (history pseudo-states are
   not states a client can be in, so they get none); a state with a ``number`` in
   its table (a standard's, docs/profiles.md) keeps it, and then the others count
   on from the highest given one. Its transitions are numbered 1.. in chart
   order. The numbers are the ``StateNumber`` / ``TransitionNumber`` properties and
   the ``Number`` of ``CurrentState`` / ``LastTransition``.
2. A *machine* is one set of sibling states (OPC 10000-16: a finite state machine
   is in exactly one of its states). The device's top-level states form its main
   machine; a compound state's children form a sub-state machine of the state,
   named ``SubStateMachine``; each region of a parallel state forms its own
   sub-state machine named after the region, the regions siblings. A sub-state
   machine is a component of its state (so names never clash). A chart whose
   only top-level state is parallel gives the device one sibling machine per
   region instead of a main machine.
3. A transition belongs to the machine holding its source state; its ``ToState``
   is the target's ancestor in that machine (a transition into a sub-state machine
   points at the state that holds it); a target outside the machine has none.
4. The command events (declared ``command``, or used by a transition and not
   declared at all) become the device's methods.
"""

from __future__ import annotations

from dataclasses import dataclass

from statectl.kernel.model import Chart, EventKind, Notify, StateKind
from statectl.kernel.semantics import Step
from statectl.run.runtime.records import InvokeIssued, Taken, taken

__all__ = ["Change", "Layout", "MachineSpec", "changes", "layout"]


@dataclass(frozen=True, slots=True)
class MachineSpec:
    """One state machine instance: its browse name, where it hangs and its states."""

    name: str
    parent: int | None  # index of the machine it is a sub-state machine of
    holder: str | None  # the state whose sub-state machine it is (HasSubStateMachine)
    states: tuple[str, ...]
    transitions: tuple[int, ...]  # transition numbers (rule 3)


@dataclass(frozen=True, slots=True)
class Layout:
    """A device's machines, its state and transition numbers and its commands."""

    machines: tuple[MachineSpec, ...]
    state_numbers: dict[str, int]
    transition_names: dict[int, str]
    #: transition number -> (source, target in its machine or None)
    ends: dict[int, tuple[str, str | None]]
    #: (source, targets, label) of a transition taken (a ``Taken``) -> transition number
    by_record: dict[tuple[str, tuple[str, ...], str], int]
    commands: tuple[str, ...]


def layout(chart: Chart) -> Layout:
    """The device's machines and numbers (rules 1-4)."""
    states = [s for s in chart.states if not s.kind.is_history]
    given = [s.number for s in states if s.number is not None]
    after = iter(range(max(given, default=0) + 1, len(states) + max(given, default=0) + 1))
    numbers = {s.name: s.number if s.number is not None else next(after) for s in states}
    machines: list[MachineSpec] = []
    home: dict[str, int] = {}  # state -> the machine that holds it

    def kids(parent: str | None) -> tuple[str, ...]:
        return tuple(s.name for s in chart.children(parent) if not s.kind.is_history)

    def region_states(region: str) -> tuple[str, ...]:
        return kids(region) if chart.state(region).kind is StateKind.COMPOUND else (region,)

    def add(name: str, parent: int | None, holder: str | None, members: tuple[str, ...]) -> None:
        at = len(machines)
        machines.append(MachineSpec(name, parent, holder, members, ()))
        for m in members:
            home[m] = at
        for m in members:
            st = chart.state(m)
            if st.kind is StateKind.COMPOUND:
                add("SubStateMachine", at, m, kids(m))
            elif st.kind is StateKind.PARALLEL:
                for region in kids(m):
                    inner = chart.state(region)
                    add(
                        region,
                        at,
                        m,
                        kids(region) if inner.kind is StateKind.COMPOUND else (region,),
                    )

    top = kids(None)
    if len(top) == 1 and chart.state(top[0]).kind is StateKind.PARALLEL:
        for region in kids(top[0]):
            add(region, None, None, region_states(region))
    else:
        add("StateMachine", None, None, top)

    def in_machine(state: str, at: int) -> str | None:
        node: str | None = state
        while node is not None:
            if home.get(node) == at:
                return node
            node = chart.state(node).parent
        return None

    owned: dict[int, list[int]] = {}
    names: dict[int, str] = {}
    ends: dict[int, tuple[str, str | None]] = {}
    by_record: dict[tuple[str, tuple[str, ...], str], int] = {}
    used: set[tuple[int, str]] = set()
    for number, t in enumerate(chart.transitions, 1):
        at = home.get(t.source)
        if at is None:
            continue
        target = in_machine(t.targets[0], at) if t.targets else t.source
        name = f"{t.source} to {target or '/'.join(t.targets)}"
        if t.events:
            name += f" on {' '.join(t.events)}"
        if (at, name) in used:
            name += f" #{number}"
        used.add((at, name))
        owned.setdefault(at, []).append(number)
        names[number] = name
        ends[number] = (t.source, target)
        by_record.setdefault((t.source, t.targets, t.label), number)
    machines = [
        MachineSpec(m.name, m.parent, m.holder, m.states, tuple(owned.get(i, ())))
        for i, m in enumerate(machines)
    ]
    declared = {e.name: e.kind for e in chart.events}
    commands = tuple(
        e for e in chart.event_names if declared.get(e, EventKind.COMMAND) is EventKind.COMMAND
    )
    return Layout(tuple(machines), numbers, names, ends, by_record, commands)


#: What the server publishes of a step: a transition it took, or a notification it issued.
Change = Taken | InvokeIssued


def changes(device: str, time: float, step: Step) -> list[Change]:
    """The transitions a step took and the notifications it issued, in the step's order."""
    out: list[Change] = []
    for micro in step.microsteps:
        out.extend(taken(micro))
        out.extend(
            InvokeIssued(device, time, a.invoke, a.name, a.method, a.event)
            for a in micro.actions
            if isinstance(a, Notify)
        )
    return out
