"""ModbusIO: an I/O device (valves, sensors, analog values) on Modbus TCP or RTU.

Rules:
1. The run config names the device's points and ``actions`` (options.py): which
   coils and holding registers an observer method writes, which inputs and
   registers it waits for, and the event it reports then.
2. One bus thread owns the link. It performs the writes an observer call queued
   (``update`` never waits for the bus), then reads every discrete input and
   every register table in one request each, every ``period`` s, and reports the
   action's ``done`` event once its writes succeeded and every ``until`` holds,
   with the points of its ``data`` (every input and register by default).
3. A write that fails is tried again, ``retries`` times ``retry_delay`` s apart.
   If it still fails the action is dropped (its completion can never come from
   the inputs alone) and the state's fault event is raised with ``{detail}``:
   the action's ``fault``, else the fault event the chart declares for the state
   the method's command enters. With none, the write is logged at ERROR and the
   device counts as left part-way (:meth:`ModbusIO.unfinished`).
4. Outages: the first failure of an outage is one WARNING on
   ``statectl.run.devices.modbus`` and one detail for :meth:`poll_fault`; the
   recovery is one WARNING. pymodbus's own log lines are let through once per
   outage (:data:`QUIET`, a filter on its logger). Nothing raises into the Subject.
5. ``pymodbus`` (the ``modbus`` extra; ``pyserial`` for RTU) is imported when the
   driver binds.
6. Each observer call is logged as the API call of its method's own name
   (``ModbusIO.Clamp()``): the action is the device's API here, so a trace reads as
   the tables do and a generated test suite checks the calls with no ``statectl_api``.
"""

from __future__ import annotations

import importlib.util
import logging
import threading
import time
from collections import deque
from collections.abc import Mapping
from typing import Any, ClassVar

from statectl.front.observers import Notification
from statectl.kernel.errors import MissingExtra, StatectlError
from statectl.kernel.model import Chart, EventKind
from statectl.run.devices.base import Driver
from statectl.run.devices.modbus.options import (
    Action,
    Register,
    modbus_option_problems,
    parse_actions,
    parse_registers,
)
from statectl.run.devices.modbus.registers import decode_register, encode_register
from statectl.run.devices.protocol import Report
from statectl.run.runtime.clock import Clock

__all__ = ["LOG", "QUIET", "ModbusIO", "OutageFilter", "fault_event_for"]

LOG = logging.getLogger("statectl.run.devices.modbus")
#: The logger pymodbus writes its own lines to.
PYMODBUS_LOGGER = "pymodbus.logging"


class OutageFilter(logging.Filter):
    """Rule 4: pymodbus's lines from a driver's bus thread pass once per outage.

    pymodbus logs a failed connect on every retry (~100 lines a second at a 10 ms
    period). The bus thread names itself with :meth:`speaking`; a line logged on
    that thread passes only if its driver has said nothing since its last success.
    """

    def __init__(self) -> None:
        super().__init__()
        self._local = threading.local()
        self._said: set[int] = set()
        self.dropped = 0

    def speaking(self, key: int | None) -> None:
        self._local.key = key

    def up(self, key: int) -> None:
        self._said.discard(key)

    def filter(self, record: logging.LogRecord) -> bool:
        key = getattr(self._local, "key", None)
        if key is None or record.levelno < logging.WARNING:
            return True
        if key in self._said:
            self.dropped += 1
            return False
        self._said.add(key)
        return True


QUIET = OutageFilter()


def fault_event_for(chart: Chart | None, method: str) -> str | None:
    """The fault event declared for the state ``method``'s command enters, or for a
    superstate of it (rule 3); None when there is none."""
    if chart is None:
        return None
    entered: list[str] = []
    for t in chart.transitions:
        for name in t.events:
            event = chart.event(name)
            if event is not None and event.api == method and event.kind is EventKind.COMMAND:
                entered += [s for s in t.targets if s not in entered]
    for state in entered:
        at: str | None = state
        while at is not None:  # the state, then its superstates (a fault row on one)
            for t in chart.transitions_from(at):
                for name in t.events:
                    event = chart.event(name)
                    if event is not None and event.kind is EventKind.FAULT:
                        return name
            at = chart.state(at).parent
    return None


