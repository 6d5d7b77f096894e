"""The pure kernel: what happens when an event meets a configuration.

Follows the algorithm of the W3C SCXML recommendation (Appendix D) and names its
parts after it, so the pseudocode can be read beside this file. Rules:

1. :func:`initial` and :func:`step` return a :class:`Step` that *describes* the
   exit set, the transitions taken, the entry set and the actions to perform;
   nothing is performed here (no observer is called, no clock is read).
2. A step is one macrostep: the external event's microstep, then eventless
   transitions and internally raised events (``Raise``, ``done.state.*``) until
   the configuration is stable, which is run-to-completion.
3. Transition selection is in document order of the active atomic states; a
   state's own transitions before its ancestors'; conflicts are resolved by
   :func:`remove_conflicting_transitions` (a descendant's transition preempts).
4. A chart is compiled once (:class:`Machine`): ancestors, descendants,
   candidate transitions per (state, event), static transition domains and
   compiled guards. Where no guard was consulted a step depends only on
   ``(snapshot, event)`` and is memoised, so dispatch is close to a lookup.
   A memoised step of a declared event is also kept as a :class:`Plan` in the
   plan table of its (interned) source snapshot; a plan points at its target's
   table, so a host walks from table to table with one dictionary lookup per
   event. Plans are decisions too: the host still performs them.
5. A host that runs executable content (the SCXML session) drives the same
   functions one microstep at a time through a :class:`Run` that carries an
   :class:`Executor`. The executor evaluates conditions and performs content at
   the spec's points, in order: each exited state's onexit, the transitions'
   content, then per entered state its onentry, initial and history content, and
   the ``done.state`` events. Events it raises go straight to the internal queue,
   so the queue order is the spec's. Without an executor, ``Raise`` is the only
   content the kernel acts on (it queues the event at once); the rest is returned.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from statectl.errors import DiagnosticError, StatectlError
from statectl.expr import Expression, compile_expression
from statectl.model import Action, Chart, Notify, Raise, State, StateKind, Transition

__all__ = [
    "Event",
    "Executor",
    "LivelockError",
    "Machine",
    "Microstep",
    "Plan",
    "Run",
    "Snapshot",
    "Step",
    "compiled",
    "enter_initial_states",
    "exit_interpreter",
    "initial",
    "macrostep",
    "microstep",
    "name_match",
    "process_event",
    "select_eventless_transitions",
    "select_transitions",
    "step",
]

#: Bound on microsteps in one macrostep; a chart that exceeds it loops forever.
MAX_MICROSTEPS = 10_000
#: Bound on memoised steps (and interned snapshots) per machine.
MEMO_LIMIT = 100_000

History = tuple[tuple[str, tuple[str, ...]], ...]


class LivelockError(StatectlError):
    """Eventless or raised transitions that never settle."""


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
    """The decision for one external event (or for start-up, ``event=None``)."""

    event: str | None
    source: Snapshot
    target: Snapshot
    microsteps: tuple[Microstep, ...]
    handled: bool  # a transition was taken for the external event
    ignored: bool  # unhandled, but declared ignored in an active state
    final: bool  # a top-level final state was reached
    guarded: bool = False  # a guard was consulted (the step is not memoised)

    @property
    def actions(self) -> tuple[Action, ...]:
        return tuple(a for m in self.microsteps for a in m.actions)

    @property
    def transitions(self) -> tuple[Transition, ...]:
        return tuple(t for m in self.microsteps for t in m.transitions)

    @property
    def exited(self) -> tuple[str, ...]:
        return tuple(s for m in self.microsteps for s in m.exited)

    @property
    def entered(self) -> tuple[str, ...]:
        return tuple(s for m in self.microsteps for s in m.entered)


def name_match(descriptors: Iterable[str], event: str) -> bool:
    """SCXML event matching: ``error`` matches ``error`` and ``error.execution``; ``*`` all."""
    for d in descriptors:
        if d == "*" or d == event:
            return True
        d = d.removesuffix(".*")
        if event.startswith(d) and event[len(d) : len(d) + 1] == ".":
            return True
    return False


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

    def raise_event(self, event: Event) -> None:
        """Append to the internal queue (``<raise>``, ``error.*``, ``done.state.*``)."""
        self.internal.append(event)


@dataclass(frozen=True, slots=True, eq=False)
class Plan:
    """A memoised step of a declared event, compiled for the host that performs it.

    ``target`` is interned and ``table`` is its own plan table (shared, filled as
    steps are memoised). ``notifies`` is every ``Notify`` of the step in order, each
    with a machine-wide slot number under which a host may cache what it builds for
    it (a notification without data, say).
    """

    step: Step
    target: Snapshot
    table: dict[str, Plan]
    notifies: tuple[tuple[int, Notify], ...]
    handled: bool
    final: bool


PlanTable = dict[str, Plan]


class Machine:
    """A chart compiled for stepping: static tables computed once at load."""

    def __init__(self, chart: Chart) -> None:
        self.chart = chart
        self.order: dict[str, int] = {s.name: i for i, s in enumerate(chart.states)}
        self.kind: dict[str, StateKind] = {s.name: s.kind for s in chart.states}
        self.parent: dict[str, str | None] = {s.name: s.parent for s in chart.states}
        self.initial_of: dict[str, tuple[str, ...]] = {}
        self.history_default: dict[str, tuple[str, ...]] = {}
        children: dict[str | None, list[str]] = {}
        for s in chart.states:
            children.setdefault(s.parent, []).append(s.name)
        self.children: dict[str | None, tuple[str, ...]] = {
            k: tuple(v) for k, v in children.items()
        }
        self.ancestors: dict[str, tuple[str, ...]] = {}
        for s in chart.states:
            chain: list[str] = []
            p = s.parent
            while p is not None:
                chain.append(p)
                p = self.parent[p]
            self.ancestors[s.name] = tuple(chain)
        self.descendants: dict[str | None, frozenset[str]] = {None: frozenset(self.order)}
        for s in chart.states:
            self.descendants[s.name] = frozenset(
                d for d in self.order if s.name in self.ancestors[d]
            )
        for s in chart.states:
            if s.kind is StateKind.COMPOUND:
                kids = [c for c in self.children.get(s.name, ()) if not self.kind[c].is_history]
                self.initial_of[s.name] = s.initial or (kids[:1] and (kids[0],)) or ()
            if s.kind.is_history:
                self.history_default[s.name] = s.history_default
        self.top_initial: tuple[str, ...] = chart.initial or self.children.get(None, ())[:1]
        self.transitions_of: dict[str, tuple[Transition, ...]] = {
            name: tuple(t for t in chart.transitions if t.source == name) for name in self.order
        }
        self.histories_of: dict[str, tuple[str, ...]] = {
            name: tuple(c for c in self.children.get(name, ()) if self.kind[c].is_history)
            for name in self.order
        }
        self.guards: dict[str, Expression] = {}
        problems = []
        # other datamodels' conditions are the executor's to evaluate
        for t in chart.transitions if chart.datamodel == "safe" else ():
            if t.guard and t.guard not in self.guards:
                expr, diags = compile_expression(t.guard, t.origin)
                problems.extend(diags)
                if expr is not None:
                    self.guards[t.guard] = expr
        if problems:
            raise DiagnosticError(problems)
        self.ignored = chart.ignored
        self._static_domain: dict[int, str | None] = {}
        for t in chart.transitions:
            if t.targets and not any(self.kind[x].is_history for x in t.targets):
                self._static_domain[id(t)] = self._domain(t, t.targets)
        self._candidates: dict[tuple[str, str | None], tuple[Transition, ...]] = {}
        self._memo: dict[tuple[Snapshot, str], Step] = {}
        self._initial: Step | None = None
        self.event_names: frozenset[str] = frozenset(chart.event_names)
        # interned snapshots with their plan tables, by value and by identity
        self._tables: dict[Snapshot, tuple[Snapshot, PlanTable]] = {}
        self._by_id: dict[int, tuple[Snapshot, PlanTable]] = {}
        self._slots: dict[int, int] = {}  # id(Notify) -> slot; the chart keeps them alive

    # -- plans ---------------------------------------------------------------------------

    def _entry(self, snapshot: Snapshot) -> tuple[Snapshot, PlanTable]:
        hit = self._by_id.get(id(snapshot))
        if hit is not None and hit[0] is snapshot:
            return hit
        entry = self._tables.get(snapshot)
        if entry is None:
            if len(self._tables) >= MEMO_LIMIT:
                return snapshot, {}  # not interned: its plans are not kept
            entry = self._tables.setdefault(snapshot, (snapshot, {}))
            self._by_id.setdefault(id(entry[0]), entry)
        return entry

    def intern(self, snapshot: Snapshot) -> Snapshot:
        """The one kept instance equal to ``snapshot``, so hosts compare and look up by identity."""
        return self._entry(snapshot)[0]

    def plans(self, snapshot: Snapshot) -> dict[str, Plan]:
        """The plan table of ``snapshot``: event -> :class:`Plan`, for the steps memoised so far.

        Read it, never write it; :func:`step` fills it.
        """
        return self._entry(snapshot)[1]

    def _install(self, snapshot: Snapshot, event: str, result: Step) -> None:
        table = self._entry(snapshot)[1]
        target, next_table = self._entry(result.target)
        slots = self._slots
        notifies = tuple(
            (slots.setdefault(id(a), len(slots)), a)
            for a in result.actions
            if isinstance(a, Notify)
        )
        table[event] = Plan(result, target, next_table, notifies, result.handled, result.final)

    # -- structure -------------------------------------------------------------------------

    def is_descendant(self, state: str, ancestor: str | None) -> bool:
        return ancestor is None or ancestor in self.ancestors[state]

    def is_atomic(self, state: str) -> bool:
        return self.kind[state] in (StateKind.ATOMIC, StateKind.FINAL)

    def candidates(self, atomic: str, event: str | None) -> tuple[Transition, ...]:
        """Transitions an atomic state offers for ``event``: its own first, then ancestors'."""
        key = (atomic, event)
        found = self._candidates.get(key)
        if found is None:
            out: list[Transition] = []
            for s in (atomic, *self.ancestors[atomic]):
                for t in self.transitions_of[s]:
                    eventless = event is None and not t.events
                    if eventless or (event is not None and name_match(t.events, event)):
                        out.append(t)
            found = self._candidates[key] = tuple(out)
        return found

    def _find_lcca(self, states: list[str]) -> str | None:
        head, tail = states[0], states[1:]
        for anc in self.ancestors[head]:
            if self.kind[anc] is StateKind.COMPOUND and all(
                self.is_descendant(s, anc) for s in tail
            ):
                return anc
        return None

    def _domain(self, t: Transition, targets: Iterable[str]) -> str | None:
        tstates = list(targets)
        if (
            t.internal
            and self.kind[t.source] is StateKind.COMPOUND
            and all(self.is_descendant(s, t.source) for s in tstates)
        ):
            return t.source
        return self._find_lcca([t.source, *tstates])


