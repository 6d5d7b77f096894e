"""Export the explored state graph as a GraphWalker JSON model.

Rules:
1. Vertices are the reachable configurations (active atomic states), edges the
   handled events between them, both as the kernel's search found them from the
   default state with the chart's default data; an edge named ``e__start`` with no
   source enters the default configuration and is the start element.
2. Names are what GraphWalker maps to test methods: ``v_`` + the states,
   ``e_`` + the event, each reduced to an identifier; ``properties`` keep the
   exact states, event and the rows (file:line) an edge takes, so nothing is lost
   to the renaming.
3. The generator is ``random(edge_coverage(100))``: every edge at least once.
"""

from __future__ import annotations

import json
import re
from typing import Any

from statectl.out.testgen.cases import where
from statectl.out.testgen.paths import Graph, leaves

__all__ = ["graphwalker_model"]


def _ident(text: str) -> str:
    return re.sub(r"\W+", "_", text).strip("_") or "x"


def graphwalker_model(g: Graph) -> str:
    """The GraphWalker JSON (one model) of ``g``'s default-data part (rules 1-3)."""
    chart = g.chart
    vertices: dict[tuple[str, ...], str] = {}
    start = leaves(chart, g.start[0].snapshot)

    def vertex(key: tuple[str, ...]) -> str:
        if key not in vertices:
            vertices[key] = f"v{len(vertices)}"
        return vertices[key]

    vertex(start)
    first = {"id": "e0", "name": "e__start", "targetVertexId": vertex(start)}
    edges: list[dict[str, Any]] = [first]
    seen: set[tuple[Any, ...]] = set()
    for e in g.edges:
        if e.source.data != 0 or not e.step.handled:
            continue
        src = leaves(chart, e.source.snapshot)
        dst = leaves(chart, e.step.target)
        key = (src, e.event, dst)
        if key in seen:
            continue
        seen.add(key)
        edges.append(
            {
                "id": f"e{len(edges)}",
                "name": f"e_{_ident(e.event)}",
                "sourceVertexId": vertex(src),
                "targetVertexId": vertex(dst),
                "properties": {
                    "event": e.event,
                    "rows": [f"{where(t)} {t.label}" for t in e.step.transitions],
                },
            }
        )
    model = {
        "name": chart.name,
        "models": [
            {
                "name": chart.name,
                "id": _ident(chart.name),
                "generator": "random(edge_coverage(100))",
                "startElementId": "e0",
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
