"""Operational coverage: which rows, states and transitions a journalled run exercised.

Rules:
1. The journal stores each step's event, data, outcome and the snapshot it left;
   the kernel re-decides every handled event step from the snapshot before it, and
   the transitions of that decision are the rows taken. A step whose journalled
   snapshot disagrees with the kernel's is counted nowhere and reported (the
   journal is of another version of the tables, or was damaged).
2. States count when entered (the start's configuration included); transitions
   are the edges of the state graph ``configuration --event--> configuration``,
   out of those :func:`~statectl.testgen.paths.explore` finds reachable.
3. Restores and recovery ``redo`` steps change nothing they exercise.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from statectl.errors import StatectlError
from statectl.journal import REDO, JournalReader, StepKind
from statectl.model import Chart, StateKind, Transition
from statectl.semantics import Snapshot, compiled, step
from statectl.testgen.cases import describe, where
from statectl.testgen.paths import default_data, explore, leaves

__all__ = ["Coverage", "coverage_table", "journal_coverage", "mermaid"]

EdgeKey = tuple[tuple[str, ...], str, tuple[str, ...]]


@dataclass(frozen=True, slots=True)
class Coverage:
    chart: Chart
    devices: tuple[str, ...]  # the journal's devices that ran this chart
    steps: int  # event steps re-decided
    rows: tuple[int, ...]  # per chart transition (table order), how often it was taken
    states: dict[str, int]  # state -> times entered
    edges: dict[EdgeKey, int]  # taken edges of the state graph
    reachable: tuple[EdgeKey, ...]  # every edge the search finds from the default state
    mismatches: tuple[str, ...]

    @property
    def never(self) -> tuple[tuple[int, Transition], ...]:
        return tuple(
            (i, t)
            for i, (t, n) in enumerate(zip(self.chart.transitions, self.rows, strict=True), 1)
            if n == 0
        )


def _same(a: Snapshot, b: Snapshot) -> bool:
    return a.active == b.active and a.previous == b.previous


def _reachable(chart: Chart) -> tuple[EdgeKey, ...]:
    g = explore(chart)
    seen: dict[EdgeKey, None] = {}
    for e in g.edges:
        if e.step.handled:
            seen[(leaves(chart, e.source.snapshot), e.event, leaves(chart, e.step.target))] = None
    return tuple(seen)


def journal_coverage(journal: str | Path, chart: Chart, device: str | None = None) -> Coverage:
    """Coverage of ``chart`` by the steps ``journal`` holds for it (rules 1-3)."""
    m = compiled(chart)
    rows: Counter[int] = Counter()
    states: Counter[str] = Counter()
    edges: Counter[EdgeKey] = Counter()
    mismatches: list[str] = []
    steps = 0
    index = {id(t): i for i, t in enumerate(chart.transitions)}
    with JournalReader(journal) as reader:
        ran = reader.devices()
        names = tuple(
            d.name
            for d in ran
            if (d.name == device if device is not None else d.chart == chart.name)
        )
        if not names:
            found = ", ".join(f"{d.name} ({d.chart})" for d in ran) or "none"
            what = f"device {device!r}" if device is not None else f"device of chart {chart.name!r}"
            raise StatectlError(f"{journal}: no {what} in the journal; devices journalled: {found}")
        for name in names:
            row = reader.device(name)
            data: dict[str, Any] = dict(default_data(chart))
            if row is not None and isinstance(row.data, dict):
                data.update(row.data)
            before: Snapshot | None = None
            for s in reader.steps(name):
                if s.kind is StepKind.START:
                    states.update(s.snapshot.active)
                elif (
                    s.kind in (StepKind.EVENT, StepKind.RECOVERY)
                    and s.outcome == "handled"
                    and s.event is not None
                    and before is not None
                ):
                    steps += 1
                    decided = step(m, before, s.event, data, s.data)
                    if not _same(decided.target, s.snapshot):
                        mismatches.append(
                            f"step {s.id} ({name}: {s.event}): the journal has "
                            f"{sorted(s.snapshot.active)}, the tables give "
                            f"{sorted(decided.target.active)}"
                        )
                    else:
                        rows.update(index[id(t)] for t in decided.transitions if id(t) in index)
                        states.update(decided.entered)
                        key = (leaves(chart, before), s.event, leaves(chart, s.snapshot))
                        edges[key] += 1
                if s.outcome != REDO:
                    before = s.snapshot
    return Coverage(
        chart,
        names,
        steps,
        tuple(rows[i] for i in range(len(chart.transitions))),
        {st.name: states[st.name] for st in chart.states if not st.kind.is_history},
        dict(edges),
        _reachable(chart),
        tuple(mismatches),
    )


def _pct(part: int, whole: int) -> str:
    return f"{part} of {whole}" + (f" ({100 * part // whole}%)" if whole else "")


def coverage_table(c: Coverage, journal: str) -> str:
    """The report as text: summary, rows, states, transitions, rows never taken."""
    chart = c.chart
    taken = sum(n > 0 for n in c.rows)
    entered = sum(n > 0 for n in c.states.values())
    hit = sum(k in c.edges for k in c.reachable)
    out = [
        f"{chart.name}: journal {journal}, device(s) {', '.join(c.devices)}, "
        f"{c.steps} event step(s)",
        f"rows {_pct(taken, len(c.rows))}, states {_pct(entered, len(c.states))}, "
        f"transitions {_pct(hit, len(c.reachable))}",
        "",
        "rows:",
    ]
    width = max((len(where(t)) for t in chart.transitions), default=0)
    for i, (t, n) in enumerate(zip(chart.transitions, c.rows, strict=True), 1):
        out.append(f"  {i:>3}  {where(t):<{width}}  {n:>6}  {describe(t)}")
    out += ["", "states:"]
    for name, n in c.states.items():
        out.append(f"  {name:<24} {n:>6}")
    out += ["", "transitions:"]
    keys = list(c.reachable) + [k for k in c.edges if k not in c.reachable]
    for k in keys:
        src, event, dst = k
        out.append(f"  {', '.join(src)} --{event}--> {', '.join(dst)}  {c.edges.get(k, 0)}")
    never = c.never
    out += ["", f"rows never taken: {len(never) or 'none'}"]
    for i, t in never:
        out.append(f"  {where(t)}: row {i}: {describe(t)}")
    if c.mismatches:
        out += ["", f"steps that disagree with the tables: {len(c.mismatches)}"]
        out += [f"  {m}" for m in c.mismatches]
    return "\n".join(out) + "\n"


def _node(name: str) -> str:
    return "s_" + "".join(ch if ch.isalnum() else "_" for ch in name)


def mermaid(c: Coverage) -> str:
    """A Mermaid flowchart of the rows: taken ones thick and green, never taken dashed red."""
    chart = c.chart
    out = ["flowchart LR"]
    shown = [s for s in chart.states if not s.kind.is_history]
    for s in shown:
        shape = f"(({s.name}))" if s.kind is StateKind.FINAL else f'["{s.name}"]'
        out.append(f"  {_node(s.name)}{shape}")
    styles: list[str] = []
    for n, (t, times) in enumerate(zip(chart.transitions, c.rows, strict=True)):
        label = " ".join(t.events) or "(eventless)"
        label = label.replace('"', "'")
        target = t.targets[0] if t.targets else t.source
        out.append(f'  {_node(t.source)} -->|"{label} x{times}"| {_node(target)}')
        style = "stroke:#2a2,stroke-width:3px" if times else "stroke:#c33,stroke-dasharray:4"
        styles.append(f"  linkStyle {n} {style}")
    out += styles
    out.append("  classDef covered fill:#dfd,stroke:#2a2")
    out.append("  classDef uncovered fill:#fee,stroke:#c33")
    for s in shown:
        cls = "covered" if c.states.get(s.name, 0) else "uncovered"
        out.append(f"  class {_node(s.name)} {cls}")
    return "\n".join(out) + "\n"
