"""Tests that go through the implementation: its faults, monitors, completions and recovery.

The other cases send every event themselves, completions and faults included; these
make the device do its part, so a device that never reports a completion, whose fault
check never (or always) reports, or that resumes wrongly after a crash fails.

Rules:
1. Fault, per ``monitoring required`` state with a fault event leaving it (its monitor,
   :func:`statectl.front.observers.extract`): the shortest path into the state, then
   ``d.fault()`` (the device reports a fault, the monitor must raise the state's first
   fault event) and ``expect`` that event's transition, ``raised=[event]``.
2. Monitor, per such state: the same path, then ``d.assert_monitored(state)``: a
   monitor runs there and polls, and raises nothing while the device has no fault.
3. Completion, per call (observer method, the event that notified it) whose call the
   device completes (:mod:`statectl.kernel.semantics.calls`): the shortest path that
   makes the call, then ``d.complete(event)``: the device must report the completion
   within the timeout of a state the call entered, else the suite's completion bound;
   ``expect`` the completion's transition.
4. Recovery, per Recovery row: the shortest path whose last event enters the row's
   state (and no other row's), then ``d.restart()``, and ``expect`` the row's effect:
   its event's transition (``raised=[event]``), or for a redo the same states with the
   entering step's notifications issued again.
5. A path's events are sent with the data the explorer found for them (a completion
   whose guard reads the pressure it carries, a command with declared data), so a
   state reached only through such an event is probed too. A probe with no path (no
   such edge in the explored graph) is not written; the module's docstring notes it.
6. Every failure says what was expected and what happened, naming the state, the
   event and the call (:class:`~statectl.out.testgen.harness.DeviceUnderTest`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from statectl.front.observers import extract
from statectl.front.tables import RecoveryRow
from statectl.kernel.model import EventKind
from statectl.kernel.semantics import compiled
from statectl.kernel.semantics import step as kernel_step
from statectl.kernel.semantics.calls import DeviceCalls
from statectl.out.escape.python import identifier, string
from statectl.out.testgen.paths import Edge, Graph, Node, leaves, notifies
from statectl.out.testgen.timing import describe_state

__all__ = ["Probe", "path_items", "probes_for"]


@dataclass(frozen=True, slots=True)
class Probe:
    """One test through the implementation: a path, one action, what must follow."""

    name: str
    doc: str
    data: tuple[tuple[str, Any], ...]
    given: tuple[str, ...]
    action: str  # the line that acts: d.fault(), d.complete(...), d.restart(), ...
    states: tuple[str, ...] = ()
    invokes: tuple[tuple[int, str], ...] = ()
    raised: tuple[str, ...] | None = None  # None: no expect line (assert_monitored checks)
    given_data: tuple[Any, ...] = ()  # per event of ``given``, the data it is sent with


def path_items(edges: Sequence[Edge]) -> tuple[tuple[str, ...], tuple[Any, ...]]:
    """The events of ``edges`` and, per event, the data it is sent with (None: none):
    what a test sends to follow that path (rule 5)."""
    return tuple(e.event for e in edges), tuple(e.data for e in edges)


def _nodes(g: Graph) -> list[Node]:
    """Every node reached, in breadth-first order (start nodes first)."""
    seen = [n for n in g.start]
    seen += [e.target for e in g.edges if g.parent.get(e.target) is e]
    return seen


def _fault_probes(g: Graph, name: Callable[[str], str]) -> tuple[list[Probe], list[str]]:
    probes: list[Probe] = []
    notes: list[str] = []
    states = {s.name: s for s in g.chart.states}
    for i, spec in enumerate((m for m in extract(g.chart).monitors if m.raises), 1):
        fault = spec.raises[0]
        found = next(
            (
                e
                for e in g.edges
                if e.event == fault
                and e.data is None
                and spec.state in e.source.snapshot.active
                and e.step.unhandled is None
            ),
            None,
        )
        where = describe_state(states[spec.state])
        if found is None:
            notes.append(f"{where}: no path reaches it with {fault} handled; no fault test")
            continue
        given, sent = path_items(g.path(found.source))
        data = tuple(g.overrides(found.source).items())
        slug = identifier(spec.state)
        probes.append(
            Probe(
                name(f"test_fault_{i:02d}_{slug}"),
                f"{where} requires monitoring: a fault the device reports there is raised as "
                f"{fault}, and its transition follows.",
                data,
                given,
                "d.fault()",
                leaves(g.chart, found.step.target),
                tuple((n.invoke, n.method) for n in notifies(found.step)),
                (fault,),
                sent,
            )
        )
        probes.append(
            Probe(
                name(f"test_monitor_{i:02d}_{slug}"),
                f"{where} requires monitoring: its monitor runs there and polls, raising "
                "nothing while the device reports no fault.",
                data,
                given,
                f"d.assert_monitored({_q(spec.state)})",
                given_data=sent,
            )
        )
    return probes, notes


def _within(g: Graph, node: Node) -> float | None:
    """The shortest timeout of a state active in ``node``: the completion's bound there."""
    due = [
        s.timeout.seconds
        for s in g.chart.states
        if s.timeout is not None and s.name in node.snapshot.active
    ]
    return min(due) if due else None


