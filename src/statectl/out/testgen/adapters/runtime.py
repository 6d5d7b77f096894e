"""statectl's own runtime with the test's driver: a Subject on a SimClock, with its monitors.

Rules:
1. The Subject runs the chart; the driver is the test's, the tables' simulated twin by
   default. It is attached through a :class:`Tap` that notes every notification the
   driver gets (observer method and the event's data) and, from the driver's API log,
   the calls the driver really made serving it and those it made by itself in between
   (``Observed.served``: what the harness compares with the tables). Time stands
   still until :meth:`RuntimeImpl.advance`.
2. What an event did is read from the Subject's records since it was sent.
3. :meth:`RuntimeImpl.restart` is a journal and a kill: what the test did so far
   (events, waits, faults) runs again on a fresh driver into a journal (SQLite, a
   temporary file), that run is closed as a crash would end it, and a System resumes
   from the journal with the tables' Recovery rows on another fresh driver; the
   resumed Subject is the device from then on.
4. A driver whose device runs in wall time (``realtime``: a CiA 402 or Modbus bus)
   gets the time too: ``advance`` waits that long on the wall clock, then moves the
   simulated one (its reports, queued meanwhile, are taken then).
5. Such a driver reports from its own thread whenever its device is done, so its
   reports are kept (:class:`WallReports`) until the test lets time run: between
   ``advance`` calls time stands still for it as for the twin, and a completion the
   bus saw while the test sent its next events cannot slip in before them. A
   completion the test sent itself in place of the device (a test's path) answers
   the device's call (:class:`~statectl.kernel.semantics.calls.DeviceCalls`); the
   device's own report of that call, made before or after, is then dropped and noted
   (``WallReports.stood_in``): the test's event was that report, and a second one
   would show up in the next probe as an event the device took by itself. Any other
   report is taken as the device made it, for the checks to judge.
"""

from __future__ import annotations

import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from statectl.front.observers import Notification, Observer
from statectl.front.tables import RecoveryRow
from statectl.kernel.model import Chart, EventKind, StateKind
from statectl.kernel.semantics.calls import CallKey, DeviceCalls
from statectl.out.testgen.adapters import ApiMade, Call, Observed, Served, Unsupported
from statectl.run.devices import SimTwin, connect
from statectl.run.devices.base import Driver
from statectl.run.journal import Journal
from statectl.run.runtime import (
    EventIgnored,
    EventReceived,
    EventRejected,
    InvokeIssued,
    ObserverCalled,
    Record,
    SimClock,
    Subject,
)
from statectl.run.runtime.hooks import ApiLogging, api_calls_since, api_count
from statectl.run.runtime.monitors import Monitor
from statectl.run.system import DeviceSetup, System

__all__ = ["Recorder", "RuntimeImpl", "Tap", "WallReports"]


class Recorder:
    """Keeps every record the Subject emits, and marks where the last event began."""

    def __init__(self) -> None:
        self.records: list[Record] = []
        self.mark = 0

    def __call__(self, record: Record) -> None:
        self.records.append(record)

    def since_mark(self) -> list[Record]:
        return self.records[self.mark :]


class Tap:
    """Stands between the Subject and the driver and notes each notification and the API
    calls the driver made for it (rule 1)."""

    def __init__(self, driver: Observer) -> None:
        self.driver = driver
        self.calls: list[Call] = []
        self.logs = isinstance(driver, ApiLogging)  # else: no API log to read
        self.served: list[Served] = []
        self._count = api_count(driver) if self.logs else 0
        #: told (method, event) of each notification before the driver gets it (rule 5)
        self.heard: Callable[[str, str], None] | None = None

    def update(self, notification: Notification) -> None:
        self.calls.append(Call(notification.method, notification.data))
        if self.heard is not None:
            self.heard(notification.method, notification.event)
        self.catch_up()
        self.driver.update(notification)
        if self.logs:
            self.served.append(Served(notification.method, notification.data, self._new()))

    def catch_up(self) -> None:
        """Note the calls the driver made by itself since the last look (a timer's, a thread's)."""
        if self.logs and api_count(self.driver) != self._count:
            self.served.append(Served(None, None, self._new()))

    def clear(self) -> None:
        self.catch_up()
        self.calls.clear()
        self.served.clear()

    def _new(self) -> tuple[ApiMade, ...]:
        made = api_calls_since(self.driver, self._count)
        self._count = api_count(self.driver)
        return tuple(ApiMade(c.device, c.function, tuple(c.args)) for c in made)

    def __getattr__(self, name: str) -> Any:  # bind, poll_fault, serves, api_log, ...
        return getattr(self.driver, name)