# -- the W3C algorithm ------------------------------------------------------------------------


def _in_env(run: Run, m: Machine, event_data: Any) -> dict[str, Any]:
    active = run.active
    env: dict[str, Any] = dict(run.data)
    env["previous"] = run.previous
    env["In"] = active.__contains__
    env["_event"] = {"name": run.event, "data": event_data}
    return env


def condition_match(m: Machine, run: Run, t: Transition, event_data: Any) -> bool:
    if not t.guard:
        return True
    run.guarded = True
    if run.executor is not None:
        return run.executor.condition(run, t)
    try:
        return bool(m.guards[t.guard].evaluate(_in_env(run, m, event_data)))
    except Exception:  # a failing guard is false, as in SCXML
        return False


def select_transitions(
    m: Machine, run: Run, event: str | None, event_data: Any = None
) -> list[Transition]:
    """Per active atomic state in document order, the first enabled transition; no conflicts.

    ``event=None`` selects eventless transitions (the spec's ``selectEventlessTransitions``).
    """
    enabled: list[Transition] = []
    atomic = sorted((s for s in run.active if m.is_atomic(s)), key=m.order.__getitem__)
    for state in atomic:
        for t in m.candidates(state, event):
            if condition_match(m, run, t, event_data):
                if t not in enabled:
                    enabled.append(t)
                break
    return remove_conflicting_transitions(m, run, enabled)


