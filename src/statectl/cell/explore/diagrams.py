"""Traces as interaction (sequence) diagrams: the paper's proposed future work.

Rules:
1. Participants are the environment and the devices, in the cell's order.
2. Each delivery is one message from its sender to its receiver; a state change
   is a note over the receiver; an event the receiver did not handle is marked.
3. The last note says what the trace shows (the failed property).
"""

from __future__ import annotations

from statectl.cell.explore.report import Trace
from statectl.kernel.semantics import Unhandled

__all__ = ["to_mermaid", "to_plantuml"]

ENV = "environment"


def _clean(text: str) -> str:
    return text.replace(";", ",").replace("#", "").replace("\n", " ")


def _tag(via: str, unhandled: Unhandled | None) -> str:
    tag = "" if via in ("environment",) else f" ({'link' if ' -> ' in via else via})"
    if via.endswith(" dropped"):
        tag = " (dropped: the link's peer was down)"
    if unhandled is not None:
        tag += f" [{unhandled}]"
    return tag


def _fate(fate: str) -> str:
    """A lossy link's event that never arrived, or a delayed one overtaken."""
    return f" [{fate.upper()}]" if fate else ""


def to_mermaid(trace: Trace, title: str = "") -> str:
    """A Mermaid ``sequenceDiagram`` of ``trace``."""
    out = ["sequenceDiagram"]
    if title:
        out.append(f"    title {_clean(title)}")
    out.append(f"    participant {ENV}")
    out.extend(f"    participant {d}" for d in trace.devices)
    start = ", ".join(f"{d}={s}" for d, s in zip(trace.devices, trace.start, strict=True))
    out.append(f"    Note over {trace.devices[0]},{trace.devices[-1]}: start: {_clean(start)}")
    for step in trace.steps:
        for d in step.deliveries:
            arrow = "-)" if d.via == "fault" else "->>"
            tag = _tag(d.via, d.unhandled) + _fate(d.fate)
            out.append(f"    {d.sender}{arrow}{d.receiver}: {_clean(d.event)}{tag}")
            if d.before != d.after:
                out.append(f"    Note over {d.receiver}: {d.before} to {d.after}")
    if title:
        out.append(f"    Note over {trace.devices[0]},{trace.devices[-1]}: {_clean(title)}")
    return "\n".join(out) + "\n"


def to_plantuml(trace: Trace, title: str = "") -> str:
    """A PlantUML sequence diagram of ``trace``."""
    out = ["@startuml"]
    if title:
        out.append(f"title {_clean(title)}")
    out.append(f'participant "{ENV}" as {ENV}')
    out.extend(f"participant {d}" for d in trace.devices)
    start = ", ".join(f"{d}={s}" for d, s in zip(trace.devices, trace.start, strict=True))
    out.append(f"note over {trace.devices[0]}, {trace.devices[-1]} : start: {start}")
    for step in trace.steps:
        for d in step.deliveries:
            arrow = "->>" if d.via == "fault" else "->"
            tag = _tag(d.via, d.unhandled) + _fate(d.fate)
            out.append(f"{d.sender} {arrow} {d.receiver} : {d.event}{tag}")
            if d.before != d.after:
                out.append(f"note over {d.receiver} : {d.before} -> {d.after}")
    if title:
        out.append(f"note over {trace.devices[0]}, {trace.devices[-1]} : {title}")
    out.append("@enduml")
    return "\n".join(out) + "\n"
