"""A Markdown page for a device: its two tables, its statechart and its invoke table.

Rules:
1. The State Definition and Event Definition tables are rendered from the built chart (not
   copied from the source file), so the page shows what statectl understood.
2. The statechart is the Mermaid writer's output in a fenced ``mermaid`` block, which
   GitHub, GitLab and most documentation tools draw.
3. A device with timeouts or deferred events gets ``timeout`` and ``defer`` columns in
   its State Definition table (others keep the paper's five columns).
4. Table cells escape ``|`` and fold line breaks, so any name or prose fits one row,
   and a ``<`` that would open raw HTML (``<script>``), so a name stays text.
"""

from __future__ import annotations

from collections.abc import Sequence

from statectl.kernel.model import Chart, ControlKind, State
from statectl.out.escape.diagram import markdown_cell
from statectl.out.render import mermaid
from statectl.out.render.diagram import Diagram

__all__ = ["cell", "table", "write"]


#: ``text`` safe in one Markdown table cell: the one Markdown escape (out.escape.diagram).
cell = markdown_cell


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    out = ["| " + " | ".join(cell(h) for h in header) + " |"]
    out.append("|" + "|".join("---" for _ in header) + "|")
    out.extend("| " + " | ".join(cell(c) for c in row) + " |" for row in rows)
    return out


def _controls(controls: frozenset[ControlKind]) -> str:
    return ", ".join(k.value for k in ControlKind if k in controls)


def _timed(chart: Chart) -> bool:
    return any(s.timeout is not None or s.defer for s in chart.states)


def _timing(s: State) -> list[str]:
    timeout = "" if s.timeout is None else f"{s.timeout.duration} -> {s.timeout.event}"
    return [timeout, ", ".join(s.defer)]


def _state_rows(chart: Chart) -> list[list[str]]:
    timed = _timed(chart)
    rows = []
    for s in chart.states:
        if s.kind.is_history:
            continue
        ignored = sorted(e for st, e in chart.ignored if st == s.name)
        rows.append(
            [
                s.component or chart.component,
                s.name,
                _controls(s.controls),
                s.description,
                ", ".join(ignored),
                *(_timing(s) if timed else []),
            ]
        )
    return rows


def _event_rows(chart: Chart) -> list[list[str]]:
    rows = []
    for t in chart.transitions:
        edef = chart.event(t.events[0]) if t.events else None
        rows.append(
            [
                " ".join(t.events) or "(eventless)",
                t.condition,
                t.guard or "",
                t.source,
                ", ".join(t.targets) or "(stays)",
                edef.kind.value if edef is not None else "",
                (edef.api or "") if edef is not None else "",
            ]
        )
    return rows


def _invoke_rows(chart: Chart) -> list[list[str]]:
    events = {a.method: a.events for a in chart.apis}
    return [
        [str(i.number), i.name, f"{i.method}()", ", ".join(events.get(i.method, ()))]
        for i in chart.invokes
    ]


def write(chart: Chart, d: Diagram) -> str:
    """The Markdown page for ``chart``; ``d`` is its diagram (for the Mermaid block)."""
    out = [f"# {cell(chart.name)}", "", "## State Definition", ""]
    out += table(
        ["component name/API", "state", "required state control", "description", "ignores"]
        + (["timeout", "defer"] if _timed(chart) else []),
        _state_rows(chart),
    )
    out += ["", "## Event Definition", ""]
    out += table(
        ["event", "condition for the trigger", "guard", "old state", "new state", "kind", "API"],
        _event_rows(chart),
    )
    out += ["", "## Statechart", "", "```mermaid", mermaid.write(d).rstrip("\n"), "```"]
    out += ["", "## Invoke table", ""]
    if chart.invokes:
        out += table(["invoke", "name", "observer method", "events"], _invoke_rows(chart))
    else:
        out.append("No event drives a device API, so there are no invoke numbers.")
    return "\n".join(out) + "\n"
