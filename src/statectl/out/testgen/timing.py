"""Test cases for a state's timeout and for the events a state defers.

Rules:
1. Per state with a ``timeout`` cell: the shortest path to a configuration where that
   state is active and its timeout is the first one due (no other active state's timeout
   is as short), and the kernel's decision for the timeout event there. The test stalls
   the driver (its completions are dropped), advances the clock to just before the
   timeout (the state must still be active), then just past it, and expects that
   decision: the timeout transition taken, with its invokes.
2. Per (state, deferred event): the shortest path to the state, the event sent there
   (kept: declared ignored, nothing changes), then the first event that leaves the
   state; the expectation is that step followed by the kept event's release in the new
   configuration, handled there. A release the new configuration would not handle, or
   defers again, gives no case (the path search offers another leaving event first).
3. Cases are ordinary :class:`~statectl.out.testgen.cases.Case` values; ``wait`` says how
   long the timeout case waits instead of sending an event.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from statectl.kernel.model import State
from statectl.out.escape.python import identifier, string
from statectl.out.testgen.cases import Case, Expect
from statectl.out.testgen.paths import Edge, Graph, Node, leaves, notifies

__all__ = ["timing_cases"]

#: How much of a timeout the test waits before checking the state is still active.
BEFORE = 0.999


def slug(text: str) -> str:
    return identifier(text)


def describe_state(s: State) -> str:
    """``Closing (clamp.yaml:28)``: the state and where its row is."""
    o = s.origin
    if not o.file:
        return s.name
    name = Path(o.file).name
    return f"{s.name} ({name}:{o.line})" if o.line is not None else f"{s.name} ({name})"


def _timeouts_due(g: Graph, node: Node) -> list[float]:
    return [
        s.timeout.seconds
        for s in g.chart.states
        if s.timeout is not None and s.name in node.snapshot.active
    ]


def _timeout_case(g: Graph, name: Callable[[str], str], i: int, s: State) -> Case | None:
    assert s.timeout is not None
    seconds, event = s.timeout.seconds, s.timeout.event
    for e in g.edges:
        if e.event != event or e.data is not None or s.name not in e.source.snapshot.active:
            continue
        due = sorted(_timeouts_due(g, e.source))
        if due.count(seconds) != 1 or due[0] != seconds:
            continue
        path = g.path(e.source)
        if any(p.data is not None for p in path) or e.step.unhandled is not None:
            continue
        doc = (
            f"{describe_state(s)}: with the device silent, {s.name} is still active just "
            f"before {seconds:g} s and {event} is raised just after."
        )
        return Case(
            name(f"test_timeout_{i:02d}_{slug(s.name)}"),
            doc,
            tuple(g.overrides(e.source).items()),
            tuple(p.event for p in path),
            None,
            Expect(
                leaves(g.chart, e.step.target),
                tuple((n.invoke, n.method) for n in notifies(e.step)),
            ),
            wait=seconds,
            wait_states=leaves(g.chart, e.source.snapshot),
        )
    return None


def _release(g: Graph, node: Node, event: str) -> Edge | None:
    for e in g.edges:
        if e.source == node and e.event == event and e.data is None:
            return e
    return None


def _defer_case(g: Graph, name: Callable[[str], str], i: int, s: State, kept: str) -> Case | None:
    for e in g.edges:
        active = e.source.snapshot.active
        if s.name not in active or e.event == kept or e.data is not None:
            continue
        if e.step.unhandled is not None or s.name in e.step.target.active:
            continue
        path = g.path(e.source)
        if any(p.data is not None for p in path):
            continue
        out = _release(g, e.target, kept)
        if out is None or out.step.unhandled is not None:
            continue
        doc = (
            f"{describe_state(s)}: {kept} sent in {s.name} is kept (nothing changes), "
            f"then released once {e.event} leaves {s.name}."
        )
        return Case(
            name(f"test_defer_{i:02d}_{slug(kept)}_in_{slug(s.name)}"),
            doc,
            tuple(g.overrides(e.source).items()),
            tuple(p.event for p in path),
            e.event,
            Expect(
                leaves(g.chart, out.step.target),
                tuple((n.invoke, n.method) for n in (*notifies(e.step), *notifies(out.step))),
            ),
            kept=kept,
            wait_states=leaves(g.chart, e.source.snapshot),
        )
    return None


def timing_cases(g: Graph, name: Callable[[str], str]) -> tuple[list[Case], list[str]]:
    """The timeout and defer cases of ``g`` (rules 1-2), and notes on those not made."""
    cases: list[Case] = []
    notes: list[str] = []
    timed = [s for s in g.chart.states if s.timeout is not None]
    for i, s in enumerate(timed, 1):
        case = _timeout_case(g, name, i, s)
        if case is None:
            notes.append(f"{describe_state(s)}: no path reaches it with its timeout first due")
        else:
            cases.append(case)
    pairs = [(s, e) for s in g.chart.states for e in s.defer]
    for i, (s, kept) in enumerate(pairs, 1):
        case = _defer_case(g, name, i, s, kept)
        if case is None:
            notes.append(
                f"{describe_state(s)}: no path leaves it to a state that handles {kept}, "
                "so its release is not tested"
            )
        else:
            cases.append(case)
    return cases, notes


def timing_body(c: Case) -> str:
    """The lines of a timeout or defer case between its path and its ``d.expect`` (rule 1-2)."""
    states = ", ".join(_quoted(x) for x in c.wait_states)
    if c.wait:
        before = round(c.wait * BEFORE, 6)
        after = round(c.wait - before + c.wait * (1 - BEFORE), 6)
        return (
            "    d.stall()\n"
            f"    d.advance({before!r})\n"
            f"    d.assert_state({states})\n"
            f"    d.wait({after!r})\n"
        )
    return (
        f"    d.send({_quoted(c.kept)})\n"
        f'    d.expect(states=[{states}], unhandled="declared ignored")\n'
        f"    d.send({_quoted(c.event or '')})\n"
    )


def _quoted(text: str) -> str:
    """A string literal as ruff writes it (double quotes where the text allows)."""
    return string(text)
