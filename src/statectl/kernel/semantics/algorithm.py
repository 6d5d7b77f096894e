"""The W3C SCXML algorithm (Appendix D), one function per step of its pseudocode.

Every function takes the compiled :class:`~statectl.kernel.semantics.machine.Machine`
and the :class:`~statectl.kernel.semantics.records.Run` it works on;
:mod:`statectl.kernel.semantics.stepping` wraps them into pure, memoised decisions.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from statectl.kernel.model import Action, Raise, StateKind, Transition
from statectl.kernel.semantics.eventview import EventView, GuardFailure
from statectl.kernel.semantics.machine import Machine
from statectl.kernel.semantics.records import (
    MAX_MICROSTEPS,
    Consult,
    Event,
    LivelockError,
    Microstep,
    Run,
)

__all__ = [
    "compute_entry_set",
    "compute_exit_set",
    "condition_match",
    "enter_initial_states",
    "entry_set",
    "exit_interpreter",
    "get_transition_domain",
    "guard_env",
    "macrostep",
    "microstep",
    "process_event",
    "remove_conflicting_transitions",
    "select_eventless_transitions",
    "select_transitions",
]

# -- the W3C algorithm ------------------------------------------------------------------------


def guard_env(run: Run, event_data: Any = None) -> dict[str, Any]:
    """What a guard is evaluated over at this point of ``run``: data, ``previous``, ``In``."""
    env: dict[str, Any] = dict(run.data)
    env["previous"] = run.previous
    env["In"] = run.active.__contains__
    env["_event"] = EventView(run.event, event_data)
    return env


def _evaluate(m: Machine, guard: str, env: dict[str, Any]) -> bool:
    try:
        return bool(m.guards[guard].evaluate(env))
    except Exception:  # a failing guard is false, as in SCXML
        return False


def condition_match(m: Machine, run: Run, t: Transition, event_data: Any) -> bool:
    """Whether ``t``'s guard holds: the executor's, the oracle's or the kernel's answer.

    A guard that reads only the snapshot (``previous``, ``In()``) is decided by the
    step's source and event, so it leaves the step memoisable; a guard over data is
    noted in ``run.consulted`` with its context, so a memoised step re-evaluates it.
    """
    guard = t.guard
    if not guard:
        return True
    if run.executor is not None:
        run.guarded = True
        return run.executor.condition(run, t)
    oracle = run.oracle
    try:
        # an oracle evaluates the guard too: if it raises, the guard failed (GuardOracle)
        forced = oracle(run, t) if oracle is not None else None
        if forced is not None:
            run.guarded = True
            return forced
        value = bool(m.guards[guard].evaluate(guard_env(run, event_data)))
    except Exception as exc:  # no silent false (eventview rule 3): the host reports it
        value = False
        run.failed(GuardFailure(guard, run.event, t.origin, f"{type(exc).__name__}: {exc}"))
    if guard not in m.snapshot_guards:
        run.guarded = True
        consulted = run.consulted
        if consulted is not None:
            current = run.current
            external = current is not None and current.type == "external" and run.event is not None
            consulted.append(
                Consult(
                    guard,
                    run.previous,
                    frozenset(run.active),
                    run.event,
                    external,
                    None if external else event_data,
                    value,
                )
            )
    return value


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
    static = m.static_domains().get(id(t), "")
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


def entry_set(
    m: Machine, transitions: list[Transition], history: Mapping[str, tuple[str, ...]] | None = None
) -> tuple[str, ...]:
    """The states taking ``transitions`` enters, in document order (``None``: start-up).

    The answer every host asks for instead of walking the chart itself: targets,
    their ancestors below the transition domain, default children and every
    region of an entered parallel state. ``history`` is what history states hold
    (none recorded: their defaults).
    """
    if len(transitions) == 1:
        flat = _top_level_targets(m, transitions[0])
        if flat is not None:
            return flat
    run = Run(set(), dict(history or {}), None, {})
    if transitions:
        to_enter = compute_entry_set(m, run, transitions)[0]
    else:
        to_enter = []
        targets = m.top_initial
        for s in targets:
            add_descendant_states_to_enter(m, run, s, to_enter, set(), {})
        for s in targets:
            add_ancestor_states_to_enter(m, run, s, None, to_enter, set(), {})
    return tuple(sorted(to_enter, key=m.order.__getitem__))


def _top_level_targets(m: Machine, t: Transition) -> tuple[str, ...] | None:
    """What ``t`` enters when every target is an atomic state at the top level: exactly
    its targets (the domain is the root, so no ancestor and no default child is added);
    ``None`` for any other transition. A flat chart of 100,000 rows asks this per row."""
    targets = t.targets
    for s in targets:
        if m.parent[s] is not None or m.kind[s] is not StateKind.ATOMIC:
            return None
    if len(targets) == 1:
        return targets
    return tuple(sorted(set(targets), key=m.order.__getitem__))


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
            add_ancestor_states_to_enter(m, run, s, state, to_enter, default_entry, history_content)
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
        return any(m.kind[c] is StateKind.FINAL and c in run.active for c in m.children.get(s, ()))
    if kind is StateKind.PARALLEL:
        return all(
            is_in_final_state(m, run, c) for c in m.children.get(s, ()) if not m.kind[c].is_history
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
