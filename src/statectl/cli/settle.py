"""The note a batch run ends with when a settle stopped at its limit (``--settle-limit``).

A batch run on the simulated clock lets time pass after each event until the work
it started is done, but at most ``System.settle_limit`` seconds (60 by default); a
device whose work takes longer is left half-way. That is never silent: the run
ends with this note and exits 1, and ``--settle-limit`` gives the work more time.
"""

from __future__ import annotations

from statectl.system import System

__all__ = ["unsettled_note"]


def unsettled_note(system: System) -> str:
    """One line for the run's summary, or ``""`` when every settle finished its work."""
    if not system.settle_cut:
        return ""
    return (
        f"{system.settle_cut} time(s) device work was still pending after the settle limit "
        f"of {system.settle_limit:g} simulated s, so the devices were left part-way "
        "(give it more time with --settle-limit SECONDS)"
    )
