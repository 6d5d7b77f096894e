"""The driver base class: a declared table from observer methods to API functions.

Rules:
1. A driver declares ``methods`` (observer method -> name of its own API
   function, e.g. ``{"Movement": "move_to"}``) and ``completions`` (observer
   method -> the event it reports when the work that method started is done).
   The tables are checked when the driver is created.
2. ``update`` looks the method up, asks :meth:`Driver.arguments` for the call's
   arguments from the notification's data, and calls the function; a method the
   table lacks is a :class:`~statectl.errors.StatectlError` naming the ones it has.
3. Each API function records itself with :meth:`Driver.log_call`, so the
   Subject can trace ``ObserverCalled(method, "SimMotor.move_to(10.0)")``.
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

import threading
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, ClassVar

from statectl.devices.protocol import DeviceDriver, Report
from statectl.errors import StatectlError
from statectl.observers import Notification
from statectl.runtime.clock import Clock
from statectl.runtime.monitors import DEFAULT_PERIOD, Monitor, attach_monitors
from statectl.runtime.records import ApiCall
from statectl.runtime.subject import Subject

__all__ = ["Driver", "check_serves", "connect", "requested_target"]


def requested_target(position: float, data: Any) -> float:
    """The absolute target a Movement asks for: ``{"target": x}`` or ``{"amount": dx}``."""
    if isinstance(data, Mapping):
        if "target" in data and isinstance(data["target"], int | float):
            return float(data["target"])
        if "amount" in data and isinstance(data["amount"], int | float):
            return position + float(data["amount"])
    raise StatectlError(
        f"a movement needs event data {{amount: <number>}} or {{target: <number>}} (got {data!r})"
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
        return self._api_log

    def update(self, notification: Notification) -> None:
        function = self.methods.get(notification.method)
        if function is None:
            available = ", ".join(f"{m}()" for m in self.methods) or "none"
            raise StatectlError(
                f"{type(self).__name__} has no observer method {notification.method}() "
                f"(invoke #{notification.invoke} {notification.name}); available: {available}"
            )
        with self._lock:
            self.method = notification.method
            args = self.arguments(notification.method, notification.data)
            getattr(self, function)(*args)

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
        self._api_log.append(ApiCall(clock.now(), type(self).__name__, function, args))

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
) -> tuple[Monitor, ...]:
    """Bind ``driver`` to ``subject``, attach it for ``invokes`` and give it its monitors.

    Raises :class:`StatectlError` before binding anything when the driver lacks an
    observer method those invokes need (rule 6).
    """
    check_serves(subject, driver, invokes)
    driver.bind(subject.post, subject.clock)
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
