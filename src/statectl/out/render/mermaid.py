"""Mermaid ``stateDiagram-v2`` writer.

Rules:
1. States are printed by safe id; a label that differs from the id is declared once as
   ``state "label" as id``. Characters Mermaid parses (``" # ; : < > { }``) become its
   numeric entity codes (``#34;``), so names and guards survive unchanged.
2. Containers nest as ``state id { ... }``; the regions of a parallel state are separated
   by ``--``; each block opens with its ``[*] -->`` initial marker.
3. An edge is written inside the innermost compound block holding both ends; a final
   state gets ``id --> [*]``; monitored states get a note; active states get class
   ``active``.
4. A state's details (its timeout, its deferred events) are state descriptions,
   ``id : after 2s / Close timeout``, printed after the state is declared.
"""

from __future__ import annotations

from statectl.out.escape import diagram as diagram_escape
from statectl.out.render.diagram import Diagram, Node, NodeKind

__all__ = ["ACTIVE_STYLE", "escape", "write"]

ACTIVE_STYLE = "fill:#ffd54f,stroke:#b28704,stroke-width:3px"

#: Text safe in a Mermaid label: the one Mermaid escape (statectl.out.escape.diagram).
escape = diagram_escape.mermaid


def _declare(node: Node) -> str:
    if node.kind.is_history or node.label != node.id:
        return f'state "{escape(node.label)}" as {node.id}'
    return node.id


def _block(d: Diagram, parent: str | None, depth: int, out: list[str]) -> None:
    pad = "    " * depth
    kids = d.children(parent)
    initial = d.initial if parent is None else d.node(parent).initial
    for target in initial:
        out.append(f"{pad}[*] --> {target}")
    is_parallel = parent is not None and d.node(parent).kind is NodeKind.PARALLEL
    for i, kid in enumerate(kids):
        if is_parallel and i > 0:
            out.append(f"{pad}--")
        if kid.label != kid.id or kid.kind.is_history or not kid.kind.is_container:
            out.append(pad + _declare(kid))
        if kid.kind.is_container:
            out.append(f"{pad}state {kid.id} {{")
            _block(d, kid.id, depth + 1, out)
            out.append(pad + "}")
        if kid.kind is NodeKind.FINAL:
            out.append(f"{pad}{kid.id} --> [*]")
        out.extend(f"{pad}{kid.id} : {escape(line)}" for line in kid.details)
    for edge in d.edges:
        if d.home(edge) == parent:
            label = f" : {escape(edge.label)}" if edge.label else ""
            out.append(f"{pad}{edge.source} --> {edge.target}{label}")


def write(d: Diagram) -> str:
    """The diagram as Mermaid ``stateDiagram-v2`` source."""
    out = [f"%% {diagram_escape.comment(d.name)}", "stateDiagram-v2"]
    _block(d, None, 1, out)
    for note in d.notes:
        out.append(f"    note right of {note.node}")
        out.append(f"        {escape(note.text)}")
        out.append("    end note")
    active = [n.id for n in d.nodes if n.active]
    if active:
        out.append(f"    classDef active {ACTIVE_STYLE}")
        out.append(f"    class {','.join(active)} active")
    return "\n".join(out) + "\n"