def select_eventless_transitions(m: Machine, run: Run) -> list[Transition]:
    return select_transitions(m, run, None)


def remove_conflicting_transitions(
    m: Machine, run: Run, enabled: list[Transition]
) -> list[Transition]:
    filtered: list[Transition] = []
    for t1 in enabled:
        preempted = False
        to_remove: list[Transition] = []
        exit1 = compute_exit_set(m, run, [t1])
        for t2 in filtered:
            if exit1 & compute_exit_set(m, run, [t2]):
                if m.is_descendant(t1.source, t2.source):
                    to_remove.append(t2)
                else:
                    preempted = True
                    break
        if not preempted:
            filtered = [t for t in filtered if t not in to_remove]
            filtered.append(t1)
    return filtered


def get_effective_target_states(m: Machine, run: Run, t: Transition) -> list[str]:
    targets: list[str] = []

    def add(names: Iterable[str]) -> None:
        for s in names:
            if m.kind[s].is_history:
                if s in run.history:
                    add(run.history[s])
                else:
                    add(m.history_default[s])
            elif s not in targets:
                targets.append(s)

    add(t.targets)
    return targets


def get_transition_domain(m: Machine, run: Run, t: Transition) -> str | None:
    static = m._static_domain.get(id(t), "")
    if static != "":
        return static
    return m._domain(t, get_effective_target_states(m, run, t))