class ModbusIO(Driver):
    """Coils, discrete inputs and registers on a Modbus server, driven by observer calls."""

    realtime: ClassVar[bool] = True  # the bus runs in wall time

    def __init__(
        self,
        *,
        transport: str = "tcp",
        host: str = "127.0.0.1",
        port: int = 502,
        serial: str | None = None,
        baudrate: int = 19200,
        parity: str = "N",
        stopbits: int = 1,
        bytesize: int = 8,
        unit: int = 1,
        coils: Mapping[str, int] | None = None,
        inputs: Mapping[str, int] | None = None,
        registers: Mapping[str, Mapping[str, Any]] | None = None,
        actions: Mapping[str, Mapping[str, Any]] | None = None,
        period: float = 0.01,
        timeout: float = 0.5,
        stale_after: float = 0.5,
        retries: int = 3,
        retry_delay: float = 0.05,
        chart: Chart | None = None,
    ) -> None:
        super().__init__()
        given = {k: v for k, v in locals().items() if k not in ("self", "chart", "__class__")}
        given = {k: ({} if v is None and k != "serial" else v) for k, v in given.items()}
        problems = modbus_option_problems(given)
        if problems:
            raise StatectlError("ModbusIO: " + "; ".join(problems))
        self.transport, self.host, self.port, self.unit = transport, host, port, unit
        self.serial: dict[str, Any] = {"port": serial, "baudrate": baudrate, "parity": parity}
        self.serial |= {"stopbits": stopbits, "bytesize": bytesize}
        self.coils = dict(coils or {})
        self.inputs = dict(inputs or {})
        self.registers: dict[str, Register] = parse_registers(registers or {})
        self.actions: dict[str, Action] = parse_actions(actions or {})
        self.faults = {m: a.fault or fault_event_for(chart, m) for m, a in self.actions.items()}
        self.period, self.timeout, self.stale_after = period, timeout, stale_after
        self.retries, self.retry_delay = retries, retry_delay
        self.values: dict[str, Any] = {}
        self.reads = 0  # successful read rounds (the bench counts them)
        self.failed_writes: list[str] = []  # rule 3: every write given up, said
        self.outages = 0  # outages seen (rule 4)
        self._count = max(self.inputs.values(), default=-1) + 1
        self._spans = self._register_spans()
        self._client: Any = None
        self._io = threading.Lock()  # one request at a time on the connection
        self._queue: deque[tuple[str, Action]] = deque()  # actions whose writes are due
        self._wake = threading.Event()
        self._waiting: tuple[str, Action] | None = None
        self._hit: set[str] = set()  # methods under way that an outage hit
        self._faults: list[str] = []
        self._last_read = 0.0
        self._stale_reported = False
        self._down: str | None = None  # the outage being reported, once
        self._down_since = 0.0
        self._raised = False  # this outage was raised as a fault event already
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _register_spans(self) -> dict[str, tuple[int, int]]:
        """Per register table, the one read that covers it: (first address, count)."""
        spans = {}
        for table in ("input", "holding"):
            regs = [r for r in self.registers.values() if r.table == table]
            if regs:
                low = min(r.address for r in regs)
                spans[table] = (low, max(r.address + r.width for r in regs) - low)
        return spans

    @property
    def where(self) -> str:
        if self.transport == "rtu":
            return f"Modbus RTU {self.serial['port']} unit {self.unit}"
        return f"Modbus {self.host}:{self.port} unit {self.unit}"

    # -- life -----------------------------------------------------------------------------------

    def bind(self, report: Report, clock: Clock) -> None:
        super().bind(report, clock)
        if self._thread is None:
            self._client = self._make_client()
            pymodbus_log = logging.getLogger(PYMODBUS_LOGGER)
            if QUIET not in pymodbus_log.filters:
                pymodbus_log.addFilter(QUIET)
            self._last_read = time.monotonic()
            self._thread = threading.Thread(target=self._run, name="modbus-bus", daemon=True)
            self._thread.start()

    def _make_client(self) -> Any:
        try:
            if self.transport == "rtu":
                if importlib.util.find_spec("serial") is None:  # pymodbus opens ports with it
                    raise ImportError("No module named 'serial' (pyserial)")
                from pymodbus import FramerType
                from pymodbus.client import ModbusSerialClient

                s = self.serial
                return ModbusSerialClient(
                    s["port"], framer=FramerType.RTU, baudrate=s["baudrate"],
                    parity=s["parity"], stopbits=s["stopbits"], bytesize=s["bytesize"],
                    timeout=self.timeout, retries=0,
                )  # fmt: skip
            from pymodbus.client import ModbusTcpClient
        except ImportError as exc:
            missing = exc.name or ("pyserial" if self.transport == "rtu" else "pymodbus")
            raise MissingExtra("the modbus driver", missing, "modbus") from None
        return ModbusTcpClient(self.host, port=self.port, timeout=self.timeout, retries=0)

    def close(self) -> None:
        """Stop the bus thread and close the connection (idempotent)."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._client is not None:
            with self._io:
                self._client.close()

    # -- observer calls -------------------------------------------------------------------------

    def serves(self) -> frozenset[str]:
        """The observer methods its ``actions`` map (base rule 6)."""
        return frozenset(self.actions)

    def update(self, notification: Notification) -> None:
        """Rule 2: queue the action's writes for the bus thread; never wait for the bus."""
        action = self.actions.get(notification.method)
        if action is None:
            available = ", ".join(f"{m}()" for m in self.actions) or "none"
            raise StatectlError(
                f"ModbusIO has no action for {notification.method}() "
                f"(invoke #{notification.invoke} {notification.name}); available: {available}"
            )
        with self._lock:
            self.method = notification.method
            self.log_call(notification.method)  # the API call the tables name (rule 6)
            self._waiting = None  # a new command replaces the one under way
            self._hit.clear()
            self._queue.append((notification.method, action))
        if self._thread is None:  # not bound to a bus: the work happens when it is
            return
        self._wake.set()

    def unfinished(self) -> str | None:
        """What an outage left undone (rule 3): writes given up, an action it interrupted."""
        with self._lock:
            parts = list(self.failed_writes)
            under_way = [m for m, _ in self._queue]
            if self._waiting is not None:
                under_way.append(self._waiting[0])
            parts += [
                f"{m}() did not complete: the link went down while it was under way"
                for m in under_way
                if m in self._hit or self._down is not None
            ]
        return "; ".join(parts) or None

    # -- the bus thread -------------------------------------------------------------------------

    def _run(self) -> None:
        QUIET.speaking(id(self))
        while not self._stop.is_set():
            while self._queue and not self._stop.is_set():
                self._perform(*self._queue[0])
            self.poll_once()
            self._wake.wait(self.period)
            self._wake.clear()

    def _perform(self, method: str, action: Action) -> None:
        """Rule 3: write the action's points, each tried ``1 + retries`` times."""
        for name, value in action.set:
            failure = None
            for attempt in range(self.retries + 1):
                if attempt:
                    self._stop.wait(self.retry_delay)
                failure = self._write(name, value)
                if failure is None or self._stop.is_set():
                    break
            if self._stop.is_set():
                return  # closing: the run is over, nothing is raised into it
            if failure is not None:
                failure = failure.removeprefix(f"{self.where}: ")
                self._give_up(method, f"{failure}; tried {self.retries + 1} times")
                return
        with self._lock:
            if self._queue and self._queue[0][0] == method:
                self._queue.popleft()
                if action.until or action.done:
                    self._waiting = (method, action)

    def _write(self, name: str, value: bool | float) -> str | None:
        """One write of a coil (function 5) or holding register(s) (16); the failure or None."""
        if name in self.coils:
            return self._request("write_coil", self.coils[name], value=value)[1]
        reg = self.registers[name]
        try:
            words = encode_register(reg, float(value))
        except StatectlError as exc:
            return str(exc)
        return self._request("write_registers", reg.address, values=words)[1]

    def _give_up(self, method: str, detail: str) -> None:
        fault = self.faults.get(method)
        text = f"{self.where}: {method}() write failed ({detail})"
        with self._lock:
            if self._queue and self._queue[0][0] == method:
                self._queue.popleft()
            self._hit.discard(method)
            self.failed_writes.append(text)
            self._faults = [f for f in self._faults if f != self._down]  # this fault says it
            raised, self._raised = self._raised, True
        if fault is None:
            LOG.error("%s; no fault event is declared for it: the device is left part-way", text)
        elif raised:  # a monitor raised this outage as its state's fault already: once is all
            LOG.warning("%s; the outage was raised as a fault already", text)
        else:
            LOG.warning("%s; raising %s", text, fault)
            self.report(fault, {"detail": text})

    def _request(self, function: str, address: int, **kwargs: Any) -> tuple[Any, str | None]:
        """One Modbus request: (its result, None), or (None, the failure) (rule 4)."""
        from pymodbus.exceptions import ModbusException

        with self._io:
            try:
                if not self._client.connected and not self._client.connect():
                    raise ConnectionError("connection refused or unreachable")
                result = getattr(self._client, function)(address, device_id=self.unit, **kwargs)
            except (ModbusException, OSError) as exc:
                self._client.close()
                return None, self._outage(f"{self.where}: {function}({address}) failed ({exc})")
        if result.isError():
            return None, self._outage(f"{self.where}: {function}({address}) answered {result}")
        if self._down is not None:
            with self._lock:
                self._down = None
            gone = time.monotonic() - self._down_since
            LOG.warning("%s: answering again after %.2f s without an answer", self.where, gone)
        QUIET.up(id(self))
        return result, None

    def _outage(self, detail: str) -> str:
        with self._lock:
            self._hit.update(m for m, _ in self._queue)
            if self._waiting is not None:
                self._hit.add(self._waiting[0])
            if self._down is None:
                LOG.warning("%s", detail)
                self._down, self._down_since = detail, time.monotonic()
                self._raised = False
                self.outages += 1
                self._faults.append(detail)
        return detail

    def _read(self) -> dict[str, Any] | None:
        """Every input and register, one request per table; None if one failed."""
        values: dict[str, Any] = {}
        if self._count:
            result = self._request("read_discrete_inputs", 0, count=self._count)[0]
            if result is None:
                return None
            bits = list(result.bits)
            values |= {name: bool(bits[addr]) for name, addr in self.inputs.items()}
        functions = {"input": "read_input_registers", "holding": "read_holding_registers"}
        for table, (low, count) in self._spans.items():
            result = self._request(functions[table], low, count=count)[0]
            if result is None:
                return None
            words = list(result.registers)
            for reg in self.registers.values():
                if reg.table == table:
                    at = reg.address - low
                    values[reg.name] = decode_register(reg, words[at : at + reg.width])
        return values

    def poll_once(self) -> bool:
        """Read every point once; report the action's completion (rule 2)."""
        if not self._count and not self._spans:
            return False
        values = self._read()
        if values is None:
            return False
        done: tuple[str, dict[str, Any]] | None = None
        with self._lock:
            self.reads += 1
            self._last_read = time.monotonic()
            self._stale_reported = False
            self.values = values
            waiting = self._waiting
            if waiting is not None and all(_holds(values[n], v) for n, v in waiting[1].until):
                self._waiting = None
                self._hit.discard(waiting[0])
                if waiting[1].done is not None:
                    names = waiting[1].data
                    data = dict(values) if names is None else {n: values[n] for n in names}
                    done = (waiting[1].done, data)
        if done is not None:
            self.report(*done)
        return True

    def poll_fault(self) -> str | None:
        injected = super().poll_fault()
        if injected is not None:
            return injected
        with self._lock:
            if self._faults:
                detail = self._faults.pop(0)
                self._raised = self._raised or detail == self._down
                return detail
            stale = time.monotonic() - self._last_read
            quiet = self._thread is not None and self._down is None  # an outage is reported already
            if quiet and stale > self.stale_after and not self._stale_reported:
                self._stale_reported = True
                detail = f"{self.where}: inputs stale, not read for {stale:.2f} s"
                LOG.warning("%s", detail)
                return detail
        return None


def _holds(value: Any, wanted: Any) -> bool:
    """An ``until`` entry: an input's true/false, or a register's (at_least|at_most, bound)."""
    if isinstance(wanted, tuple):
        bound, limit = wanted
        return bool(value >= limit if bound == "at_least" else value <= limit)
    return bool(value is wanted)
