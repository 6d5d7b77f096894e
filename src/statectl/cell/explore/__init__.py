"""Verify a cell: every reachable global state, with the kernel's semantics.

``verify_cell(path)`` loads a cell file, explores it and returns a
:class:`Report`; ``export_promela`` writes the same composed model for SPIN.
"""

from statectl.cell.explore.compose import MAX_DELIVERIES, Branch, Composed, Delivery, Stimulus
from statectl.cell.explore.diagrams import to_mermaid, to_plantuml
from statectl.cell.explore.local import FreeGuard, LocalSpace, Reaction
from statectl.cell.explore.promela import export_promela
from statectl.cell.explore.report import (
    FAILURES,
    Finding,
    Kind,
    Report,
    Trace,
    TraceStep,
    Unanticipated,
)
from statectl.cell.explore.search import Progress, explore, trace_to
from statectl.cell.explore.verify import verify_cell, write_traces

__all__ = [
    "FAILURES",
    "MAX_DELIVERIES",
    "Branch",
    "Composed",
    "Delivery",
    "Finding",
    "FreeGuard",
    "Kind",
    "LocalSpace",
    "Progress",
    "Reaction",
    "Report",
    "Stimulus",
    "Trace",
    "TraceStep",
    "Unanticipated",
    "explore",
    "export_promela",
    "to_mermaid",
    "to_plantuml",
    "trace_to",
    "verify_cell",
    "write_traces",
]
