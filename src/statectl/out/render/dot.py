"""Graphviz DOT writer.

Rules:
1. Every id and label is a double-quoted DOT string (``\\`` and ``"`` escaped, newlines as
   ``\\n``), so no state name can collide with a DOT keyword or break the syntax.
2. A container is a ``cluster_<id>`` subgraph holding an invisible anchor node; edges to
   or from a container attach to its anchor and are clipped at the cluster
   (``compound=true`` with ``lhead``/``ltail``). Parallel containers draw dashed.
3. Helper nodes have ids starting with ``_``, which safe state ids never do.
4. Initial markers are small filled points; final states have a double border; history
   states are circles labelled H or H*; monitored states get a note; active states fill.
5. A state's details (its timeout, its deferred events) are further lines of its label
   (a node's or a cluster's), under the name.
"""

from __future__ import annotations

from statectl.out.escape import diagram as diagram_escape
from statectl.out.render.diagram import Diagram, Node, NodeKind

__all__ = ["ACTIVE_FILL", "quote", "write"]

ACTIVE_FILL = "#ffd54f"
_ACTIVE_CLUSTER_FILL = "#fff3c4"


#: ``text`` as a DOT double-quoted string: the one DOT escape (statectl.out.escape.diagram).
quote = diagram_escape.dot


def _anchor(node_id: str) -> str:
    return f"_anchor_{node_id}"


def _attrs(pairs: dict[str, str]) -> str:
    return "[" + ", ".join(f"{k}={v}" for k, v in pairs.items()) + "]"


def _label(node: Node) -> str:
    return "\n".join((node.label, *node.details))


def _node_line(node: Node) -> str:
    attrs: dict[str, str] = {"label": quote(_label(node))}
    if node.kind.is_history:
        attrs["shape"] = "circle"
        attrs["width"] = "0.3"
    if node.kind is NodeKind.FINAL:
        attrs["peripheries"] = "2"
    if node.active:
        attrs["style"] = quote("rounded,filled,bold")
        attrs["fillcolor"] = quote(ACTIVE_FILL)
        attrs["penwidth"] = "2"
    return f"{quote(node.id)} {_attrs(attrs)};"


def _block(d: Diagram, parent: str | None, depth: int, out: list[str]) -> None:
    pad = "  " * depth
    initial = d.initial if parent is None else d.node(parent).initial
    start = "_start" if parent is None else f"_start_{parent}"
    if initial:
        out.append(f'{pad}{quote(start)} [shape=point, width=0.12, label=""];')
        for target in initial:
            out.append(f"{pad}{quote(start)} -> {_end(d, target)};")
    for kid in d.children(parent):
        if kid.kind.is_container:
            out.append(f"{pad}subgraph {quote('cluster_' + kid.id)} {{")
            inner = pad + "  "
            style = "rounded,dashed" if kid.kind is NodeKind.PARALLEL else "rounded"
            if kid.active:  # clusters inherit attributes, so inactive ones reset them
                style += ",filled"
            fill = _ACTIVE_CLUSTER_FILL if kid.active else "white"
            out.append(f"{inner}fillcolor={quote(fill)};")
            out.append(f"{inner}penwidth={2 if kid.active else 1};")
            out.append(f"{inner}label={quote(_label(kid))};")
            out.append(f"{inner}style={quote(style)};")
            out.append(
                f'{inner}{quote(_anchor(kid.id))} [shape=point, style=invis, width=0, label=""];'
            )
            _block(d, kid.id, depth + 1, out)
            out.append(pad + "}")
        else:
            out.append(pad + _node_line(kid))


def _end(d: Diagram, node_id: str) -> str:
    node = d.node(node_id)
    return quote(_anchor(node_id) if node.kind.is_container else node_id)


def write(d: Diagram) -> str:
    """The diagram as Graphviz DOT source."""
    out = [
        f"digraph {quote(d.name)} {{",
        "  graph [compound=true, rankdir=LR, fontname=Helvetica];",
        "  node [shape=box, style=rounded, fontname=Helvetica];",
        "  edge [fontname=Helvetica, fontsize=10];",
    ]
    _block(d, None, 1, out)
    for e in d.edges:
        attrs: dict[str, str] = {"label": quote(e.label)}
        source, target = d.node(e.source), d.node(e.target)
        if source.kind.is_container and e.source not in d.ancestors(e.target):
            attrs["ltail"] = quote("cluster_" + e.source)
        if target.kind.is_container and e.target not in d.ancestors(e.source):
            attrs["lhead"] = quote("cluster_" + e.target)
        if e.internal or e.dashed:
            attrs["style"] = "dashed"
        if e.color:
            attrs["color"] = attrs["fontcolor"] = quote(e.color)
        line = f"{_end(d, e.source)} -> {_end(d, e.target)}"
        out.append(f"  {line} {_attrs(attrs)};")
    for note in d.notes:
        note_id = quote(f"_note_{note.node}")
        out.append(f"  {note_id} [shape=note, fontsize=10, label={quote(note.text)}];")
        attrs = {"style": "dashed", "arrowhead": "none"}
        if d.node(note.node).kind.is_container:
            attrs["ltail"] = quote("cluster_" + note.node)
        out.append(f"  {_end(d, note.node)} -> {note_id} {_attrs(attrs)};")
    out.append("}")
    return "\n".join(out) + "\n"