def compute_exit_set(m: Machine, run: Run, transitions: list[Transition]) -> set[str]:
    to_exit: set[str] = set()
    for t in transitions:
        if t.targets:
            domain = get_transition_domain(m, run, t)
            to_exit |= run.active & m.descendants[domain]
    return to_exit


def _perform(run: Run, actions: tuple[Action, ...], record: list[Action]) -> None:
    """Perform one block of content now: by the executor, or (no executor) queue ``Raise``."""
    if not actions:
        return
    record.extend(actions)
    if run.executor is not None:
        run.executor.execute(run, actions)
        return
    for a in actions:
        if isinstance(a, Raise):
            run.raise_event(Event(a.event))


def _record_history(m: Machine, run: Run, to_exit: list[str]) -> None:
    for s in to_exit:
        for h in m.histories_of[s]:
            if m.kind[h] is StateKind.HISTORY_DEEP:
                saved = [x for x in run.active if m.is_atomic(x) and m.is_descendant(x, s)]
            else:
                saved = [x for x in run.active if m.parent[x] == s]
            run.history[h] = tuple(sorted(saved, key=m.order.__getitem__))


def _exit_ordered(m: Machine, run: Run, to_exit: list[str], actions: list[Action]) -> None:
    chart = m.chart
    for s in to_exit:
        state = chart.states[m.order[s]]
        _perform(run, state.on_exit, actions)
        if run.executor is not None:
            run.executor.state_exited(run, state)
        run.active.discard(s)


def exit_states(
    m: Machine, run: Run, enabled: list[Transition], actions: list[Action]
) -> list[str]:
    to_exit = sorted(compute_exit_set(m, run, enabled), key=m.order.__getitem__, reverse=True)
    _record_history(m, run, to_exit)
    _exit_ordered(m, run, to_exit, actions)
    return to_exit


def execute_transition_content(run: Run, enabled: list[Transition], actions: list[Action]) -> None:
    for t in enabled:
        _perform(run, t.actions, actions)


def compute_entry_set(
    m: Machine, run: Run, transitions: list[Transition]
) -> tuple[list[str], set[str], dict[str, tuple[Action, ...]]]:
    to_enter: list[str] = []
    default_entry: set[str] = set()
    history_content: dict[str, tuple[Action, ...]] = {}
    for t in transitions:
        for s in t.targets:
            add_descendant_states_to_enter(m, run, s, to_enter, default_entry, history_content)
        ancestor = get_transition_domain(m, run, t)
        for s in get_effective_target_states(m, run, t):
            add_ancestor_states_to_enter(
                m, run, s, ancestor, to_enter, default_entry, history_content
            )
    return to_enter, default_entry, history_content


def add_descendant_states_to_enter(
    m: Machine,
    run: Run,
    state: str,
    to_enter: list[str],
    default_entry: set[str],
    history_content: dict[str, tuple[Action, ...]],
) -> None:
    if m.kind[state].is_history:
        parent = m.parent[state]
        saved = run.history.get(state)
        if saved is not None:
            targets = saved
        else:
            targets = m.history_default[state]
            actions = m.chart.states[m.order[state]].history_actions
            if actions and parent is not None:
                history_content[parent] = actions
        for s in targets:
            add_descendant_states_to_enter(m, run, s, to_enter, default_entry, history_content)
        for s in targets:
            add_ancestor_states_to_enter(
                m, run, s, parent, to_enter, default_entry, history_content
            )
        return
    if state not in to_enter:
        to_enter.append(state)
    kind = m.kind[state]
    if kind is StateKind.COMPOUND:
        default_entry.add(state)
        targets = m.initial_of[state]
        for s in targets:
            add_descendant_states_to_enter(m, run, s, to_enter, default_entry, history_content)
        for s in targets:
            add_ancestor_states_to_enter(
                m, run, s, state, to_enter, default_entry, history_content
            )
    elif kind is StateKind.PARALLEL:
        for child in m.children.get(state, ()):
            if m.kind[child].is_history:
                continue
            if not any(m.is_descendant(s, child) or s == child for s in to_enter):
                add_descendant_states_to_enter(
                    m, run, child, to_enter, default_entry, history_content
                )


