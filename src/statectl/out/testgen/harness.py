"""The device under test: a Subject on a SimClock wired to a driver, with a recorder.

Rules:
1. The Subject runs the chart (the kernel decides); the driver is whatever the
   test was given, the tables' simulated twin by default. Time stands still
   unless the test calls :meth:`DeviceUnderTest.advance`, so nothing the driver
   schedules on the clock (its completions, its monitors' polls) happens behind
   the test's back.
2. :meth:`DeviceUnderTest.send` processes one event and keeps the records it
   produced; :meth:`DeviceUnderTest.expect` compares them with the tables: the
   states reached, the invoke numbers issued and their observer methods, the
   device API the driver called for each (``api``: observer method -> API
   function; by default the driver's own ``methods`` table, else the method's
   name as the twin calls it), or why the event changed nothing and that the
   driver was not called.
3. Every failure says what was sent, what was expected and what happened.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from statectl.front.observers import Observer
from statectl.kernel.model import Chart, Notify, StateKind
from statectl.kernel.semantics import Outcome, Unhandled
from statectl.kernel.semantics import step as kernel_step
from statectl.out.testgen.coverage import Tally
from statectl.run.devices import SimTwin, connect
from statectl.run.devices.base import Driver
from statectl.run.runtime import (
    ApiLogging,
    EventIgnored,
    EventRejected,
    InvokeIssued,
    ObserverCalled,
    Record,
    SimClock,
    Subject,
)

__all__ = ["DeviceUnderTest", "Recorder", "api_function"]


class Recorder:
    """Keeps every record the Subject emits, and marks where the last event began."""

    def __init__(self) -> None:
        self.records: list[Record] = []
        self.mark = 0

    def __call__(self, record: Record) -> None:
        self.records.append(record)

    def since_mark(self) -> list[Record]:
        return self.records[self.mark :]


def api_function(call: str) -> str:
    """``SimMotor.move_to(10.0)`` -> ``move_to``: the function an ObserverCalled names."""
    return call.split("(", 1)[0].rsplit(".", 1)[-1]


def _default_api(driver: Observer) -> dict[str, str] | None:
    table = getattr(type(driver), "methods", None)
    if isinstance(table, Mapping) and table:
        return {str(k): str(v) for k, v in table.items()}
    return None


class DeviceUnderTest:
    """A started device whose every event is checked against what its tables say."""

    def __init__(
        self,
        chart: Chart,
        driver: Observer | None = None,
        *,
        data: Mapping[str, Any] | None = None,
        event_data: Mapping[str, Any] | None = None,
        api: Mapping[str, str | None] | None = None,
        strict: bool = False,
        tally: Tally | None = None,
        where: str = "",
    ) -> None:
        self.chart = chart
        self.strict = strict
        self.clock = SimClock()
        self.subject = Subject(chart, clock=self.clock, data=data)
        self.driver: Observer = driver if driver is not None else SimTwin(chart)
        self.event_data = dict(event_data or {})
        given = _default_api(self.driver) if api is None else dict(api)
        self.api: Mapping[str, str | None] | None = given
        self.recorder = Recorder()
        self.subject.listen(self.recorder)
        if hasattr(self.driver, "bind") and hasattr(self.driver, "poll_fault"):
            connect(self.subject, self.driver)  # type: ignore[arg-type]  # a DeviceDriver
        else:
            self.subject.attach(self.driver)  # a plain observer: no monitors to poll it
        self.sent: list[str] = []
        self.dropped: list[str] = []  # what the driver reported after stall()
        self.subject.start()
        if tally is not None:
            self._count(tally, where)

    def _count(self, tally: Tally, where: str) -> None:
        """Tell ``tally`` every step the device takes (the plugin's --statectl-coverage)."""
        subject = self.subject
        start = subject.snapshot
        if start is None:
            return
        tally.start(start)
        last = [start]

        def heard(event: str, data: Any, outcome: str) -> None:
            after = subject.snapshot
            if after is None:
                return
            if outcome == Outcome.HANDLED:
                tally.event(last[0], event, subject.data, data, after, where)
            last[0] = after

        subject.on_step(heard)

    # -- driving -------------------------------------------------------------------------------

    @property
    def states(self) -> tuple[str, ...]:
        """The active atomic states in document order: the state reached."""
        m = self.subject.machine
        return tuple(
            s
            for s in sorted(self.subject.configuration, key=m.order.__getitem__)
            if m.kind[s] in (StateKind.ATOMIC, StateKind.FINAL)
        )

    def send(self, event: str, data: Any = None) -> None:
        """Process ``event`` (with ``data``, else ``event_data[event]``) to completion.

        With ``strict``, an event that meets a state the tables neither handle it in
        nor declare it ignored (the kernel's ``no transition``) fails at once.
        """
        __tracebackhide__ = True
        self.recorder.mark = len(self.recorder.records)
        before = self.states
        self.sent.append(event)
        self.subject.dispatch(event, data if data is not None else self.event_data.get(event))
        if self.strict:
            missed = [
                r.event
                for r in self.recorder.since_mark()
                if isinstance(r, EventIgnored | EventRejected)
                and r.reason is Unhandled.NO_TRANSITION
            ]
            if missed:
                raise AssertionError(
                    f"{self._path()}: {', '.join(missed)} in {list(before)} is a pair the tables "
                    "neither handle nor ignore (statectl_strict); add a row or an ignore entry"
                )

    def given(self, *events: str | Sequence[Any]) -> None:
        """Send each event (or ``[event, data]``) in turn; each must be handled."""
        __tracebackhide__ = True
        for item in events:
            if isinstance(item, str):
                e, data = item, None
            else:
                e, data = item[0], item[1]
            self.send(e, data)
            reason = self._unhandled()
            if reason is not None:
                raise AssertionError(
                    f"{self._path()}: {e!r} was not handled in the path to the case "
                    f"({reason}); the device is in {list(self.states)}"
                )
            problems = self._check_calls(self._issued())
            if problems:
                raise AssertionError(f"{self._path()}: " + "; ".join(problems))

    def step(self, event: str, data: Any = None) -> None:
        """Send ``event`` and check the outcome against the kernel's decision for it.

        What the kernel decides from the device's snapshot before the event is the
        expectation: the states reached, the invokes issued (with their methods, so
        the driver's API calls are checked), or the reason nothing happened.
        """
        __tracebackhide__ = True
        before = self.subject.snapshot
        value = data if data is not None else self.event_data.get(event)
        if before is None or event not in self.subject.machine.event_names:
            self.send(event, data)
            return
        decided = kernel_step(self.subject.machine, before, event, self.subject.data, value)
        self.send(event, data)
        m = self.subject.machine
        self.expect(
            states=[
                s
                for s in sorted(decided.target.active, key=m.order.__getitem__)
                if m.kind[s] in (StateKind.ATOMIC, StateKind.FINAL)
            ],
            invokes=[(a.invoke, a.method) for a in decided.actions if isinstance(a, Notify)],
            unhandled=decided.unhandled.value if decided.unhandled is not None else None,
        )

    def advance(self, seconds: float) -> int:
        """Move the simulated clock on (the driver's completions and monitors run)."""
        return self.subject.advance(seconds)

    def wait(self, seconds: float) -> int:
        """Move the clock on, and check what happened meanwhile with :meth:`expect`
        (a timeout's transition: what the device did without being sent anything)."""
        self.recorder.mark = len(self.recorder.records)
        self.sent.append(f"(wait {seconds:g} s)")
        return self.subject.advance(seconds)

    def stall(self) -> None:
        """From now on the driver's own reports (its completions) are dropped, as from a
        device that went silent: a state's timeout can then run out in a test."""
        if isinstance(self.driver, Driver) and self.driver._clock is not None:
            Driver.bind(self.driver, self._drop, self.driver._clock)

    def _drop(self, event: str, data: Any = None) -> None:
        self.dropped.append(event)

    # -- checking ------------------------------------------------------------------------------

    def assert_state(self, *states: str) -> None:
        """The device is in exactly ``states`` (its active atomic states, document order)."""
        __tracebackhide__ = True
        if tuple(states) != self.states:
            raise AssertionError(
                f"{self._path()}: expected the state {list(states)}, "
                f"device is in {list(self.states)}"
            )

    def assert_called(self, name: str) -> None:
        """The last event made the driver call ``name``: an API function or observer method."""
        __tracebackhide__ = True
        called = self._called()
        if not any(name in (m, api_function(api)) for m, api in called):
            shown = [api for _, api in called] or "nothing"
            raise AssertionError(
                f"{self._path()}: expected the driver to call {name}(), it called {shown}"
            )

    def _path(self) -> str:
        return "after " + (" -> ".join(self.sent) if self.sent else "the start")

    def _unhandled(self) -> str | None:
        for r in self.recorder.since_mark():
            if isinstance(r, EventIgnored | EventRejected):
                return r.reason.value
        return None

    def _issued(self) -> list[tuple[int, str]]:
        return [
            (r.invoke, r.method) for r in self.recorder.since_mark() if isinstance(r, InvokeIssued)
        ]

    def _called(self) -> list[tuple[str, str]]:
        return [
            (r.method, r.api) for r in self.recorder.since_mark() if isinstance(r, ObserverCalled)
        ]

    def expect(
        self,
        *,
        states: Sequence[str],
        invokes: Iterable[Sequence[Any]] = (),
        unhandled: str | None = None,
    ) -> None:
        """Compare the last event's outcome with the tables' (rule 2)."""
        __tracebackhide__ = True
        problems: list[str] = []
        if tuple(states) != self.states:
            problems.append(f"state: expected {list(states)}, device is in {list(self.states)}")
        reason = self._unhandled()
        if reason != unhandled:
            want = f"unhandled ({unhandled})" if unhandled else "handled"
            got = f"unhandled ({reason})" if reason else "handled"
            problems.append(f"outcome: expected {want}, it was {got}")
        wanted = [(int(n), str(m)) for n, m in invokes]
        issued = self._issued()
        if issued != wanted:
            problems.append(f"invokes: expected {wanted}, issued {issued}")
        problems += self._check_calls(wanted)
        if problems:
            raise AssertionError(f"{self._path()}: " + "; ".join(problems))

    def _check_calls(self, wanted: list[tuple[int, str]]) -> list[str]:
        called = self._called()
        if not wanted:
            if called:
                return [f"the driver was called though nothing was notified: {called}"]
            return []
        if not isinstance(self.driver, ApiLogging):
            return []  # a plain observer: the Subject notes update(#n), nothing to compare
        problems = []
        for _, method in wanted:
            calls = [api for m, api in called if m == method]
            if not calls:
                problems.append(f"{method}(): the driver made no API call")
                continue
            expected = self.api.get(method, method) if self.api is not None else method
            if expected is not None and expected not in [api_function(c) for c in calls]:
                problems.append(
                    f"{method}(): expected the API call {expected}(), the driver called {calls}"
                )
        return problems