class WallReports:
    """Rule 5: the reports of a driver in wall time, kept until the test lets time run.

    ``report`` is the driver's (any thread); everything else runs on the test's
    thread. ``pending`` are the calls the device owes a report of, by the one model
    of calls and completions; ``answered`` counts, per completion, the calls the
    test answered itself whose report has not come yet. A count stays until that
    report comes, even when a later command made the device give the call up (a
    report already on its way may still come): a device that never sends it leaves
    one, which drops one later report of that completion that no call is pending for.
    """

    def __init__(self, chart: Chart, dropped: list[str]) -> None:
        self.calls = DeviceCalls(chart)
        self.completions = frozenset(e.name for e in chart.events if e.kind is EventKind.COMPLETION)
        self.pending: tuple[CallKey, ...] = ()
        self.answered: dict[str, int] = {}
        #: reports dropped because the test had sent them in the device's place
        self.stood_in: list[str] = []
        self._dropped = dropped  # where a silenced device's reports go (stall)
        self._held: list[tuple[str, Any]] = []
        self._lock = threading.Lock()
        self._silent = False

    def report(self, event: str, data: Any = None) -> None:
        """The driver's report: kept, or dropped once the device was silenced."""
        with self._lock:
            if self._silent:
                self._dropped.append(event)
            else:
                self._held.append((event, data))

    def called(self, method: str, event: str) -> None:
        """A notification: a call the device now owes (superseding those it leaves)."""
        self.pending = self.calls.after_calls(self.pending, [(method, event)])

    def _settle(self, completion: str) -> bool:
        ways = self.calls.settled_by(self.pending, completion)
        if ways:
            self.pending = ways[0]
        return bool(ways)

    def sent(self, event: str) -> None:
        """The test sends ``event`` itself; a completion stands in for the device's report."""
        if event not in self.completions:
            return
        settled = self._settle(event)
        with self._lock:
            kept = next((i for i, (e, _) in enumerate(self._held) if e == event), None)
            if kept is not None:
                del self._held[kept]
                self.stood_in.append(event)
                return
        if settled:
            self.answered[event] = self.answered.get(event, 0) + 1

    def release(self) -> list[tuple[str, Any]]:
        """The reports kept so far, in order, but those the test stood in for."""
        with self._lock:
            held, self._held = self._held, []
        out = []
        for event, data in held:
            settled = event not in self.completions or self._settle(event)
            if not settled and self.answered.get(event, 0) > 0:
                self.answered[event] -= 1
                self.stood_in.append(event)
                continue
            out.append((event, data))
        return out

    def silence(self) -> None:
        """stall(): what was kept and whatever comes later is dropped."""
        with self._lock:
            self._silent = True
            self._dropped.extend(e for e, _ in self._held)
            self._held.clear()


def _silent(event: str, data: Any = None) -> None:
    """Where a stalled driver's reports go in a replay: nowhere."""


def _is_device_driver(driver: object) -> bool:
    return hasattr(driver, "bind") and hasattr(driver, "poll_fault")


