"""Operational coverage: which rows, states and transitions a journalled run exercised.

Rules:
1. The journal stores each step's event, data, outcome and the snapshot it left;
   the kernel re-decides every handled event step from the snapshot before it, and
   the transitions of that decision are the rows taken. A step whose journalled
   snapshot disagrees with the kernel's is counted nowhere and reported (the
   journal is of another version of the tables, or was damaged).
2. States count when entered (the start's configuration included); transitions
   are the edges of the state graph ``configuration --event--> configuration``,
   out of those :func:`~statectl.out.testgen.paths.explore` finds reachable.
3. Restores and recovery ``redo`` steps change nothing they exercise.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from statectl.front.tables.inputs import read_input_text
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart, StateKind, Transition
from statectl.kernel.semantics import Outcome, Snapshot, compiled, step
from statectl.out.escape import diagram as diagram_escape
from statectl.out.render import dot
from statectl.out.render.diagram import from_chart
from statectl.out.render.svg import dot_to_svg
from statectl.out.testgen.cases import describe, where
from statectl.out.testgen.paths import default_data, explore, leaves
from statectl.run.journal import REDO, JournalReader, StepKind

__all__ = [
    "Coverage",
    "Tally",
    "coverage_table",
    "journal_coverage",
    "load_tally",
    "mermaid",
    "svg",
]

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


class Tally:
    """Counts what the steps of one chart exercised: rows, states entered, graph edges.

    The journal feeds it from its rows; the pytest plugin from each device's steps
    (``--statectl-coverage``), and writes it as JSON that :func:`load_tally` reads.
    """

    def __init__(self, chart: Chart) -> None:
        self.chart = chart
        self.machine = compiled(chart)
        self.index = {t: i for i, t in enumerate(chart.transitions)}  # by value: any copy
        self.rows: Counter[int] = Counter()
        self.states: Counter[str] = Counter()
        self.edges: Counter[EdgeKey] = Counter()
        self.mismatches: list[str] = []
        self.steps = 0

    def start(self, snapshot: Snapshot) -> None:
        self.states.update(snapshot.active)

    def event(
        self,
        before: Snapshot,
        event: str,
        data: Mapping[str, Any],
        event_data: Any,
        after: Snapshot,
        where: str,
    ) -> None:
        """A handled event: the kernel re-decides it; a disagreement is noted, not counted."""
        self.steps += 1
        decided = step(self.machine, before, event, data, event_data)
        if not _same(decided.target, after):
            self.mismatches.append(
                f"{where}: {event}: the run has {sorted(after.active)}, the tables give "
                f"{sorted(decided.target.active)}"
            )
            return
        self.rows.update(self.index[t] for t in decided.transitions if t in self.index)
        self.states.update(decided.entered)
        chart = self.chart
        self.edges[(leaves(chart, before), event, leaves(chart, after))] += 1

    def coverage(self, sources: tuple[str, ...]) -> Coverage:
        chart = self.chart
        return Coverage(
            chart,
            sources,
            self.steps,
            tuple(self.rows[i] for i in range(len(chart.transitions))),
            {st.name: self.states[st.name] for st in chart.states if not st.kind.is_history},
            dict(self.edges),
            _reachable(chart),
            tuple(self.mismatches),
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "chart": self.chart.name,
            "steps": self.steps,
            "rows": [self.rows[i] for i in range(len(self.chart.transitions))],
            "states": dict(self.states),
            "edges": [[list(s), e, list(d), n] for (s, e, d), n in self.edges.items()],
            "mismatches": list(self.mismatches),
        }


def load_tally(path: str | Path, chart: Chart) -> Coverage:
    """Coverage of ``chart`` from a ``--statectl-coverage`` JSON file of a pytest run."""
    try:
        doc = json.loads(read_input_text(path))
        entry = doc["charts"].get(chart.name)
        if entry is None:
            found = ", ".join(doc["charts"]) or "none"
            raise StatectlError(
                f"{path}: no chart {chart.name!r} in this test run's coverage; it has: {found}"
            )
        rows = [int(n) for n in entry["rows"]]
        if len(rows) != len(chart.transitions):
            raise StatectlError(
                f"{path}: {chart.name} had {len(rows)} rows in the test run, the tables have "
                f"{len(chart.transitions)}; run the tests again on these tables"
            )
        tally = Tally(chart)
        tally.steps = int(entry["steps"])
        tally.rows.update(dict(enumerate(rows)))
        tally.states.update({str(k): int(v) for k, v in entry["states"].items()})
        for src, event, dst, n in entry["edges"]:
            tally.edges[(tuple(src), str(event), tuple(dst))] += int(n)
        tally.mismatches = [str(m) for m in entry["mismatches"]]
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise StatectlError(
            f"{path}: not a coverage file written by pytest --statectl-coverage ({exc})"
        ) from None
    return tally.coverage(("pytest",))


def journal_coverage(journal: str | Path, chart: Chart, device: str | None = None) -> Coverage:
    """Coverage of ``chart`` by the steps ``journal`` holds for it (rules 1-3)."""
    tally = Tally(chart)
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
                    tally.start(s.snapshot)
                elif (
                    s.kind in (StepKind.EVENT, StepKind.RECOVERY)
                    and s.outcome == Outcome.HANDLED
                    and s.event is not None
                    and before is not None
                ):
                    tally.event(before, s.event, data, s.data, s.snapshot, f"step {s.id} ({name})")
                if s.outcome != REDO:
                    before = s.snapshot
    return tally.coverage(names)


def _pct(part: int, whole: int) -> str:
    return f"{part} of {whole}" + (f" ({100 * part // whole}%)" if whole else "")


def coverage_table(c: Coverage, journal: str) -> str:
    """The report as text: summary, rows, states, transitions, rows never taken."""
    chart = c.chart
    taken = sum(n > 0 for n in c.rows)
    entered = sum(n > 0 for n in c.states.values())
    hit = sum(k in c.edges for k in c.reachable)
    out = [
        f"{chart.name}: {journal} ({', '.join(c.devices)}), {c.steps} event step(s)",
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
        name = diagram_escape.mermaid(s.name)
        shape = f'(("{name}"))' if s.kind is StateKind.FINAL else f'["{name}"]'
        out.append(f"  {_node(s.name)}{shape}")
    styles: list[str] = []
    for n, (t, times) in enumerate(zip(chart.transitions, c.rows, strict=True)):
        label = " ".join(t.events) or "(eventless)"
        label = diagram_escape.mermaid(label)
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


TAKEN, NEVER = "#22aa22", "#cc3333"  # six digits: Graphviz reads no shorthand


def svg(c: Coverage) -> str:
    """The chart's diagram (as ``statectl render``) with the coverage drawn on it, via Graphviz.

    States entered are highlighted; each row's edge is labelled with how often it
    was taken, green when it was, red and dashed when never. Needs Graphviz ``dot``
    (a missing one is a StatectlError saying what to install).
    """
    chart = c.chart
    entered = frozenset(s for s, n in c.states.items() if n and chart.has_state(s))
    d = from_chart(chart, entered)
    per_edge: list[int] = []  # from_chart's edges: per row, one per target, in table order
    for t, times in zip(chart.transitions, c.rows, strict=True):
        per_edge += [times] * len(t.targets or (t.source,))
    if len(per_edge) != len(d.edges):  # a row from or to an unknown state: labels only
        per_edge = [0] * len(d.edges)
    edges = tuple(
        replace(
            e,
            label=f"{e.label} x{n}" if n else f"{e.label} (never)",
            color=TAKEN if n else NEVER,
            dashed=not n,
        )
        for e, n in zip(d.edges, per_edge, strict=True)
    )
    return dot_to_svg(dot.write(replace(d, edges=edges)))
