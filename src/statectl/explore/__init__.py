"""Verify a cell: every reachable global state, with the kernel's semantics.

``verify_cell(path)`` loads a cell file, explores it and returns a
:class:`Report`; ``export_promela`` writes the same composed model for SPIN.
"""

from statectl.explore.compose import MAX_DELIVERIES, Branch, Composed, Delivery, Stimulus
from statectl.explore.diagrams import to_mermaid, to_plantuml
from statectl.explore.local import FreeGuard, LocalSpace, Outcome
from statectl.explore.promela import export_promela
from statectl.explore.report import (
    FAILURES,
    Finding,
    Kind,
    Report,
    Trace,
    TraceStep,
    Unanticipated,
)
from statectl.explore.search import Progress, explore, trace_to
from statectl.explore.verify import verify_cell, write_traces

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
    "Outcome",
    "Progress",
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