def add_ancestor_states_to_enter(
    m: Machine,
    run: Run,
    state: str,
    ancestor: str | None,
    to_enter: list[str],
    default_entry: set[str],
    history_content: dict[str, tuple[Action, ...]],
) -> None:
    for anc in m.ancestors[state]:
        if anc == ancestor:
            break
        if anc not in to_enter:
            to_enter.append(anc)
        if m.kind[anc] is StateKind.PARALLEL:
            for child in m.children.get(anc, ()):
                if m.kind[child].is_history:
                    continue
                if not any(m.is_descendant(s, child) or s == child for s in to_enter):
                    add_descendant_states_to_enter(
                        m, run, child, to_enter, default_entry, history_content
                    )


def is_in_final_state(m: Machine, run: Run, s: str) -> bool:
    kind = m.kind[s]
    if kind is StateKind.COMPOUND:
        return any(
            m.kind[c] is StateKind.FINAL and c in run.active for c in m.children.get(s, ())
        )
    if kind is StateKind.PARALLEL:
        return all(
            is_in_final_state(m, run, c)
            for c in m.children.get(s, ())
            if not m.kind[c].is_history
        )
    return False


def _enter_ordered(
    m: Machine,
    run: Run,
    to_enter: list[str],
    default_entry: set[str],
    history_content: dict[str, tuple[Action, ...]],
    actions: list[Action],
) -> list[str]:
    """The loop of ``enterStates``: per state in document order, content and done events."""
    ordered = sorted(to_enter, key=m.order.__getitem__)
    chart = m.chart
    executor = run.executor
    for s in ordered:
        state = chart.states[m.order[s]]
        run.active.add(s)
        if executor is not None:
            executor.state_entered(run, state)
        _perform(run, state.on_entry, actions)
        if s in default_entry:
            _perform(run, state.initial_actions, actions)
        if s in history_content:
            _perform(run, history_content[s], actions)
        if m.kind[s] is StateKind.FINAL:
            parent = m.parent[s]
            if parent is None:
                run.final = True
                run.final_state = s
            else:
                data = executor.done_data(run, state) if executor is not None else None
                run.raise_event(Event("done.state." + parent, data))
                grandparent = m.parent[parent]
                if (
                    grandparent is not None
                    and m.kind[grandparent] is StateKind.PARALLEL
                    and is_in_final_state(m, run, grandparent)
                ):
                    run.raise_event(Event("done.state." + grandparent))
    return ordered


def enter_states(
    m: Machine, run: Run, enabled: list[Transition], actions: list[Action]
) -> list[str]:
    to_enter, default_entry, history_content = compute_entry_set(m, run, enabled)
    return _enter_ordered(m, run, to_enter, default_entry, history_content, actions)


def microstep(m: Machine, run: Run, enabled: list[Transition], event: str | None) -> Microstep:
    """Exit, transition content, enter: one set of non-conflicting transitions taken."""
    actions: list[Action] = []
    exited = exit_states(m, run, enabled, actions)
    execute_transition_content(run, enabled, actions)
    entered = enter_states(m, run, enabled, actions)
    left_atomic = [s for s in exited if m.is_atomic(s)]
    if left_atomic:
        run.previous = left_atomic[0]
    return Microstep(event, tuple(enabled), tuple(exited), tuple(entered), tuple(actions))


def _check_livelock(m: Machine, steps: list[Microstep]) -> None:
    if len(steps) > MAX_MICROSTEPS:
        raise LivelockError(
            f"chart {m.chart.name!r} took more than {MAX_MICROSTEPS} microsteps "
            "without settling; look for eventless or raised transitions that loop"
        )


def macrostep(m: Machine, run: Run, steps: list[Microstep]) -> None:
    """Eventless transitions, then internal events, until stable (run-to-completion).

    The inner loop of the spec's ``mainEventLoop``; it stops early once a top-level
    final state is entered. Without an executor an eventless selection sees no
    ``_event``; with one, ``run.current`` keeps the last event, as in SCXML.
    """
    while not run.final:
        _check_livelock(m, steps)
        if run.executor is None:
            run.event = None
        enabled = select_eventless_transitions(m, run)
        if enabled:
            steps.append(microstep(m, run, enabled, None))
            continue
        if not run.internal:
            return
        internal = run.internal.popleft()
        run.current = internal
        run.event = internal.name
        enabled = select_transitions(m, run, internal.name, internal.data)
        if enabled:
            steps.append(microstep(m, run, enabled, internal.name))



