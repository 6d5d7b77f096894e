"""Diagrams and pages of a chart: one neutral diagram model, one writer per format.

Rules:
1. :func:`render` builds the :class:`~statectl.out.render.diagram.Diagram` once from the chart
   and hands it to the writer named by ``fmt``; no writer reads the chart's semantics.
2. ``active`` names states to highlight (a live dashboard); the diagram is otherwise the
   same.
3. An unknown format is a :class:`~statectl.kernel.errors.StatectlError` listing the formats.
"""

from __future__ import annotations

from collections.abc import Callable

from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart
from statectl.out.render import dot, markdown, mermaid, plantuml, svg
from statectl.out.render.diagram import Diagram, Edge, Node, NodeKind, Note, from_chart

__all__ = ["FORMATS", "Diagram", "Edge", "Node", "NodeKind", "Note", "from_chart", "render"]

FORMATS: tuple[str, ...] = ("mermaid", "dot", "plantuml", "svg", "md")

_WRITERS: dict[str, Callable[[Chart, Diagram], str]] = {
    "mermaid": lambda _chart, d: mermaid.write(d),
    "dot": lambda _chart, d: dot.write(d),
    "plantuml": lambda _chart, d: plantuml.write(d),
    "svg": lambda _chart, d: svg.write(d),
    "md": markdown.write,
}


def render(chart: Chart, fmt: str, *, active: frozenset[str] = frozenset()) -> str:
    """``chart`` in format ``fmt`` (one of :data:`FORMATS`), ``active`` states highlighted."""
    writer = _WRITERS.get(fmt)
    if writer is None:
        raise StatectlError(
            f"unknown diagram format {fmt!r}. Available formats: {', '.join(FORMATS)}"
        )
    return writer(chart, from_chart(chart, active))
