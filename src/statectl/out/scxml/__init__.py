"""SCXML: read documents into charts, run them with full SCXML semantics, write them back.

``read_scxml`` (text -> chart + diagnostics), ``Session``/``Scheduler`` (the
interpreter, on a real or simulated clock) and ``run_file`` (one document to its
top-level final state) are the entry points; the W3C algorithm itself is
:mod:`statectl.kernel.semantics`.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from statectl.out.scxml.reader import read_scxml, read_scxml_file
from statectl.out.scxml.scheduler import RealClock, Scheduler, SessionTimeout, SimulatedClock
from statectl.out.scxml.session import Session
from statectl.out.scxml.writer import write_scxml

__all__ = [
    "RealClock",
    "Scheduler",
    "Session",
    "SessionTimeout",
    "SimulatedClock",
    "read_scxml",
    "read_scxml_file",
    "run_file",
    "write_scxml",
]


def run_file(
    path: str,
    timeout: float,
    *,
    simulated: bool = False,
    verbose: bool = False,
    allow_src: bool = False,
) -> str | None:
    """Run one document; return the id of the top-level final state reached, else ``None``.

    Delays run on the wall clock unless ``simulated`` (then time jumps to the next
    delayed send and ``timeout`` is simulated seconds). Either way the run also
    stops after ``timeout`` wall-clock seconds with :class:`SessionTimeout`,
    whatever the document does. ``allow_src`` lets a ``safe``/``null`` document
    read ``src`` files inside its own directory. A document with errors raises
    :class:`~statectl.kernel.errors.DiagnosticError`.
    """
    chart = read_scxml_file(path)
    clock = SimulatedClock() if simulated else RealClock()
    log = (lambda text: print(text, file=sys.stderr)) if verbose else None
    scheduler = Scheduler(clock, log, log)
    scheduler.wall_deadline = time.monotonic() + timeout
    session = Session(chart, scheduler, base=Path(path).resolve().parent, allow_src=allow_src)
    try:
        return scheduler.run(session, clock.now() + timeout)
    finally:
        if isinstance(clock, RealClock):
            clock.stop()  # its timer thread, started by the first delayed send
