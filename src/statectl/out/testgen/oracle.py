"""The specification beside the implementation: the oracle of the Hypothesis module.

Rules:
1. The specification is the chart of the tables the module names, stepped by the
   pure kernel (:func:`~statectl.kernel.semantics.initial`, :func:`~statectl.kernel.semantics.step`)
   from its own snapshot and data; it never reads the device's. The implementation
   is whatever the harness runs (the ``statectl_chart`` fixture's chart and the
   driver under test), so a wrong implementation cannot agree with itself.
2. :meth:`Specification.check` decides an event from the specification's snapshot,
   sends it to the device through the harness's public methods and compares the
   device with the decision (``expect``): the states reached, the invokes and the
   driver's API call for each, or the reason nothing happened. Then the
   specification takes the step itself, with the data it assigns.
3. An event the specification cannot take for want of data its assignments read
   leaves the specification where it was; the device must stay there too.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

from statectl.kernel.model import Chart, Notify
from statectl.kernel.semantics import compiled, initial, step
from statectl.out.testgen.paths import default_data, leaves
from statectl.run.runtime.eventdata import AssignError, assignments_of

__all__ = ["Specification"]


class HarnessDevice(Protocol):
    """What the oracle needs of a device under test (the harness's public methods)."""

    event_data: Mapping[str, Any]

    def send(self, event: str, data: Any = None) -> None: ...

    def expect(self, *, states: Any, invokes: Any = (), unhandled: str | None = None) -> None: ...

    def assert_state(self, *states: str) -> None: ...


class Specification:
    """The tables' chart run by the kernel alone, one step per event sent (rule 1)."""

    def __init__(self, chart: Chart, data: Mapping[str, Any] | None = None) -> None:
        self.chart = chart
        self.machine = compiled(chart)
        self.data: dict[str, Any] = dict(default_data(chart))
        self.data.update(data or {})
        self.snapshot = initial(self.machine, self.data).target

    @property
    def states(self) -> tuple[str, ...]:
        """The active atomic states the specification is in, in document order."""
        return leaves(self.chart, self.snapshot)

    def start(self, device: HarnessDevice) -> None:
        """The device starts where the specification does."""
        __tracebackhide__ = True
        device.assert_state(*self.states)

    def check(self, device: HarnessDevice, event: str, data: Any = None) -> None:
        """Send ``event`` to the device and compare it with the specification (rule 2)."""
        __tracebackhide__ = True
        value = data if data is not None else device.event_data.get(event)
        decided = step(self.machine, self.snapshot, event, self.data, value)
        try:
            updates = assignments_of(decided, self.data, event, value, self.chart.name)
        except AssignError:  # rule 3
            device.send(event, data)
            device.assert_state(*self.states)
            return
        device.send(event, data)
        device.expect(
            states=list(leaves(self.chart, decided.target)),
            invokes=[(a.invoke, a.method) for a in decided.actions if isinstance(a, Notify)],
            unhandled=decided.unhandled.value if decided.unhandled is not None else None,
        )
        self.snapshot = decided.target
        self.data.update(updates or {})
