"""The note a batch run ends with when device work outlasted a settle (``--settle-limit``).

A batch run on the simulated clock lets time pass after each event line until the
work it started is done, but at most ``System.settle_limit`` seconds (60 by default),
which then all pass. Work still due after that is a problem only when it mattered:
an event line came while it was still in flight (the line acted on a device left
part-way), or the run ended with it. ``+SECONDS`` lines in between let it finish
without either. Neither is silent: the run ends with this note and exits 1, and
``--settle-limit`` gives the work more time.
"""

from __future__ import annotations

from collections.abc import Sequence

from statectl.run.system import System

__all__ = ["unsettled_note"]


def unsettled_note(system: System, early: Sequence[int], ended: bool) -> str:
    """One line for the run's summary, or ``""`` when no line and not the end met
    unfinished work: ``early`` are the event lines that came while it was in flight."""
    if not early and not ended:
        return ""
    limit = f"the settle limit of {system.settle_limit:g} simulated s"
    said: list[str] = []
    if early:
        lines = ", ".join(str(n) for n in early)
        said.append(
            f"line{'s' if len(early) > 1 else ''} {lines} came while device work was still "
            f"in flight after {limit}"
        )
    if ended:
        said.append(
            f"the run ended with device work still in flight after {limit}, so the devices "
            "were left part-way"
        )
    return "; ".join(said) + " (give it more time with --settle-limit SECONDS or a +SECONDS line)"
