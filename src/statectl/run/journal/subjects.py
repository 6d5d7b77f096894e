"""Taking up a journalled snapshot: the one place that reaches into a Subject for resume.

Rules:
1. A restored Subject is in the journalled snapshot without having entered it:
   no entry action runs and no observer is notified (the device did that work
   before the restart, or a recovery rule redoes it).
2. Listeners see ``Started`` and one ``MicrostepTaken`` entering the active
   states in document order (no transition), monitors of active states run
   again and a dashboard shows the state.
"""

from __future__ import annotations

from statectl.kernel.semantics import Snapshot
from statectl.run.runtime.subject import Subject

__all__ = ["restore_subject"]


def restore_subject(subject: Subject, snapshot: Snapshot) -> None:
    """Put ``subject`` in ``snapshot`` instead of starting it; nothing is notified.

    Listeners see ``Started`` and a ``MicrostepTaken`` entering the active states,
    and the monitors of active states run again.
    """
    subject.restore(snapshot)