class RuntimeImpl:
    """The :class:`~statectl.out.testgen.adapters.Implementation` of statectl's runtime."""

    def __init__(
        self,
        chart: Chart,
        driver: Observer | None = None,
        *,
        data: Mapping[str, Any] | None = None,
        new_driver: Callable[[Chart], Any] | None = None,
        recovery: tuple[RecoveryRow, ...] = (),
    ) -> None:
        self.chart = chart
        self.data = dict(data) if data is not None else None
        self.new_driver = new_driver
        self.recovery = recovery
        self.clock = SimClock()
        self.driver: Observer = driver if driver is not None else SimTwin(chart)
        self.recorder = Recorder()
        self.tap = Tap(self.driver)
        self.subject = Subject(chart, clock=self.clock, data=data)
        self.subject.listen(self.recorder)
        self.monitors: tuple[Monitor, ...] = ()
        self.dropped: list[str] = []  # what the driver reported after stall()
        self.wall: WallReports | None = None  # rule 5
        if _is_device_driver(self.driver):
            if getattr(self.driver, "realtime", False):
                self.wall = WallReports(chart, self.dropped)
                self.tap.heard = self.wall.called
            report = self.wall.report if self.wall is not None else None
            self.monitors = connect(self.subject, self.tap, report=report)
        else:
            self.subject.attach(self.tap)  # a plain observer: no monitors to poll it
        self.history: list[tuple[str, Any]] = []  # what the test did, for restart()
        self._system: System | None = None
        self._tmp: tempfile.TemporaryDirectory[str] | None = None

    def start(self) -> None:
        self.subject.start()

    # -- the protocol --------------------------------------------------------------------------

    def states(self) -> tuple[str, ...]:
        m = self.subject.machine
        return tuple(
            s
            for s in sorted(self.subject.configuration, key=m.order.__getitem__)
            if m.kind[s] in (StateKind.ATOMIC, StateKind.FINAL)
        )

    def send(self, event: str, data: Any = None) -> Observed:
        self._mark()
        self.history.append(("send", (event, data)))
        if self.wall is not None:
            self.wall.sent(event)
        self.subject.dispatch(event, data)
        return self.observed(sent=event)

    def advance(self, seconds: float) -> Observed:
        self._mark()
        self.history.append(("advance", seconds))
        if getattr(self.driver, "realtime", False):
            time.sleep(seconds)  # rule 4: a bus in wall time needs the time to pass
        if self.wall is not None:
            for event, data in self.wall.release():
                self.subject.post(event, data)
        if self._system is not None:
            self._system.advance(seconds)
        else:
            self.subject.advance(seconds)
        return self.observed()

    def inject_fault(self, detail: str) -> None:
        inject = getattr(self.driver, "inject_fault", None)
        if not callable(inject):
            raise Unsupported(f"{type(self.driver).__name__} has no inject_fault()")
        self.history.append(("fault", detail))
        inject(detail)

    def monitoring(self) -> dict[str, int]:
        return {m.spec.state: m.polls for m in self.monitors if m.active}

    def stall(self) -> None:
        """From now on the driver's own reports (its completions) are dropped."""
        self.history.append(("stall", None))
        if self.wall is not None:
            self.wall.silence()
        elif isinstance(self.driver, Driver) and self.driver._clock is not None:
            Driver.bind(self.driver, self._drop, self.driver._clock)

    def restart(self) -> Observed:
        """Rule 3: replay into a journal, kill, resume from it with the Recovery rows."""
        self._tmp = self._tmp or tempfile.TemporaryDirectory(prefix="statectl-testgen-")
        db = Path(self._tmp.name) / f"run{len(self.history)}.db"
        first = self._system_on(db)
        first.start()
        for what, arg in self.history:
            self._replay(first, what, arg)
        first.close()  # the crash: whatever the device was doing is lost
        second = self._system_on(db)
        self._adopt(second)
        self._mark()
        second.start(resume=True)
        second.drain()
        return self.observed()

    def close(self) -> None:
        if self._system is not None:
            self._system.close()
        if self._tmp is not None:
            self._tmp.cleanup()

    # -- helpers -------------------------------------------------------------------------------

    def _drop(self, event: str, data: Any = None) -> None:
        self.dropped.append(event)

    def _mark(self) -> None:
        self.recorder.mark = len(self.recorder.records)
        self.tap.clear()

    def _fresh(self) -> Observer:
        """A new driver like the test's: ``new_driver``'s, else the twin or the driver's
        class made again with no arguments (a SimMotor)."""
        made = self.new_driver(self.chart) if self.new_driver is not None else None
        if made is not None:
            return made  # type: ignore[no-any-return]
        if isinstance(self.driver, SimTwin):
            return type(self.driver)(self.chart)
        try:
            again: Observer = type(self.driver)()
        except TypeError:
            raise Unsupported(
                f"restarting needs a new {type(self.driver).__name__}: override "
                "statectl_new_driver to make one"
            ) from None
        return again

    def _system_on(self, db: Path) -> System:
        driver = Tap(self._fresh())
        setup = DeviceSetup(self.chart.name, self.chart, self.recovery, "", driver)
        return System((setup,), SimClock(), Journal(db))

    def _replay(self, system: System, what: str, arg: Any) -> None:
        driver = system.setups[0].driver
        if what == "send":
            system.post(None, arg[0], arg[1])
            system.drain()
        elif what == "advance":
            system.advance(arg)
        elif what == "fault" and driver is not None:
            getattr(driver, "inject_fault", lambda d: None)(arg)
        elif what == "stall" and isinstance(driver, Tap) and isinstance(driver.driver, Driver):
            inner = driver.driver
            if inner._clock is not None:
                Driver.bind(inner, _silent, inner._clock)

    def _adopt(self, system: System) -> None:
        """The resumed System's Subject is the device from now on."""
        self._system = system
        tap = system.setups[0].driver
        assert isinstance(tap, Tap)
        self.tap, self.driver = tap, tap.driver
        self.subject = system.subjects[self.chart.name]
        self.clock = system.clock  # type: ignore[assignment]  # a SimClock (_system_on)
        self.subject.listen(self.recorder)
        self.monitors = ()
        self.history = []
        self.wall = None  # the resumed driver reports to the System's door

    def observed(self, sent: str | None = None) -> Observed:
        """What the records since the mark show (rule 2)."""
        since = self.recorder.since_mark()
        self.tap.catch_up()
        unhandled_all = tuple(
            (r.event, r.reason.value) for r in since if isinstance(r, EventIgnored | EventRejected)
        )
        skip_sent = sent is not None
        events = []
        for r in since:
            if isinstance(r, EventReceived):
                if skip_sent and r.event == sent:
                    skip_sent = False
                    continue
                events.append(r.event)
        return Observed(
            unhandled=unhandled_all[0][1] if unhandled_all else None,
            invokes=tuple((r.invoke, r.method) for r in since if isinstance(r, InvokeIssued)),
            calls=tuple(self.tap.calls),
            events=tuple(events),
            unhandled_all=unhandled_all,
            driver_calls=tuple((r.method, r.api) for r in since if isinstance(r, ObserverCalled)),
            served=tuple(self.tap.served) if self.tap.logs else None,
        )
