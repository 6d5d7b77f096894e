"""Timeouts in the explorer: a state's timeout event may happen whenever the state is active.

The explorer has no clock: a timeout runs out after an unknown wait, so the search
offers the timeout event to the device (as a ``completion`` stimulus: the device
raises it itself) in every local state where a state with that timeout is active,
and never elsewhere. Every interleaving with the cell's other stimuli is explored,
which covers every duration.
"""

from __future__ import annotations

from statectl.cell.explore.local import LocalSpace
from statectl.kernel.model import Chart

__all__ = ["timeout_events", "timing_out"]


def timeout_events(chart: Chart) -> tuple[str, ...]:
    """The distinct events of the chart's state timeouts, in state order."""
    return tuple(dict.fromkeys(s.timeout.event for s in chart.states if s.timeout))


def timing_out(space: LocalSpace, lid: int, event: str) -> bool:
    """Whether local state ``lid`` has an active state whose timeout raises ``event``."""
    chart = space.chart
    for name in space.snapshots[lid].active:
        timeout = chart.state(name).timeout
        if timeout is not None and timeout.event == event:
            return True
    return False
