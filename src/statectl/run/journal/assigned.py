"""On resume, the data a device's assignments changed, brought back from its journal.

The journal keeps each step's snapshot and event, not the device's data; data that
event rows change (``assign``) would come back at its initial values after a
restart, a counter silently reset. So a resuming device replays, from its initial
data, the assignments of every handled step the journal holds for it, in order,
each decided again by :func:`statectl.kernel.semantics.step` from the snapshot before it
(steps are pure, so the decision and the values are those of the run). Charts that
assign nothing skip this entirely.
"""

from __future__ import annotations

from statectl.kernel.model import Assign
from statectl.kernel.semantics import Outcome, Snapshot, step
from statectl.run.journal.format import StepKind
from statectl.run.journal.read import JournalReader
from statectl.run.runtime import Subject
from statectl.run.runtime.eventdata import assignments_of

__all__ = ["replay_assigned_data"]


def replay_assigned_data(subject: Subject, reader: JournalReader, upto: int) -> int:
    """Bring back ``subject``'s assigned data from the journal's steps up to row ``upto``.

    Returns how many steps changed data. Call after the snapshot was restored,
    before the device processes anything.
    """
    chart = subject.chart
    if not any(isinstance(a, Assign) for t in chart.transitions for a in t.actions):
        return 0
    data = dict(subject.data)
    before: Snapshot | None = None
    changed = 0
    for row in reader.steps(subject.name, upto=upto):
        taken = row.kind in (StepKind.EVENT, StepKind.RECOVERY) and row.outcome == Outcome.HANDLED
        if taken and before is not None and row.event is not None:
            decision = step(subject.machine, before, row.event, data, row.data)
            updates = assignments_of(decision, data, row.event, row.data, subject.name)
            if updates:
                data.update(updates)
                changed += 1
        before = row.snapshot
    subject._engine.data.update(data)  # the owner's data, before it processes anything
    return changed