def _completion_probes(g: Graph, name: Callable[[str], str]) -> tuple[list[Probe], list[str]]:
    calls = DeviceCalls(g.chart)
    kinds = {e.name: e.kind for e in g.chart.events}
    seen: set[tuple[str, str]] = set()
    probes: list[Probe] = []
    unsure: dict[tuple[str, str], str] = {}  # calls whose completion needs the device's data
    for e in g.edges:
        if e.step.unhandled is not None:
            continue
        if kinds.get(e.event) is EventKind.COMPLETION:
            continue
        for n in notifies(e.step):
            key = (n.method, e.event)
            if key in seen:
                continue
            completions = calls.call(n.method, e.event).completions
            follow = next(
                (
                    x
                    for x in g.edges
                    if x.source == e.target and x.data is None and x.event in completions
                    and x.step.unhandled is None
                ),
                None,
            )  # fmt: skip
            if follow is None:
                if any(x.source == e.target and x.event in completions for x in g.edges):
                    unsure[key] = (
                        f"{n.method}() called by {e.event}: {' or '.join(completions)} is taken "
                        "only with the data the device reports (its guards read it); no "
                        "completion test"
                    )
                continue
            seen.add(key)
            within = _within(g, e.target)
            given, sent = path_items((*g.path(e.source), e))
            bound = f"{within:g} s (its state's timeout)" if within else "the suite's bound"
            arg = f", within={within!r}" if within else ""
            probes.append(
                Probe(
                    name(f"test_completion_{len(probes) + 1:02d}_{identifier(n.method)}"
                         f"_after_{identifier(e.event)}"),
                    f"{n.method}() called by {e.event}: the device reports {follow.event} "
                    f"within {bound}, and its transition follows.",
                    tuple(g.overrides(e.source).items()),
                    given,
                    f"d.complete({_q(follow.event)}{arg})",
                    leaves(g.chart, follow.step.target),
                    tuple((x.invoke, x.method) for x in notifies(follow.step)),
                    (follow.event,),
                    sent,
                )
            )  # fmt: skip
    return probes, [text for key, text in unsure.items() if key not in seen]


def _recovery_probes(
    g: Graph, rows: Sequence[RecoveryRow], name: Callable[[str], str]
) -> tuple[list[Probe], list[str]]:
    probes: list[Probe] = []
    notes: list[str] = []
    ruled = {r.state for r in rows}
    machine = compiled(g.chart)
    for i, r in enumerate(rows, 1):
        where = f"Recovery row {i}" + (f", {_where(r)}" if r.origin.file else "")
        entering = next(
            (
                e
                for e in g.edges
                if g.parent.get(e.target) is e
                and r.state in e.target.snapshot.active
                and r.state not in e.source.snapshot.active
                and len(ruled & e.target.snapshot.active) == 1
            ),
            None,
        )
        if entering is None:
            notes.append(f"{where}: no path enters {r.state} alone; its rule is not tested")
            continue
        node = entering.target
        given, sent = path_items(g.path(node))
        if r.redo:
            redone = ", ".join(f"{n.method}()" for n in notifies(entering.step))
            what = f"{r.state} is redone ({redone})"
            raised: tuple[str, ...]
            states, invokes, raised = (
                leaves(g.chart, node.snapshot),
                tuple((n.invoke, n.method) for n in notifies(entering.step)),
                (),
            )
        else:
            decided = kernel_step(machine, node.snapshot, r.event, dict(g.datas[node.data]), r.data)
            what = f"{r.event} is taken"
            states = leaves(g.chart, decided.target)
            invokes = tuple((n.invoke, n.method) for n in notifies(decided))
            raised = (r.event,)
        probes.append(
            Probe(
                name(f"test_recovery_{i:02d}_{identifier(r.state)}"),
                f"{where}: a device stopped in {r.state} resumes there and {what} first.",
                tuple(g.overrides(node).items()),
                given,
                "d.restart()",
                states,
                invokes,
                raised,
                sent,
            )
        )
    return probes, notes


def _where(r: RecoveryRow) -> str:
    o = r.origin
    return f"{Path(o.file).name}:{o.line}" if o.line is not None else Path(o.file).name


def _q(text: str) -> str:
    return string(text)


def probes_for(
    g: Graph, rows: Sequence[RecoveryRow], used: Callable[[str], str]
) -> tuple[list[Probe], list[str]]:
    """Every probe of ``g`` (rules 1-4) and notes on those not made (rule 5)."""
    faults, notes = _fault_probes(g, used)
    completions, unsure = _completion_probes(g, used)
    recovery, more = _recovery_probes(g, rows, used)
    return [*faults, *completions, *recovery], [*notes, *unsure, *more]
