"""ModbusIO: an I/O device (a gripper's valves and sensors) on Modbus TCP, named in the run config.

Rules:
1. The run config names the device's points: ``coils`` (outputs: valves) and
   ``inputs`` (discrete inputs: sensors), each name -> address, and its
   ``actions``: observer method -> coils to set, inputs to wait for, and the
   completion event to report::

       actions:
         Grip: {set: {close: true, open: false}, until: {closed: true}, done: Grip completion}

2. One poll thread reads all the discrete inputs in one request every
   ``period`` s (addresses 0..highest), checks the action under way and reports
   its ``done`` event once every ``until`` input has its value.
3. Faults become one detail each for :meth:`poll_fault` (the monitored state's
   fault event) and one log line on ``statectl.run.devices.modbus``: a connection
   refused or reset, an exception response, inputs not read for ``stale_after``
   s. The thread reconnects by itself; nothing raises into the Subject.
4. ``pymodbus`` (the ``modbus`` extra) is imported when the driver binds.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from statectl.front.observers import Notification
from statectl.kernel.errors import StatectlError
from statectl.run.devices.base import Driver, finite_number
from statectl.run.devices.protocol import Report
from statectl.run.runtime.clock import Clock

__all__ = ["LOG", "Action", "ModbusIO", "modbus_option_problems"]

LOG = logging.getLogger("statectl.run.devices.modbus")
#: The most discrete inputs one read may ask for (Modbus allows 2000).
MAX_INPUTS = 2000


@dataclass(frozen=True, slots=True)
class Action:
    """What one observer method does: coils to write, inputs to wait for, the event then."""

    set: tuple[tuple[str, bool], ...]
    until: tuple[tuple[str, bool], ...]
    done: str | None


def _address_problems(kind: str, points: Any) -> list[str]:
    if not isinstance(points, Mapping):
        return [f"{kind} must map names to addresses (got {points!r})"]
    return [
        f"{kind}.{name}: address must be a number 0-{MAX_INPUTS - 1} (got {addr!r})"
        for name, addr in points.items()
        if not (isinstance(addr, int) and not isinstance(addr, bool) and 0 <= addr < MAX_INPUTS)
    ]


def modbus_option_problems(options: Mapping[str, Any]) -> Sequence[str]:
    """Problems with a ``modbus`` driver's options (D511), all at once."""
    problems: list[str] = []
    coils, inputs = options.get("coils", {}), options.get("inputs", {})
    problems += _address_problems("coils", coils)
    problems += _address_problems("inputs", inputs)
    port = options.get("port", 502)
    if not (isinstance(port, int) and not isinstance(port, bool) and 0 < port <= 65535):
        problems.append(f"port must be a number 1-65535 (got {port!r})")
    host = options.get("host", "127.0.0.1")
    if not (isinstance(host, str) and host):
        problems.append(f"host must be a host name or address, e.g. 127.0.0.1 (got {host!r})")
    unit = options.get("unit", 1)
    if not (isinstance(unit, int) and not isinstance(unit, bool) and 0 <= unit <= 255):
        problems.append(f"unit must be a Modbus device id 0-255 (got {unit!r})")
    for key in ("period", "timeout", "stale_after"):
        v = options.get(key, 1.0)
        if not (finite_number(v) and v > 0):
            problems.append(f"{key} must be seconds > 0 (got {v!r})")
    actions = options.get("actions", {})
    if not isinstance(actions, Mapping):
        return [*problems, f"actions must map observer methods to actions (got {actions!r})"]
    for method, spec in actions.items():
        if not isinstance(spec, Mapping):
            problems.append(f"actions.{method} must be a mapping with set/until/done")
            continue
        for key in spec:
            if key not in ("set", "until", "done"):
                problems.append(f"actions.{method}: unknown key {key!r} (has set, until, done)")
        for key, names in (("set", coils), ("until", inputs)):
            points = spec.get(key, {})
            if not isinstance(points, Mapping):
                problems.append(f"actions.{method}.{key} must map point names to true/false")
                continue
            for name, val in points.items():
                if not isinstance(names, Mapping) or name not in names:
                    kind = "coils" if key == "set" else "inputs"
                    problems.append(f"actions.{method}.{key}: {name!r} is not one of the {kind}")
                elif not isinstance(val, bool):
                    problems.append(f"actions.{method}.{key}.{name} must be true or false")
        if "done" in spec and not isinstance(spec["done"], str):
            problems.append(f"actions.{method}.done must be an event name")
    return problems


