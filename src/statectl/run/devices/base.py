"""The driver base class: a declared table from observer methods to API functions.

Rules:
1. A driver declares ``methods`` (observer method -> name of its own API
   function, e.g. ``{"Movement": "move_to"}``) and ``completions`` (observer
   method -> the event it reports when the work that method started is done).
   The tables are checked when the driver is created.
2. ``update`` looks the method up, asks :meth:`Driver.arguments` for the call's
   arguments from the notification's data, and calls the function; a method the
   table lacks is a :class:`~statectl.kernel.errors.StatectlError` naming the ones it has.
3. Each API function records itself with :meth:`Driver.log_call`, so the
   Subject can trace ``ObserverCalled(method, "SimMotor.move_to(10.0)")``. The
   log keeps the last :data:`API_LOG_KEEP` calls; ``api_calls`` counts them all.
4. Fault injection is shared: :meth:`Driver.inject_fault` arms a detail that
   :meth:`Driver.poll_fault` returns once, from ``after`` seconds on.
5. Timer callbacks and ``update`` may run on different threads (WallClock), so
   both hold the driver's lock while they touch its state.
6. :func:`connect` checks the driver against the chart before anything runs:
   every observer method of the invokes it is attached for must be one the
   driver :meth:`~Driver.serves`, else a :class:`StatectlError` names the
   missing and the available methods. Otherwise the first such transition would
   be committed and only then fail, leaving the device in the new state.
   A driver without ``serves()`` (a bare protocol implementation) is trusted.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, ClassVar

from statectl.front.observers import Notification
from statectl.kernel.errors import StatectlError
from statectl.run.devices.protocol import DeviceDriver, Report
from statectl.run.runtime.clock import Clock
from statectl.run.runtime.monitors import DEFAULT_PERIOD, Monitor, attach_monitors
from statectl.run.runtime.records import ApiCall
from statectl.run.runtime.subject import Subject

__all__ = [
    "API_LOG_KEEP",
    "Driver",
    "check_serves",
    "connect",
    "finite_number",
    "requested_target",
]

#: The API calls a driver keeps in ``api_log``, the most recent; ``api_calls`` counts them
#: all. A device that runs for days makes millions of calls: an unbounded log was memory
#: that only grew, and the appends slowed down as it did.
API_LOG_KEEP = 1000


def _number(value: Any) -> bool:
    """An int or a float, not a bool (which Python counts as 1)."""
    kind = type(value)
    return kind is int or kind is float or (isinstance(value, int | float) and kind is not bool)


def finite_number(value: Any) -> bool:
    """A finite int or float: what a driver option or a setpoint must be. A bool is none
    (YAML's ``yes`` would count as 1), nor are ``.nan`` and ``.inf``."""
    return _number(value) and math.isfinite(value)


def requested_target(position: float, data: Any) -> float:
    """The absolute target a Movement asks for: ``{"target": x}`` or ``{"amount": dx}``.

    Refused unless a finite number: a ``.nan`` or ``.inf`` amount (or ``true``, which
    Python counts as 1) would fail deep in a driver (a NaN timer delay, ``round(nan)``,
    an encoder count of infinity) instead of as one clear error before any API call.
    """
    if type(data) is dict or isinstance(data, Mapping):  # the common case first
        target = None
        if "target" in data and _number(data["target"]):
            target = float(data["target"])
        elif "amount" in data and _number(data["amount"]):
            target = position + float(data["amount"])
        if target is not None and target - target == 0.0:  # finite: inf - inf and nan are nan
            return target
    raise StatectlError(
        "a movement needs a finite number: event data {amount: <number>} or "
        f"{{target: <number>}} (got {data!r})"
    )


class Driver:
    """Base of the drivers statectl ships; subclasses declare ``methods`` and ``completions``."""

    methods: ClassVar[Mapping[str, str]] = {}
    completions: ClassVar[Mapping[str, str]] = {}

    def __init__(self) -> None:
        missing = sorted({f for f in self.methods.values() if not callable(getattr(self, f, None))})
        if missing:
            raise StatectlError(
                f"{type(self).__name__}.methods names API functions it does not have: {missing}"
            )
        unknown = sorted(set(self.completions) - set(self.methods))
        if unknown:
            raise StatectlError(
                f"{type(self).__name__}.completions names methods not in .methods: {unknown}"
            )
        self._api_log: list[ApiCall] = []
        self._api_new: list[tuple[float, str, tuple[Any, ...]]] = []  # logged, not yet ApiCalls
        self._api_dropped = 0  # calls dropped from the front of the log (rule 3)
        self._owner = type(self).__name__  # the API's owner in every ApiCall
        # observer method -> the function update() calls, under the lock it holds
        self._api = {m: self._locked_form(f) for m, f in self.methods.items()}
        self._report: Report | None = None
        self._clock: Clock | None = None
        self._fault: tuple[str, float] | None = None
        self._lock = threading.RLock()
        self.method: str | None = None  # the observer method served last

    # -- protocol ----------------------------------------------------------------------------

    def bind(self, report: Report, clock: Clock) -> None:
        self._report = report
        self._clock = clock

    @property
    def clock(self) -> Clock:
        if self._clock is None:
            raise StatectlError(f"{type(self).__name__} is not bound; call bind() or connect()")
        return self._clock

    @property
    def api_log(self) -> Sequence[ApiCall]:
        """The last :data:`API_LOG_KEEP` (or more) API calls, oldest first."""
        if self._api_new:
            self._settle_log()
        return self._api_log

    @property
    def api_calls(self) -> int:
        """Every API call made so far, also those no longer in :attr:`api_log`."""
        return self._api_dropped + len(self._api_log) + len(self._api_new)

    def api_since(self, before: int) -> tuple[ApiCall, ...]:
        """The calls made since :attr:`api_calls` was ``before``, as values.

        What a step listener's Subject asks after every notification: read from the
        calls logged since the last read, without settling the log (which then stays
        cheap for whoever reads it next), and under the lock a notification takes.
        """
        with self._lock:
            new = self._api_new
            n = self._api_dropped + len(self._api_log) + len(new) - before
            if n <= 0:
                return ()
            if n <= len(new):
                owner = self._owner
                return tuple([ApiCall(t, owner, f, a) for t, f, a in new[len(new) - n :]])
        return tuple(self.api_log[-n:])  # some were settled meanwhile: the log has them

    def _settle_log(self) -> None:
        """Turn the calls logged since the last read into :class:`ApiCall` values (rule 3).

        A call is logged as a plain tuple and becomes an ``ApiCall`` only when the log
        is read (a trace reads it per notification; nobody else may ever read it), and
        the log is cut back to the last :data:`API_LOG_KEEP`.
        """
        with self._lock:
            owner, new = self._owner, self._api_new
            log = self._api_log
            log.extend([ApiCall(t, owner, f, a) for t, f, a in new])
            new.clear()
            if len(log) >= 2 * API_LOG_KEEP:
                self._api_dropped += len(log) - API_LOG_KEEP
                del log[:-API_LOG_KEEP]

    def update(self, notification: Notification) -> None:
        method = notification.method
        function = self._api.get(method)
        if function is None:
            available = ", ".join(f"{m}()" for m in self.methods) or "none"
            raise StatectlError(
                f"{type(self).__name__} has no observer method {method}() "
                f"(invoke #{notification.invoke} {notification.name}); available: {available}"
            )
        with self._lock:
            self.method = method
            function(*self.arguments(method, notification.data))

    def _locked_form(self, function: str) -> Callable[..., object]:
        """The callable :meth:`update` uses for API ``function``, called with the lock held.

        By default the public function itself (which takes the lock again); a driver
        whose public functions only take the lock around a private body returns
        that body, so a notification takes the lock once.
        """
        found: Callable[..., object] = getattr(self, function)
        return found

    def serves(self) -> frozenset[str]:
        """The observer methods :meth:`update` handles (rule 6): the keys of ``methods``."""
        return frozenset(self.methods)

    def arguments(self, method: str, data: Any) -> tuple[Any, ...]:
        """The API call's arguments for ``method`` given the event data; none by default."""
        return ()

    def poll_fault(self) -> str | None:
        with self._lock:
            if self._fault is None:
                return None
            detail, due = self._fault
            if self.clock.now() < due:
                return None
            self._fault = None
            return detail

    # -- helpers for subclasses --------------------------------------------------------------

    def inject_fault(self, detail: str, after: float | None = None) -> None:
        """Make :meth:`poll_fault` return ``detail`` once, ``after`` seconds from now."""
        with self._lock:
            self._fault = (detail, self.clock.now() + (after or 0.0))

    def log_call(self, function: str, *args: Any) -> None:
        clock = self._clock
        if clock is None:
            raise StatectlError(f"{type(self).__name__} is not bound; call bind() or connect()")
        self._log(clock.now(), function, args)

    def _log(self, now: float, function: str, args: tuple[Any, ...]) -> None:
        """:meth:`log_call` for a driver that read the clock already (one read per call)."""
        new = self._api_new
        new.append((now, function, args))
        if len(new) >= 2 * API_LOG_KEEP:  # nobody reads the log: drop, never build, the old
            self._api_dropped += len(self._api_log) + len(new) - API_LOG_KEEP
            self._api_log.clear()
            del new[:-API_LOG_KEEP]

    def report(self, event: str, data: Any = None) -> None:
        if self._report is None:
            raise StatectlError(f"{type(self).__name__} is not bound; call bind() or connect()")
        self._report(event, data)

    def complete(self, method: str, data: Any = None) -> None:
        """Report that the work ``method`` started is done (``completions[method]``)."""
        event = self.completions.get(method)
        if event is not None:
            self.report(event, data)


def connect(
    subject: Subject,
    driver: DeviceDriver,
    *,
    invokes: Iterable[int] | None = None,
    period: float = DEFAULT_PERIOD,
    report: Report | None = None,
) -> tuple[Monitor, ...]:
    """Bind ``driver`` to ``subject``, attach it for ``invokes`` and give it its monitors.

    The driver reports its completions to ``report`` (a System's door), else to the
    Subject's queue. Raises :class:`StatectlError` before binding anything when the
    driver lacks an observer method those invokes need (rule 6).
    """
    check_serves(subject, driver, invokes)
    driver.bind(subject.post if report is None else report, subject.clock)
    subject.attach(driver, invokes)
    return attach_monitors(subject, driver, period=period)


def check_serves(subject: Subject, driver: object, invokes: Iterable[int] | None = None) -> None:
    """Rule 6: the driver serves every observer method of ``invokes`` (default: all of them)."""
    serves = getattr(driver, "serves", None)
    if not callable(serves):
        return
    served = frozenset(serves())
    wanted = None if invokes is None else frozenset(invokes)
    needed = {i.method for i in subject.chart.invokes if wanted is None or i.number in wanted}
    missing = sorted(needed - served)
    if missing:
        available = ", ".join(f"{m}()" for m in sorted(served)) or "none"
        raise StatectlError(
            f"{type(driver).__name__} cannot drive {subject.name}: its chart calls observer "
            f"method(s) {', '.join(f'{m}()' for m in missing)} that the driver does not serve; "
            f"available: {available}"
        )
