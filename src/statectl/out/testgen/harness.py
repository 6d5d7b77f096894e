"""The device under test: an implementation of the tables, checked event by event.

Rules:
1. The implementation is whatever the test was given (:mod:`.adapters`): statectl's
   runtime with the test's driver by default (the tables' simulated twin unless told
   otherwise; time stands still until :meth:`DeviceUnderTest.advance`), the generated
   C++, a device over OPC UA or a hand-written class.
2. :meth:`DeviceUnderTest.send` processes one event and keeps what the implementation
   showed; :meth:`DeviceUnderTest.expect` compares it with the tables: the states
   reached, the invoke numbers issued and their observer methods, the device API calls
   made (the observer methods the tables notify, with the event's data as arguments,
   in order: a stray call or a wrong argument fails naming it), or why the event changed
   nothing. On the runtime the calls are the ones the driver really made (its API log,
   per notification served): one call each of the method's function (``api``: observer
   method -> function; by default the driver's ``methods`` table, else the method's
   name), with the event's data or nothing as argument where that is the method's own
   name; a second call, another method's function or a call made by itself fails.
3. Faults, monitors and completions go through the implementation: :meth:`fault` has
   the device report a fault that its monitor must raise, :meth:`assert_monitored`
   checks a monitor polls, :meth:`complete` lets time run until the device reports a
   completion (within a bound), :meth:`restart` stops and resumes the device.
4. Every failure says what was sent, what was expected and what happened. A test
   needing what the implementation cannot do (restart a C++ harness) is skipped, saying so.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, NoReturn

from statectl.front.observers import Observer
from statectl.front.tables import RecoveryRow
from statectl.kernel.model import Chart, EventKind, Notify, StateKind
from statectl.kernel.semantics import Outcome, Unhandled
from statectl.kernel.semantics import step as kernel_step
from statectl.out.testgen.adapters import ApiMade, Call, Implementation, Observed, Unsupported
from statectl.out.testgen.adapters.runtime import Recorder, RuntimeImpl
from statectl.out.testgen.coverage import Tally
from statectl.run.runtime import SimClock, Subject

__all__ = ["COMPLETION_BOUND", "FAULT_BOUND", "DeviceUnderTest", "api_function"]

#: Seconds a device may take to report a completion when its state has no timeout.
COMPLETION_BOUND = 5.0
#: Seconds a monitor may take to raise a fault the device reported (five polls of the
#: runtime's default period; shorter than the twin's 1 s work, so its completion comes after).
FAULT_BOUND = 0.5
#: The step time runs in while a test waits for a completion, a fault or a poll.
TICK = 0.05


def api_function(call: str) -> str:
    """``SimMotor.move_to(10.0)`` -> ``move_to``: the function an ObserverCalled names."""
    return call.split("(", 1)[0].rsplit(".", 1)[-1]


def _default_api(driver: Observer) -> dict[str, str] | None:
    table = getattr(type(driver), "methods", None)
    if isinstance(table, Mapping) and table:
        return {str(k): str(v) for k, v in table.items()}
    return None


def _merge(a: Observed, b: Observed) -> Observed:
    """What two stretches showed together (an event, then time run on)."""

    def both(x: tuple[Any, ...] | None, y: tuple[Any, ...] | None) -> tuple[Any, ...] | None:
        return None if x is None or y is None else (*x, *y)

    return Observed(
        a.unhandled if a.unhandled is not None else b.unhandled,
        both(a.invokes, b.invokes),
        both(a.calls, b.calls),
        (*a.events, *b.events),
        (*a.unhandled_all, *b.unhandled_all),
        both(a.driver_calls, b.driver_calls),
        both(a.served, b.served),
    )


def _skip(why: Unsupported) -> NoReturn:
    import pytest  # only ever under pytest: the plugin's fixtures make these devices

    pytest.skip(f"the implementation under test cannot do this: {why}")


class DeviceUnderTest:
    """A started implementation whose every event is checked against what its tables say."""

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
        impl: Implementation | None = None,
        new_driver: Callable[[Chart], Any] | None = None,
        recovery: tuple[RecoveryRow, ...] = (),
        completion_bound: float = COMPLETION_BOUND,
    ) -> None:
        self.chart = chart
        self.strict = strict
        self.completion_bound = completion_bound
        self.runtime: RuntimeImpl | None = None
        if impl is None:
            self.runtime = RuntimeImpl(
                chart, driver, data=data, new_driver=new_driver, recovery=recovery
            )
            impl = self.runtime
        self.impl: Implementation = impl
        self.event_data = dict(event_data or {})
        if self.runtime is not None:
            given = _default_api(self.runtime.driver) if api is None else dict(api)
        else:
            given = dict(api) if api is not None else None
        self.api: Mapping[str, str | None] | None = given
        #: the API names are the driver's own declared table (no ``statectl_api`` given)
        self._own_api = self.runtime is not None and api is None and given is not None
        self.sent: list[str] = []
        self._seen = Observed(invokes=(), calls=(), driver_calls=(), served=())
        self._data: Any = None  # the data of the last event sent: the API calls' arguments
        self._data_known = False
        if self.runtime is not None:
            self.runtime.start()
            if tally is not None:
                self._count(tally, where)

    # -- the runtime's parts (tests written for the runtime reach them) ----------------------

    @property
    def subject(self) -> Subject:
        return self._runtime().subject

    @property
    def recorder(self) -> Recorder:
        return self._runtime().recorder

    @property
    def clock(self) -> SimClock:
        return self._runtime().clock

    @property
    def driver(self) -> Observer:
        return self._runtime().driver

    @property
    def dropped(self) -> list[str]:
        return self._runtime().dropped

    def _runtime(self) -> RuntimeImpl:
        if self.runtime is None:
            raise AttributeError(f"{type(self.impl).__name__} is not statectl's runtime")
        return self.runtime

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
        return tuple(self.impl.states())

    @property
    def observed(self) -> Observed:
        """What the implementation showed for the last event sent or stretch of time."""
        return self._seen

    def send(self, event: str, data: Any = None) -> None:
        """Process ``event`` (with ``data``, else ``event_data[event]``) to completion.

        With ``strict``, an event that meets a state the tables neither handle it in
        nor declare it ignored (the kernel's ``no transition``) fails at once.
        """
        __tracebackhide__ = True
        before = self.states
        self.sent.append(event)
        value = data if data is not None else self.event_data.get(event)
        self._data, self._data_known = value, True
        try:
            self._seen = self.impl.send(event, value)
        except Unsupported as why:
            _skip(why)
        if self.strict:
            missed = [e for e, r in self._seen.unhandled_all if r == Unhandled.NO_TRANSITION.value]
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
            issued = self._issued()
            problems = self._check_calls(issued) if issued is not None else []
            if problems:
                raise AssertionError(f"{self._path()}: " + "; ".join(problems))

    def step(self, event: str, data: Any = None) -> None:
        """Send ``event`` and check the outcome against the kernel's decision for it.

        What the kernel decides from the device's snapshot before the event is the
        expectation: the states reached, the invokes issued (with their methods, so
        the driver's API calls are checked), or the reason nothing happened.
        """
        __tracebackhide__ = True
        if self.runtime is None:
            _skip(Unsupported("step() follows the runtime's snapshot; use send and expect"))
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
        """Let time run (the driver's completions and monitors run); what happens meanwhile
        counts with the last event's outcome. Returns the events the device took."""
        try:
            seen = self.impl.advance(seconds)
        except Unsupported as why:
            _skip(why)
        self._seen = _merge(self._seen, seen)
        return len(seen.events)

    def wait(self, seconds: float) -> int:
        """Let time run, and check what happened meanwhile with :meth:`expect`
        (a timeout's transition: what the device did without being sent anything)."""
        self.sent.append(f"(wait {seconds:g} s)")
        self._data_known = False
        try:
            self._seen = self.impl.advance(seconds)
        except Unsupported as why:
            _skip(why)
        return len(self._seen.events)

    def stall(self) -> None:
        """From now on the driver's own reports (its completions) are dropped, as from a
        device that went silent: a state's timeout can then run out in a test."""
        try:
            self.impl.stall()
        except Unsupported as why:
            _skip(why)

    def _run_until(self, within: float, done: Callable[[Observed], bool]) -> float:
        """Let time run a tick at a time until ``done`` or ``within`` seconds passed."""
        self._data_known = False
        seen = Observed(invokes=(), calls=(), driver_calls=(), served=())
        waited = 0.0
        while waited < within - 1e-9 and not done(seen):
            tick = min(TICK, within - waited)
            try:
                seen = _merge(seen, self.impl.advance(tick))
            except Unsupported as why:
                _skip(why)
            waited += tick
        self._seen = seen
        return waited

    def fault(
        self, detail: str = "fault injected by statectl testgen", within: float = FAULT_BOUND
    ) -> None:
        """Have the device report a fault, then let time run until its monitor raised an
        event or ``within`` seconds passed; :meth:`expect` checks what followed."""
        self.sent.append(f"(device fault in {'/'.join(self.states)})")
        try:
            self.impl.inject_fault(detail)
        except Unsupported as why:
            _skip(why)
        self._run_until(within, lambda seen: bool(seen.events))

    def complete(self, event: str, within: float | None = None) -> None:
        """Let time run until the device reports ``event`` (a completion): within ``within``
        seconds (the state's timeout), else the suite's completion bound."""
        __tracebackhide__ = True
        bound = self.completion_bound if within is None else within
        called = [f"{m}()" for _, m in self._seen.invokes or ()]  # the calls it answers
        self.sent.append(f"(until {event})")
        waited = self._run_until(bound, lambda seen: bool(seen.events))
        got = self._seen.events
        if not got or got[0] != event:
            found = f"it reported {list(got)} first" if got else "it reported nothing"
            answers = f"; the call it answers: {', '.join(called)}" if called else ""
            raise AssertionError(
                f"{self._path()}: expected the device to report {event} within {bound:g} s; "
                f"{found} (waited {waited:g} s); the device is in {list(self.states)}{answers}"
            )

    def assert_monitored(self, state: str, polls: int = 2, within: float = FAULT_BOUND) -> None:
        """A monitor runs in ``state`` and polls ``polls`` times, raising nothing while the
        device reports no fault."""
        __tracebackhide__ = True
        try:
            before = self.impl.monitoring()
        except Unsupported as why:
            _skip(why)
        if state not in before:
            raise AssertionError(
                f"{self._path()}: {state} requires monitoring, but no monitor runs there "
                f"(monitored: {sorted(before) or 'none'})"
            )
        start = before[state]

        def polled(seen: Observed) -> bool:
            return bool(seen.events) or self.impl.monitoring().get(state, 0) - start >= polls

        self.sent.append(f"(monitor {state})")
        waited = self._run_until(within, polled)
        if self._seen.events:
            raise AssertionError(
                f"{self._path()}: expected the monitor of {state} to poll {polls} time(s) and "
                f"raise nothing, as the device reported no fault; within {waited:g} s the "
                f"device took {self._kinds(self._seen.events)} and is in {list(self.states)}"
            )
        done = self.impl.monitoring().get(state, 0) - start
        if done < polls:
            raise AssertionError(
                f"{self._path()}: expected the monitor of {state} to poll {polls} time(s) "
                f"within {within:g} s; it polled {done} time(s)"
            )

    def _kinds(self, events: Sequence[str]) -> str:
        """``Leak (a fault its monitor raised though none was reported), ...``: each event the
        device took by itself, said as what it is."""
        said = {
            EventKind.FAULT: "a fault its monitor raised though none was reported",
            EventKind.COMPLETION: "a completion the device reported",
        }
        parts = []
        for e in events:
            d = self.chart.event(e)
            what = said.get(d.kind, f"a {d.kind.value} event") if d is not None else "an event"
            parts.append(f"{e} ({what})")
        return ", ".join(parts)

    def restart(self) -> None:
        """Stop the device as a power loss would and resume it from what it persisted;
        :meth:`expect` checks what resuming did (the Recovery table's row)."""
        self.sent.append("(restart)")
        self._data_known = False
        try:
            self._seen = self.impl.restart()
        except Unsupported as why:
            _skip(why)

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
        calls = [c.method for c in self._seen.calls or ()]
        if not any(name in (m, api_function(api)) for m, api in called) and name not in calls:
            shown = [api for _, api in called] or [str(c) for c in self._seen.calls or ()]
            raise AssertionError(
                f"{self._path()}: expected the driver to call {name}(), it called "
                f"{shown or 'nothing'}"
            )

    def _path(self) -> str:
        return "after " + (" -> ".join(self.sent) if self.sent else "the start")

    def _unhandled(self) -> str | None:
        return self._seen.unhandled

    def _issued(self) -> list[tuple[int, str]] | None:
        invokes = self._seen.invokes
        if invokes is not None:
            return list(invokes)
        if self._seen.calls is not None:
            return [(-1, c.method) for c in self._seen.calls]
        return None

    def _called(self) -> list[tuple[str, str]]:
        return list(self._seen.driver_calls or ())

    def expect(
        self,
        *,
        states: Sequence[str],
        invokes: Iterable[Sequence[Any]] = (),
        unhandled: str | None = None,
        raised: Sequence[str] | None = None,
    ) -> None:
        """Compare the last event's outcome with the tables' (rule 2); ``raised``: the
        events the device took by itself (a fault its monitor raised, a completion)."""
        __tracebackhide__ = True
        seen = self._seen
        problems: list[str] = []
        if tuple(states) != self.states:
            problems.append(f"state: expected {list(states)}, device is in {list(self.states)}")
        reason = seen.unhandled
        if reason != unhandled and not (reason == "unhandled" and unhandled is not None):
            want = f"unhandled ({unhandled})" if unhandled else "handled"
            got = f"unhandled ({reason})" if reason else "handled"
            problems.append(f"outcome: expected {want}, it was {got}")
        if raised is not None and list(seen.events) != list(raised):
            problems.append(f"raised: expected {list(raised)}, the device took {list(seen.events)}")
        wanted = [(int(n), str(m)) for n, m in invokes]
        if seen.invokes is not None and list(seen.invokes) != wanted:
            problems.append(f"invokes: expected {wanted}, issued {list(seen.invokes)}")
        problems += self._check_api(wanted)
        problems += self._check_calls(wanted)
        if problems:
            raise AssertionError(f"{self._path()}: " + "; ".join(problems))

    def _check_api(self, wanted: list[tuple[int, str]]) -> list[str]:
        """Rule 2: the API calls made are the tables' notifications, in order, with the
        event's data as their arguments; a stray or a wrong one is named."""
        made = self._seen.calls
        if made is None:
            return []
        problems = []
        expected = [Call(m, self._data) for _, m in wanted]
        for i, call in enumerate(made):
            if i >= len(expected):
                problems.append(f"stray API call {call}: the tables make no such call here")
            elif call.method != expected[i].method:
                problems.append(f"API call {i + 1}: expected {expected[i].method}(), made {call}")
            elif self._data_known and call.data != expected[i].data:
                problems.append(f"API call {call}: wrong argument, the tables give {expected[i]}")
        problems += [f"{c.method}(): no API call made" for c in expected[len(made) :]]
        return problems

    def _check_calls(self, wanted: list[tuple[int, str]]) -> list[str]:
        """Rule 2 on statectl's runtime: the calls the driver really made (its API log),
        per notification, against the tables: one call of the method's API function, with
        the event's data as its argument where the function is the tables' own name; a
        stray call, one made twice, or a wrong argument is named."""
        served = self._seen.served
        if served is None or self.runtime is None:
            return self._check_notified(wanted)
        problems: list[str] = []
        for s in served:
            if s.method is not None:
                problems += self._check_served(s.method, s.data, s.calls)
                continue
            problems += [
                f"stray API call {c}: the driver made it by itself; the tables make no such call"
                for c in s.calls
                if self._stray(c.function)
            ]
        return problems

    def _function(self, method: str) -> str | None:
        """The API function the tables' ``method`` calls (``statectl_api``, else the driver's
        declared ``methods``, else the method's own name); None: not checked."""
        return self.api.get(method, method) if self.api is not None else method

    def _stray(self, function: str) -> bool:
        """Whether a call the tables did not ask for is an error: always, but that a driver
        with its own API table may call outside it (SimMotor's ``stop()`` before a new
        target); a call there to another method's function of the table is still one."""
        if self._own_api and self.api is not None:
            return function in self.api.values()
        return True

    def _check_served(self, method: str, data: Any, calls: Sequence[ApiMade]) -> list[str]:
        expected = self._function(method)
        if expected is None:
            return []
        if not calls:
            return [f"{method}(): the driver made no API call"]
        hits = [c for c in calls if c.function == expected]
        if not hits:
            made = [str(c) for c in calls]
            return [f"{method}(): expected the API call {expected}(), the driver called {made}"]
        problems = [
            f"stray API call {c} serving {method}(): the tables make one {expected}() call"
            for c in hits[1:]
        ]
        problems += [
            f"stray API call {c} serving {method}(): the tables make no such call here"
            for c in calls
            if c.function != expected and self._stray(c.function)
        ]
        if expected == method:  # the tables' own name: its argument is the event's data
            allowed: list[tuple[Any, ...]] = [()] if data is None else [(), (data,)]
            given = Call(method, data)
            problems += [
                f"API call {c}: wrong argument, the tables give {given}"
                for c in hits
                if c.args not in allowed
            ]
        return problems

    def _check_notified(self, wanted: list[tuple[int, str]]) -> list[str]:
        """A driver that logs no API calls: nothing called unless notified."""
        called = self._called()
        if not wanted and called:
            return [f"the driver was called though nothing was notified: {called}"]
        return []
