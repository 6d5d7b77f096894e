"""Export the explored state graph as a GraphWalker JSON model.

Rules:
1. Vertices are the reachable configurations (active atomic states), edges the
   handled events between them, both as the kernel's search found them from the
   default state (from every start data it tried); an edge named ``e__start``
   with no source enters the default configuration and is the start element.
2. Names are what GraphWalker maps to test methods: ``v_`` + the states,
   ``e_`` + the event, each reduced to an identifier; ``properties`` keep the
   exact states, event and the rows (file:line) an edge takes, so nothing is lost
   to the renaming.
3. The generator is ``random(edge_coverage(100))``: every edge at least once.
4. Guards and data ride along (:mod:`~statectl.out.testgen.jsguard`), so a walk
   never asks for a path the device cannot take: the model's actions set
   ``previous`` and the chart's data to their start values; an edge's guard is the
   guard of each row it takes (with the edge's event data and its source's ``In()``
   written as literals), and the negation of each guarded row of the event before
   them that was not taken; its actions set ``previous`` as the step leaves it and
   perform the rows' assignments. An edge per explored (configuration, event,
   configuration, rows, event data), from every start data the search tried. A
   guard that cannot be written as JavaScript stays in ``properties`` with a note.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from typing import Any

from statectl.kernel.model import Assign
from statectl.out.testgen.cases import where
from statectl.out.testgen.jsguard import js_expression
from statectl.out.testgen.paths import Edge, Graph, leaves

__all__ = ["graphwalker_model"]


def _ident(text: str) -> str:
    return re.sub(r"\W+", "_", text).strip("_") or "x"


def _guard(g: Graph, e: Edge, names: frozenset[str]) -> tuple[str | None, list[str]]:
    """The edge's JavaScript guard (rule 4), and the guards it could not write."""
    active = e.source.snapshot.active
    taken = e.step.transitions
    first = min(
        (g.chart.transitions.index(t) for t in taken if t in g.chart.transitions), default=0
    )
    parts: list[str] = []
    missed: list[str] = []
    for t in taken:
        if t.guard:
            js = js_expression(t.guard, names, e.data, active.__contains__)
            parts.append(js) if js is not None else missed.append(t.guard)
    for t in g.chart.transitions[:first]:
        if t.guard and e.event in t.events and t.source in active and t not in taken:
            js = js_expression(t.guard, names, e.data, active.__contains__)
            parts.append(f"!({js})") if js is not None else missed.append(f"not ({t.guard})")
    return (" && ".join(parts) or None), missed


def _actions(e: Edge, names: frozenset[str], previous: set[Any]) -> tuple[list[str], list[str]]:
    """The edge's actions (rule 4): ``previous`` as the step leaves it, the assignments."""
    out: list[str] = []
    missed: list[str] = []
    if len(previous) == 1:
        (after,) = previous
        out.append(f"previous = {json.dumps(after)};")
    for a in e.step.actions:
        if isinstance(a, Assign):
            js = js_expression(
                a.expr or "None", names, e.data, e.source.snapshot.active.__contains__
            )
            if js is None or a.location not in names:
                missed.append(f"{a.location} = {a.expr}")
            else:
                out.append(f"{a.location} = {js};")
    return out, missed


def _edges(g: Graph, vertex: Callable[[tuple[str, ...]], str]) -> list[dict[str, Any]]:
    chart = g.chart
    names = frozenset(k for k, _ in g.defaults)
    groups: dict[tuple[Any, ...], list[Edge]] = {}
    for e in g.edges:
        if e.step.handled:
            src, dst = leaves(chart, e.source.snapshot), leaves(chart, e.step.target)
            key = (src, e.event, dst, tuple(id(t) for t in e.step.transitions), repr(e.data))
            groups.setdefault(key, []).append(e)
    edges: list[dict[str, Any]] = []
    for (src, event, dst, _, _), group in groups.items():
        e = group[0]
        after = {x.step.target.previous for x in group}
        changed = any(x.step.target.previous != x.source.snapshot.previous for x in group)
        guard, missed = _guard(g, e, names)
        actions, not_done = _actions(e, names, after if changed else set())
        props: dict[str, Any] = {
            "event": event,
            "rows": [f"{where(t)} {t.label}" for t in e.step.transitions],
        }
        if e.data is not None:
            props["data"] = e.data
        if missed or not_done:
            props["notWritten"] = missed + not_done
        edge: dict[str, Any] = {
            "id": f"e{len(edges) + 1}",
            "name": f"e_{_ident(event)}",
            "sourceVertexId": vertex(src),
            "targetVertexId": vertex(dst),
        }
        if guard is not None:
            edge["guard"] = guard
        if actions:
            edge["actions"] = actions
        edge["properties"] = props
        edges.append(edge)
    return edges


def graphwalker_model(g: Graph) -> str:
    """The GraphWalker JSON (one model) of ``g`` (rules 1-4)."""
    chart = g.chart
    vertices: dict[tuple[str, ...], str] = {}
    start = leaves(chart, g.start[0].snapshot)

    def vertex(key: tuple[str, ...]) -> str:
        if key not in vertices:
            vertices[key] = f"v{len(vertices)}"
        return vertices[key]

    vertex(start)
    first = {"id": "e0", "name": "e__start", "targetVertexId": vertex(start)}
    edges: list[dict[str, Any]] = [first, *_edges(g, vertex)]
    setup = [f"previous = {json.dumps(g.start[0].snapshot.previous)};"]
    setup += [f"{k} = {json.dumps(v)};" for k, v in g.defaults if _json_safe(v)]
    model = {
        "name": chart.name,
        "models": [
            {
                "name": chart.name,
                "id": _ident(chart.name),
                "generator": "random(edge_coverage(100))",
                "startElementId": "e0",
                "actions": setup,
                "vertices": [
                    {
                        "id": vid,
                        "name": "v_" + "_".join(_ident(s) for s in key),
                        "properties": {"states": list(key)},
                    }
                    for key, vid in vertices.items()
                ],
                "edges": edges,
            }
        ],
    }
    return json.dumps(model, indent=2) + "\n"


def _json_safe(value: Any) -> bool:
    try:
        json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        return False
    return True