class ModbusIO(Driver):
    """Coils and discrete inputs on a Modbus TCP server, driven by observer calls (rules 1-4)."""

    realtime: ClassVar[bool] = True  # the bus runs in wall time

    def __init__(
        self,
        *,
        host: str = "127.0.0.1",
        port: int = 502,
        unit: int = 1,
        coils: Mapping[str, int] | None = None,
        inputs: Mapping[str, int] | None = None,
        actions: Mapping[str, Mapping[str, Any]] | None = None,
        period: float = 0.01,
        timeout: float = 0.5,
        stale_after: float = 0.5,
    ) -> None:
        super().__init__()
        options = {"coils": coils or {}, "inputs": inputs or {}, "actions": actions or {}}
        given = {"port": port, "period": period, "timeout": timeout, "stale_after": stale_after}
        problems = modbus_option_problems({**options, **given, "host": host, "unit": unit})
        if problems:
            raise StatectlError("ModbusIO: " + "; ".join(problems))
        self.host, self.port, self.unit = host, port, unit
        self.coils = dict(coils or {})
        self.inputs = dict(inputs or {})
        self.actions = {
            m: Action(
                tuple(spec.get("set", {}).items()),
                tuple(spec.get("until", {}).items()),
                spec.get("done"),
            )
            for m, spec in (actions or {}).items()
        }
        self.period, self.timeout, self.stale_after = period, timeout, stale_after
        self.values: dict[str, bool] = {}
        self.reads = 0  # successful input reads (the bench counts them)
        self._count = max(self.inputs.values(), default=-1) + 1
        self._client: Any = None
        self._io = threading.Lock()  # one request at a time on the connection
        self._waiting: tuple[str, Action] | None = None
        self._faults: list[str] = []
        self._last_read = 0.0
        self._stale_reported = False
        self._down: str | None = None  # the outage being reported, once
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def where(self) -> str:
        return f"Modbus {self.host}:{self.port} unit {self.unit}"

    # -- life -----------------------------------------------------------------------------------

    def bind(self, report: Report, clock: Clock) -> None:
        super().bind(report, clock)
        if self._thread is None:
            try:
                from pymodbus.client import ModbusTcpClient
            except ImportError as exc:
                raise StatectlError(
                    f"the modbus driver needs the modbus extra ({exc}); "
                    "pip install 'statectl[modbus]'"
                ) from None
            self._client = ModbusTcpClient(
                self.host, port=self.port, timeout=self.timeout, retries=0
            )
            self._last_read = time.monotonic()
            self._thread = threading.Thread(target=self._run, name="modbus-poll", daemon=True)
            self._thread.start()

    def close(self) -> None:
        """Stop polling and close the connection (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._client is not None:
            with self._io:
                self._client.close()

    # -- observer calls -------------------------------------------------------------------------

    def serves(self) -> frozenset[str]:
        """The observer methods its ``actions`` map (base rule 6)."""
        return frozenset(self.actions)

    def update(self, notification: Notification) -> None:
        action = self.actions.get(notification.method)
        if action is None:
            available = ", ".join(f"{m}()" for m in self.actions) or "none"
            raise StatectlError(
                f"ModbusIO has no action for {notification.method}() "
                f"(invoke #{notification.invoke} {notification.name}); available: {available}"
            )
        with self._lock:
            self.method = notification.method
            self.log_call("actuate", notification.method)
            self._waiting = (notification.method, action) if action.until or action.done else None
        for name, value in action.set:
            self._request("write_coil", self.coils[name], value=value)
        if not action.until and action.done:
            with self._lock:
                self._waiting = None
            self.report(action.done, None)

    # -- the bus side ---------------------------------------------------------------------------

    def _request(self, function: str, address: int, **kwargs: Any) -> Any:
        """One Modbus request; a failure is a fault detail and ``None`` (rule 3)."""
        from pymodbus.exceptions import ModbusException

        with self._io:
            try:
                if not self._client.connected and not self._client.connect():
                    raise ConnectionError("connection refused or unreachable")
                result = getattr(self._client, function)(address, device_id=self.unit, **kwargs)
            except (ModbusException, OSError) as exc:
                self._client.close()
                self._outage(f"{self.where}: {function}({address}) failed ({exc})")
                return None
        if result.isError():
            self._outage(f"{self.where}: {function}({address}) answered {result}")
            return None
        if self._down is not None:
            LOG.info("%s: answering again", self.where)
            self._down = None
        return result

    def _outage(self, detail: str) -> None:
        with self._lock:
            if self._down is None:
                LOG.warning("%s", detail)
                self._down = detail
                self._faults.append(detail)

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.poll_once()

    def poll_once(self) -> bool:
        """Read every discrete input once; report the action's completion (rule 2)."""
        if self._count == 0:
            return False
        result = self._request("read_discrete_inputs", 0, count=self._count)
        if result is None:
            return False
        bits = list(result.bits)
        done: str | None = None
        with self._lock:
            self.reads += 1
            self._last_read = time.monotonic()
            self._stale_reported = False
            self.values = {name: bool(bits[addr]) for name, addr in self.inputs.items()}
            waiting = self._waiting
            if waiting is not None and all(self.values[n] is v for n, v in waiting[1].until):
                self._waiting = None
                done = waiting[1].done
        if done is not None:
            self.report(done, dict(self.values))
        return True

    def poll_fault(self) -> str | None:
        injected = super().poll_fault()
        if injected is not None:
            return injected
        with self._lock:
            if self._faults:
                return self._faults.pop(0)
            stale = time.monotonic() - self._last_read
            quiet = self._thread is not None and self._down is None  # an outage is reported already
            if quiet and stale > self.stale_after and not self._stale_reported:
                self._stale_reported = True
                detail = f"{self.where}: inputs stale, not read for {stale:.2f} s"
                LOG.warning("%s", detail)
                return detail
        return None
