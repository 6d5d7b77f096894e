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
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from statectl.front.observers import Notification, Observer
from statectl.front.tables import RecoveryRow
from statectl.kernel.model import Chart, StateKind
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

__all__ = ["Recorder", "RuntimeImpl", "Tap"]


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

    def update(self, notification: Notification) -> None:
        self.calls.append(Call(notification.method, notification.data))
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
        if _is_device_driver(self.driver):
            self.monitors = connect(self.subject, self.tap)
        else:
            self.subject.attach(self.tap)  # a plain observer: no monitors to poll it
        self.dropped: list[str] = []  # what the driver reported after stall()
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
        self.subject.dispatch(event, data)
        return self.observed(sent=event)

    def advance(self, seconds: float) -> Observed:
        self._mark()
        self.history.append(("advance", seconds))
        if getattr(self.driver, "realtime", False):
            time.sleep(seconds)  # rule 4: a bus in wall time needs the time to pass
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
        if isinstance(self.driver, Driver) and self.driver._clock is not None:
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
