"""The specification beside the implementation: the oracle of the Hypothesis module.

Rules:
1. The specification is the chart of the tables the module names, stepped by the
   pure kernel (:func:`~statectl.kernel.semantics.initial`, :func:`~statectl.kernel.semantics.step`)
   from its own snapshot and data; it never reads the device's. The implementation
   is whatever the harness runs (the ``statectl_chart`` fixture's chart and the
   driver under test, or ``--statectl-impl``), so a wrong implementation cannot
   agree with itself.
2. :meth:`Specification.check` decides an event from the specification's snapshot,
   sends it to the device and compares the device with the decision (``expect``):
   the states reached, the invokes and the API calls, or the reason nothing
   happened. The specification takes the step itself, with the data it assigns, and
   keeps or releases deferred events as the runtime does. An event the specification
   cannot take for want of data its assignments read leaves the specification where
   it was; the device must stay there too.
3. The specification keeps the calls the device owes, as every host of the tables
   does (:class:`~statectl.kernel.semantics.calls.DeviceCalls`): each notification is
   a call; a call is *owed* while the device is in a state it entered, and must be
   completed within the completion bound of when it was made.
4. Time runs only through the implementation (:meth:`run`, :meth:`inject`,
   :meth:`watch`), a tick at a time. Each event the device takes by itself must be
   one the specification allows at that moment: a completion of a call it made (it
   settles the oldest such call), the fault an active monitored state's monitor
   raises after a fault was injected (once per fault), or the timeout event of an
   active state. The specification takes each in turn and compares as in rule 2
   (the API calls by name: their data is the device's own). While a pending call's
   completion would meet a guard that reads the completion's data, which the
   specification cannot know, time runs only up to ``FAULT_BOUND`` past the call
   (what the harness assumes a device takes at least for a call; its fault probes too).
5. ``run`` lets time run until nothing is owed: a call owed longer than the bound
   fails, naming it (a device that never completes, or completes late). ``inject``
   has the device report a fault in a monitored state: the monitor must raise the
   state's fault within :data:`~statectl.out.testgen.harness.FAULT_BOUND`, unless the
   state was left first. ``watch`` checks each active monitored state's monitor runs
   and polls twice without a fault.
6. API calls come from the tables, after every rule as after every event the other
   modules send (the harness's ``expect``, the one check): the notifications in
   order with the event's data, and on statectl's runtime the calls the driver really
   made for each; a stray call or a wrong argument is named.
7. A rule the implementation cannot do (:class:`~statectl.out.testgen.adapters.Unsupported`,
   e.g. a fault over OPC UA) is skipped from then on, with a :class:`RuleSkipped`
   warning saying why; the other rules go on.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any, NoReturn, Protocol

from statectl.front.observers import extract
from statectl.kernel.model import Chart, Kept, Notify, keep_deferred, take_released
from statectl.kernel.semantics import Step, Unhandled, compiled, initial, step
from statectl.kernel.semantics.calls import CallKey, DeviceCalls
from statectl.out.testgen.adapters import Implementation, Observed, Unsupported
from statectl.out.testgen.harness import FAULT_BOUND, TICK
from statectl.out.testgen.paths import default_data, leaves
from statectl.run.runtime.eventdata import AssignError, assignments_of

__all__ = ["FAULT_DETAIL", "RuleSkipped", "Specification"]

#: The detail of the faults the ``fault`` rule injects (the monitor raises it as data).
FAULT_DETAIL = "fault injected by statectl testgen --hypothesis"
#: Polls a monitor must make while the ``monitor`` rule watches it.
POLLS = 2
_EPS = 1e-9


class RuleSkipped(UserWarning):
    """A rule of the Hypothesis module the implementation under test cannot do (rule 7)."""


class HarnessDevice(Protocol):
    """What the oracle needs of a device under test (the harness's public parts)."""

    event_data: Mapping[str, Any]
    sent: list[str]
    impl: Implementation
    completion_bound: float

    @property
    def states(self) -> tuple[str, ...]: ...

    @property
    def observed(self) -> Observed: ...

    def send(self, event: str, data: Any = None) -> None: ...

    def wait(self, seconds: float) -> int: ...

    def expect(self, *, states: Any, invokes: Any = (), unhandled: str | None = None) -> None: ...

    def assert_state(self, *states: str) -> None: ...


def _fail(device: HarnessDevice, message: str) -> NoReturn:
    __tracebackhide__ = True
    path = " -> ".join(device.sent) if device.sent else "the start"
    raise AssertionError(f"after {path}: {message}")


class Specification:
    """The tables' chart run by the kernel alone, one step per event (module rules)."""

    def __init__(self, chart: Chart, data: Mapping[str, Any] | None = None) -> None:
        self.chart = chart
        self.machine = compiled(chart)
        self.data: dict[str, Any] = dict(default_data(chart))
        self.data.update(data or {})
        self.snapshot = initial(self.machine, self.data).target
        self.calls = DeviceCalls(chart)
        self.monitors = {m.state: m.raises[0] for m in extract(chart).monitors if m.raises}
        self.timeouts = {s.name: s.timeout.event for s in chart.states if s.timeout is not None}
        self.pending: dict[CallKey, float] = {}  # call -> when it was made (rule 3)
        self.now = 0.0
        self.fault: str | None = None  # a fault injected that no monitor raised yet
        self.unsupported: dict[str, str] = {}
        self.kept: list[Kept] = []  # deferred events the device keeps

    @property
    def states(self) -> tuple[str, ...]:
        """The active atomic states the specification is in, in document order."""
        return leaves(self.chart, self.snapshot)

    def owed(self) -> list[CallKey]:
        """The calls the device owes a completion for now (rule 3)."""
        here = set(self.states)
        return [k for k in self.pending if self.calls.call(*k).entered & here]

    def monitored(self) -> list[str]:
        """The active states whose monitor raises a fault, in table order."""
        return [s for s in self.monitors if s in self.snapshot.active]

    def until(self) -> float:
        """Until when time may run (rule 4): while a pending call's completion would meet a
        guard reading its data (the device reports that data, or fails for want of it; the
        specification cannot know it), only :data:`FAULT_BOUND` past the call, the time
        the harness assumes a device takes at least for a call; else without end."""
        due = [
            made + FAULT_BOUND
            for k, made in self.pending.items()
            for c in self.calls.call(*k).completions
            if step(self.machine, self.snapshot, c, self.data).unhandled is Unhandled.GUARD_ERROR
        ]
        return min(due, default=math.inf)

    def can(self, rule: str) -> bool:
        """Whether ``rule`` (``run``, ``fault``, ``monitor``) has something to do now."""
        until = self.until()
        if rule in self.unsupported or self.now + TICK > until + _EPS:
            return False
        if rule == "run":
            return until == math.inf and bool(self.owed())
        return bool(self.monitored()) and (rule != "fault" or self.fault is None)

    def start(self, device: HarnessDevice) -> None:
        """The device starts where the specification does."""
        __tracebackhide__ = True
        device.assert_state(*self.states)

    # -- rule 2: an event sent ---------------------------------------------------------------

    def check(self, device: HarnessDevice, event: str, data: Any = None) -> None:
        """Send ``event`` to the device and compare it with the specification (rule 2)."""
        __tracebackhide__ = True
        if f"send {event}" in self.unsupported or not self._send(device, event, data):
            return
        taken = self._process(event, data if data is not None else device.event_data.get(event))
        if taken is None:
            device.assert_state(*self.states)
            return
        notes = [a for s in taken for a in s.actions if isinstance(a, Notify)]
        # the first reason of the stretch, as the device shows it (a released event's too)
        first = next((s.unhandled.value for s in taken if s.unhandled is not None), None)
        device.expect(
            states=list(self.states), invokes=[(a.invoke, a.method) for a in notes], unhandled=first
        )

    def _process(self, event: str, data: Any) -> list[Step] | None:
        """Take ``event`` as the device's runtime does: the kernel's step with the data it
        assigns, then the deferred events it keeps or releases (:mod:`statectl.run.runtime.defer`);
        None when its assignments read data it lacks (the specification stays, rule 2)."""
        decided = self._step(event, data)
        if decided is None:
            return None
        if decided.unhandled is Unhandled.DECLARED_IGNORED and event in self._deferring():
            keep_deferred(self.kept, event, data)  # kept, or dropped when full, as the runtime
            return [decided]
        taken = [decided]
        while (kept := take_released(self.kept, self._deferring())) is not None:
            released = self._step(*kept)
            taken += [released] if released is not None else []
        return taken

    def _deferring(self) -> tuple[str, ...]:
        return self.chart.deferring(self.snapshot.active)

    def _step(self, event: str, data: Any) -> Step | None:
        """One step of the kernel, taken by the specification with what it assigns."""
        decided = step(self.machine, self.snapshot, event, self.data, data)
        try:
            updates = assignments_of(decided, self.data, event, data, self.chart.name)
        except AssignError:
            return None
        self._took(decided, event, updates)
        return decided

    def _send(self, device: HarnessDevice, event: str, data: Any) -> bool:
        """Send through the harness; an event the implementation cannot take is left out
        from then on (rule 7): False then."""
        import pytest  # only ever under pytest: the harness skips through it

        before = device.states
        try:
            device.send(event, data)
        except pytest.skip.Exception as why:
            self._unsupported(f"send {event}", str(why))
            if device.states != before:
                from hypothesis import reject

                reject()  # the device moved meanwhile: this example cannot go on
            return False
        return True

    def _took(self, decided: Step, event: str, updates: Mapping[str, Any] | None) -> None:
        """The specification takes the step it decided, and notes the calls it made."""
        self.snapshot = decided.target
        self.data.update(updates or {})
        made = [(a.method, event) for a in decided.actions if isinstance(a, Notify)]
        if made:
            kept = self.calls.after_calls(tuple(self.pending), made)
            self.pending = {k: self.pending.get(k, self.now) for k in kept}

    def _unsupported(self, rule: str, why: str) -> None:
        self.unsupported[rule] = why
        warnings.warn(
            RuleSkipped(f"{self.chart.name}: the Hypothesis rule {rule!r} is skipped: {why}"),
            stacklevel=3,
        )

    # -- rules 4-5: time runs ------------------------------------------------------------------

    def run(self, device: HarnessDevice) -> None:
        """Let time run until the device owes nothing (rule 5)."""
        __tracebackhide__ = True
        start, label = self.now, len(device.sent)
        device.sent.append("(time runs)")
        while (
            self.owed()
            and self.until() == math.inf
            and self.now - start < 2 * device.completion_bound - _EPS
        ):
            if self._tick(device, "run", label) is None:
                return

    def inject(self, device: HarnessDevice) -> None:
        """Have the device report a fault; its monitor must raise it (rule 5)."""
        __tracebackhide__ = True
        watched = self.monitored()
        try:
            device.impl.inject_fault(FAULT_DETAIL)
        except Unsupported as why:
            self._unsupported("fault", f"the implementation under test cannot do this: {why}")
            return
        self.fault = FAULT_DETAIL
        start, label = self.now, len(device.sent)
        device.sent.append(f"(device fault in {', '.join(watched)})")
        while (
            self.fault is not None
            and self.monitored()
            and self.now - start < FAULT_BOUND - _EPS
            and self.now + TICK <= self.until() + _EPS
        ):
            if self._tick(device, "fault", label) is None:
                return
        if self.fault is not None and self.monitored() and self.now - start >= FAULT_BOUND - _EPS:
            raised = sorted({self.monitors[s] for s in self.monitored()})
            _fail(
                device,
                f"the device reported a fault in {', '.join(self.monitored())}, which requires "
                f"monitoring; its monitor raised nothing within {FAULT_BOUND:g} s (the tables "
                f"expect {' or '.join(raised)}); the device is in {list(device.states)}",
            )

    def watch(self, device: HarnessDevice) -> None:
        """Each active monitored state's monitor runs and polls (rule 5)."""
        __tracebackhide__ = True
        watched = self.monitored()
        try:
            before = dict(device.impl.monitoring())
        except Unsupported as why:
            self._unsupported("monitor", f"the implementation under test cannot do this: {why}")
            return
        missing = [s for s in watched if s not in before]
        if missing:
            _fail(
                device,
                f"{', '.join(missing)} requires monitoring, but no monitor runs there "
                f"(monitored: {sorted(before) or 'none'})",
            )
        start, label = self.now, len(device.sent)
        device.sent.append(f"(monitor {', '.join(watched)})")
        while self.now - start < FAULT_BOUND - _EPS:
            if self.now + TICK > self.until() + _EPS:
                return  # time may not run on (rule 4): too short a watch to count polls
            seen = self._tick(device, "monitor", label)
            if seen is None or seen.events:
                return  # something happened: the states may have changed meanwhile
            polled = device.impl.monitoring()
            if all(polled.get(s, 0) - before[s] >= POLLS for s in watched):
                return
        polled = device.impl.monitoring()
        few = [f"{s} {polled.get(s, 0) - before[s]} time(s)" for s in watched]
        _fail(
            device,
            f"the monitor of {', '.join(few)} polled in {FAULT_BOUND:g} s, expected {POLLS}",
        )

    def _tick(self, device: HarnessDevice, rule: str, label: int) -> Observed | None:
        """One tick of time through the implementation, judged (rule 4); None when the
        implementation cannot let time run (rule 7)."""
        __tracebackhide__ = True
        import pytest  # only ever under pytest: the harness skips through it

        try:
            device.wait(TICK)
        except pytest.skip.Exception as why:
            self._unsupported(rule, str(why))
            return None
        device.sent.pop()  # the tick's own entry: the rule's label says what time did
        self.now += TICK
        seen = device.observed
        if seen.events:
            taken = ", ".join(seen.events)
            device.sent[label] = f"{device.sent[label][:-1]}: {taken} by {self.now:g} s)"
        self._judge(device, seen)
        self._overdue(device)
        return seen

    def _judge(self, device: HarnessDevice, seen: Observed) -> None:
        """Rule 4: each event the device took must be allowed, and the device must be
        where the specification is after taking them all, having done what it decides
        (the harness's ``expect``, as for an event sent)."""
        __tracebackhide__ = True
        invokes: list[tuple[int, str]] = []
        reasons: list[str] = []
        released = 0  # kept events the device released: in its events, taken already
        for event in seen.events:
            if released:
                released -= 1
                continue
            taken = self._process(event, self._allowed(device, event)) or []
            released = len(taken) - 1
            for decided in taken:
                invokes += [(a.invoke, a.method) for a in decided.actions if isinstance(a, Notify)]
                if decided.unhandled is not None:
                    reasons.append(decided.unhandled.value)
        device.expect(
            states=list(self.states), invokes=invokes, unhandled=reasons[0] if reasons else None
        )

    def _allowed(self, device: HarnessDevice, event: str) -> Any:
        """Rule 4: settle what ``event``, taken by the device itself, answers, and return
        the data it comes with; an event the tables do not allow now fails."""
        __tracebackhide__ = True
        completing = [k for k in self.pending if event in self.calls.call(*k).completions]
        if completing:
            del self.pending[min(completing, key=self.pending.__getitem__)]
            return None
        if event in self.calls.unasked:
            return None
        if self.fault is not None and event in {self.monitors[s] for s in self.monitored()}:
            detail, self.fault = self.fault, None
            return {"detail": detail}
        if any(self.timeouts.get(s) == event for s in self.snapshot.active):
            return None
        if event in self.monitors.values() and self.fault is None:
            why = "no fault was reported: its fault check reports a fault the device lacks"
        else:
            why = "it completes no call the device was making, and no timeout or fault raises it"
        _fail(device, f"the device took {event} by itself in {list(self.states)}, but {why}")

    def _overdue(self, device: HarnessDevice) -> None:
        """Rule 5: no call is owed longer than the completion bound."""
        __tracebackhide__ = True
        bound = device.completion_bound
        for key in self.owed():
            if self.now - self.pending[key] >= bound - _EPS:
                call = self.calls.call(*key)
                _fail(
                    device,
                    f"{call.method}() called by {call.event} at {self.pending[key]:g} s: the "
                    f"device reported none of {list(call.completions)} within {bound:g} s; it "
                    f"is in {list(device.states)}",
                )