def process_event(m: Machine, run: Run, event: Event) -> Microstep | None:
    """Select and take the transitions of one external event (the macrostep's first microstep)."""
    run.current = event
    run.event = event.name
    enabled = select_transitions(m, run, event.name, event.data)
    if not enabled:
        return None
    return microstep(m, run, enabled, event.name)


def enter_initial_states(m: Machine, run: Run) -> Microstep:
    """Enter the document's initial configuration (the spec's ``enterStates([initial])``)."""
    actions: list[Action] = []
    to_enter: list[str] = []
    default_entry: set[str] = set()
    history_content: dict[str, tuple[Action, ...]] = {}
    targets = m.top_initial
    for s in targets:
        add_descendant_states_to_enter(m, run, s, to_enter, default_entry, history_content)
    for s in targets:
        add_ancestor_states_to_enter(m, run, s, None, to_enter, default_entry, history_content)
    ordered = _enter_ordered(m, run, to_enter, default_entry, history_content, actions)
    return Microstep(None, (), (), tuple(ordered), tuple(actions))


def exit_interpreter(m: Machine, run: Run) -> list[str]:
    """Exit every active state in exit order, performing onexit (the spec's ``exitInterpreter``)."""
    to_exit = sorted(run.active, key=m.order.__getitem__, reverse=True)
    _exit_ordered(m, run, to_exit, [])
    return to_exit


def _snapshot(run: Run) -> Snapshot:
    return Snapshot(frozenset(run.active), tuple(sorted(run.history.items())), run.previous)


def initial(m: Machine, data: Mapping[str, Any] | None = None) -> Step:
    """Enter the chart's initial configuration and settle it (memoised when no guard ran)."""
    cached = m._initial
    if cached is not None:
        return cached
    run = Run(set(), {}, None, data or {})
    steps = [enter_initial_states(m, run)]
    macrostep(m, run, steps)
    empty = Snapshot(frozenset())
    target = m.intern(_snapshot(run))
    result = Step(None, empty, target, tuple(steps), True, False, run.final, run.guarded)
    if not run.guarded:
        m._initial = result
    return result


def step(
    m: Machine,
    snapshot: Snapshot,
    event: str,
    data: Mapping[str, Any] | None = None,
    event_data: Any = None,
) -> Step:
    """Process one external event to completion; return what happened, perform nothing."""
    hit = m._by_id.get(id(snapshot))
    if hit is not None and hit[0] is snapshot:
        plan = hit[1].get(event)
        if plan is not None:
            return plan.step
    key = (snapshot, event)
    cached = m._memo.get(key)
    if cached is not None:
        return cached
    run = Run(set(snapshot.active), dict(snapshot.history), snapshot.previous, data or {})
    steps: list[Microstep] = []
    first = process_event(m, run, Event(event, event_data, "external"))
    handled = first is not None
    ignored = False
    if first is not None:
        steps.append(first)
        macrostep(m, run, steps)
    else:
        ignored = any((s, event) in m.ignored for s in snapshot.active)
    result = Step(
        event,
        snapshot,
        m.intern(_snapshot(run)) if handled else snapshot,
        tuple(steps),
        handled,
        ignored,
        run.final,
        run.guarded,
    )
    if not run.guarded and len(m._memo) < MEMO_LIMIT:
        m._memo[key] = result
        if event in m.event_names:
            m._install(snapshot, event, result)
    return result


_COMPILED: dict[int, tuple[Chart, Machine]] = {}
_COMPILED_LIMIT = 256
_compiling = threading.Lock()


def compiled(chart: Chart) -> Machine:
    """The :class:`Machine` of ``chart`` shared by every host that only steps it.

    Compiling is the expensive part of a new instance; a chart is a value, so one
    compilation (and one memo) serves every instance of it in the process. A host
    that changes its machine (an explorer swapping guards) builds its own.
    """
    hit = _COMPILED.get(id(chart))
    if hit is not None and hit[0] is chart:
        return hit[1]
    with _compiling:
        hit = _COMPILED.get(id(chart))
        if hit is not None and hit[0] is chart:
            return hit[1]
        m = Machine(chart)
        if len(_COMPILED) >= _COMPILED_LIMIT:
            del _COMPILED[next(iter(_COMPILED))]
        _COMPILED[id(chart)] = (chart, m)
        return m
