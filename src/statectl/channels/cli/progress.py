"""Progress of long commands (verify, codegen, testgen): one line on a terminal, rewritten.

The explorer reports :class:`~statectl.cell.explore.Progress` records to a callback and
prints nothing itself; showing them is the command line's concern.
"""

from __future__ import annotations

from statectl.cell.explore import Progress
from statectl.cell.explore.progress import ProgressLine

__all__ = ["ProgressPrinter"]


class ProgressPrinter(ProgressLine):
    """verify's progress: states, expanded, depth and rate, on one rewritten line."""

    def __call__(self, p: Progress) -> None:
        rate = p.states / p.seconds if p.seconds else 0.0
        self.show(
            f"exploring: {p.states:,} states, {p.expanded:,} expanded, depth {p.depth}, "
            f"{rate:,.0f} states/s"
        )
