"""A plain SVG of a diagram for when Graphviz is not installed.

Rules:
1. States are boxes in rows (containers are not nested, they are drawn as boxes
   too); transitions are straight lines with their label at the middle.
2. Each state's group carries ``class="node"`` and a ``<title>`` with the node id,
   as Graphviz's SVG does, so the page highlights active states the same way.
3. Every name is XML-escaped; nothing from the model reaches the SVG unescaped.
"""

from __future__ import annotations

from xml.sax.saxutils import escape

from statectl.out.render.diagram import Diagram

__all__ = ["fallback_svg"]

_W, _H, _GAP_X, _GAP_Y, _PER_ROW = 150, 44, 90, 80, 4


def fallback_svg(d: Diagram) -> str:
    """``d`` as a simple SVG (rule 1)."""
    nodes = [n for n in d.nodes if not n.kind.is_history]
    place: dict[str, tuple[float, float]] = {}
    for i, n in enumerate(nodes):
        row, col = divmod(i, _PER_ROW)
        place[n.id] = (20 + col * (_W + _GAP_X), 20 + row * (_H + _GAP_Y))
    cols = min(len(nodes), _PER_ROW) or 1
    rows = (len(nodes) + _PER_ROW - 1) // _PER_ROW or 1
    width = 40 + cols * _W + (cols - 1) * _GAP_X
    height = 40 + rows * _H + (rows - 1) * _GAP_Y
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12">',
        '<defs><marker id="arrow" markerWidth="8" markerHeight="8" refX="8" refY="4" '
        'orient="auto"><path d="M0,0 L8,4 L0,8 z" fill="#555"/></marker></defs>',
    ]
    for k, e in enumerate(d.edges):
        if e.source not in place or e.target not in place:
            continue
        (x1, y1), (x2, y2) = place[e.source], place[e.target]
        x1, y1, x2, y2 = x1 + _W / 2, y1 + _H / 2, x2 + _W / 2, y2 + _H / 2
        shift = 8 * ((k % 3) - 1)
        label = escape(e.label)
        if e.source == e.target:
            out.append(
                f'<g class="edge"><path d="M{x1 - 20},{y1 - _H / 2} C{x1 - 30},{y1 - _H - 20} '
                f'{x1 + 30},{y1 - _H - 20} {x1 + 20},{y1 - _H / 2}" fill="none" stroke="#555" '
                f'marker-end="url(#arrow)"/><text x="{x1}" y="{y1 - _H - 8}" '
                f'text-anchor="middle">{label}</text></g>'
            )
            continue
        out.append(
            f'<g class="edge"><line x1="{x1}" y1="{y1 + shift}" x2="{x2}" y2="{y2 + shift}" '
            f'stroke="#555" marker-end="url(#arrow)"/><text x="{(x1 + x2) / 2}" '
            f'y="{(y1 + y2) / 2 + shift - 4}" text-anchor="middle">{label}</text></g>'
        )
    for n in nodes:
        x, y = place[n.id]
        out.append(
            f'<g class="node"><title>{escape(n.id)}</title><rect x="{x}" y="{y}" '
            f'width="{_W}" height="{_H}" rx="10" fill="white" stroke="#333"/>'
            f'<text x="{x + _W / 2}" y="{y + _H / 2 + 4}" text-anchor="middle">'
            f"{escape(n.label)}</text></g>"
        )
    out.append("</svg>")
    return "\n".join(out) + "\n"
