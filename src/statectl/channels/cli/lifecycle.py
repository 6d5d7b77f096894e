"""How ``statectl run`` and ``statectl node`` say a resume and end, whichever way they leave.

Rules:
1. A device resumed from its journal is one line: its states, what its Recovery
   rules did, how many accepted events were delivered again.
2. On the way out, what the command started is stopped in the reverse order it
   started (servers first: nothing posts to a System that is closing), then the
   System closes, then what must outlive that close runs (the shipper ships what
   the journal committed, for a few seconds at most).
3. A failure is said once, as ``statectl COMMAND: ...`` (no traceback), the command
   being the one the user ran (``run`` or ``node``); a journal failure the close raises
   is said so too, unless the command already said it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TextIO

from statectl.kernel.exits import PROBLEMS
from statectl.run.journal import JournalError
from statectl.run.system import System

__all__ = ["Ending", "say_resumed"]


def say_resumed(system: System, resumed: Mapping[str, bool], out: TextIO) -> None:
    """Rule 1: one line per device resumed from the journal."""
    for name, bound in system.bound.items():
        if resumed.get(name):
            taken = ", ".join(bound.recovered) or "none"
            out.write(
                f"resumed {name} in {', '.join(sorted(system.subjects[name].configuration))}"
                f"; recovery: {taken}; {bound.redelivered} accepted event(s) redelivered\n"
            )


class Ending:
    """What a run or a node started, ended in its ``finally`` (rules 2 and 3)."""

    def __init__(self, command: str, err: TextIO) -> None:
        self.command = command
        self.err = err
        self.failed = ""  # what the command reported as its failure, if anything
        self.system: System | None = None
        self._started: list[Callable[[], object]] = []
        self._after: list[Callable[[], object]] = []

    def started(self, stop: Callable[[], object]) -> None:
        """Something running beside the System (a server): ``stop`` it first, newest first."""
        self._started.append(stop)

    def after_close(self, finish: Callable[[], object]) -> None:
        """Something that must run once the System has closed (the shipper's last ship)."""
        self._after.append(finish)

    def fail(self, exc: BaseException, what: str = "") -> int:
        """Rule 3: say the failure once; the exit status."""
        self.failed = str(exc)
        self.err.write(f"statectl {self.command}: {what}{exc}\n")
        return PROBLEMS

    def close(self) -> None:
        """Rule 2, in its order."""
        for stop in reversed(self._started):
            stop()
        if self.system is not None:
            try:
                self.system.close()
            except JournalError as exc:
                if str(exc) not in self.failed:
                    self.err.write(f"statectl {self.command}: {exc}\n")
        for finish in self._after:
            finish()
