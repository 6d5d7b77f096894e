"""Progress of long commands (verify, codegen, testgen): one line on a terminal, rewritten.

The explorer reports :class:`~statectl.explore.Progress` records to a callback and
prints nothing itself; showing them is the command line's concern.
"""

from __future__ import annotations

import sys
from typing import TextIO

from statectl.explore import Progress
from statectl.explore.progress import CountProgress

__all__ = ["CountProgress", "ProgressPrinter"]


class ProgressPrinter:
    """A one-line progress display on a terminal stream (rewritten in place)."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream: TextIO = stream if stream is not None else sys.stderr
        self.shown = False

    def __call__(self, p: Progress) -> None:
        rate = p.states / p.seconds if p.seconds else 0.0
        text = (
            f"\rexploring: {p.states:,} states, {p.expanded:,} expanded, depth {p.depth}, "
            f"{rate:,.0f} states/s "
        )
        self.stream.write(text)
        self.stream.flush()
        self.shown = True

    def done(self) -> None:
        if self.shown:
            self.stream.write("\n")
