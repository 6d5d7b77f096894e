"""PlantUML state diagram writer.

Rules:
1. States are printed by safe id and declared ``state "label" as id``; PlantUML has no
   escape for ``"`` inside that label, so a double quote becomes ``'``. Line breaks in
   labels become spaces.
2. Containers nest as ``state "label" as id { ... }``; the regions of a parallel state are
   separated by ``--``; each block opens with its ``[*] -->`` initial marker.
3. An edge is written inside the innermost compound block holding both ends; a final
   state gets ``id --> [*]``; history states use the ``<<history>>`` / ``<<history*>>``
   stereotypes; monitored states get a note; active states get a fill colour.
4. A state's details (its timeout, its deferred events) are description lines,
   ``id : after 2s / Close timeout``, printed after the state.
"""

from __future__ import annotations

from statectl.out.escape import diagram as diagram_escape
from statectl.out.render.diagram import Diagram, Node, NodeKind

__all__ = ["ACTIVE_COLOR", "label", "write"]

ACTIVE_COLOR = "#FFD54F"


#: Text safe in a PlantUML quoted label: the one PlantUML escape (statectl.out.escape.diagram).
label = diagram_escape.plantuml


def _head(node: Node) -> str:
    text = f'state "{label(node.label)}" as {node.id}'
    if node.kind is NodeKind.HISTORY_SHALLOW:
        text += " <<history>>"
    elif node.kind is NodeKind.HISTORY_DEEP:
        text += " <<history*>>"
    if node.active:
        text += f" {ACTIVE_COLOR}"
    return text


def _block(d: Diagram, parent: str | None, depth: int, out: list[str]) -> None:
    pad = "  " * depth
    initial = d.initial if parent is None else d.node(parent).initial
    for target in initial:
        out.append(f"{pad}[*] --> {target}")
    is_parallel = parent is not None and d.node(parent).kind is NodeKind.PARALLEL
    for i, kid in enumerate(d.children(parent)):
        if is_parallel and i > 0:
            out.append(f"{pad}--")
        if kid.kind.is_container:
            out.append(f"{pad}{_head(kid)} {{")
            _block(d, kid.id, depth + 1, out)
            out.append(pad + "}")
        else:
            out.append(pad + _head(kid))
        if kid.kind is NodeKind.FINAL:
            out.append(f"{pad}{kid.id} --> [*]")
        out.extend(f"{pad}{kid.id} : {label(line)}" for line in kid.details)
    for edge in d.edges:
        if d.home(edge) == parent:
            text = f" : {label(edge.label)}" if edge.label else ""
            out.append(f"{pad}{edge.source} --> {edge.target}{text}")


def write(d: Diagram) -> str:
    """The diagram as PlantUML source (``@startuml`` ... ``@enduml``)."""
    out = ["@startuml", "hide empty description", f"title {label(d.name)}"]
    _block(d, None, 0, out)
    for note in d.notes:
        out.append(f"note right of {note.node} : {label(note.text)}")
    out.append("@enduml")
    return "\n".join(out) + "\n"
