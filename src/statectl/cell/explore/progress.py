"""A count-style progress line for long explorations (codegen's rows, testgen's nodes).

Lives beside the explorer so the testgen command (an inner ring) can show it as the
CLI does (the CLI's codegen imports it from here).
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["CountProgress", "ProgressLine"]


class ProgressLine:
    """One progress line on ``stream`` (stderr by default), rewritten in place; :meth:`done`
    ends it with a newline if anything was shown."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream: TextIO = stream if stream is not None else sys.stderr
        self.shown = False

    def show(self, text: str) -> None:
        self.stream.write(f"\r{text} ")
        self.stream.flush()
        self.shown = True

    def done(self) -> None:
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()


class CountProgress(ProgressLine):
    """``codegen``/``testgen`` progress: one line, ``WHAT: done of known NOUN``, rewritten.

    Called once per item of work with the items done and the items known so far; it
    writes nothing until the work has run ``after`` seconds (a quick run stays quiet),
    then at most every ``interval`` seconds, so the call is cheap enough for every item.
    """

    def __init__(
        self,
        what: str,
        noun: str,
        stream: TextIO | None = None,
        *,
        after: float = 0.5,
        interval: float = 0.2,
    ) -> None:
        super().__init__(stream)
        self.what = what
        self.noun = noun
        self.start = time.monotonic()
        self.next = self.start + after
        self.interval = interval

    def __call__(self, done: int, known: int) -> None:
        now = time.monotonic()
        if now < self.next:
            return
        self.next = now + self.interval
        self.show(f"{self.what}: {done:,} of {known:,} {self.noun}, {now - self.start:.1f} s")
