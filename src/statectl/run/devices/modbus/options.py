"""The ``modbus`` driver's options: checked all at once (D511), then parsed into values.

Rules:
1. Points are named: ``coils`` (outputs) and ``inputs`` (discrete inputs), name ->
   address 0-1999; ``registers`` name -> ``{table: holding|input, address,
   type: int16|uint16|int32|float32, scale, offset, byte_order, word_order}``.
   A register's value in the model is ``raw * scale + offset``.
2. An action (observer method) may ``set`` coils (true/false) and holding
   registers (a number), wait ``until`` inputs read a value and registers reach
   ``{at_least: x}`` / ``{at_most: x}``, report ``done`` with the points in ``data``
   (default: every input and register), and raise ``fault`` when a write fails
   (default: the fault event the chart declares for the state the method enters).
3. The link is ``transport: tcp`` (``host``, ``port``) or ``rtu`` (``serial``,
   ``baudrate``, ``parity``, ``stopbits``, ``bytesize``); a write is tried
   ``1 + retries`` times, ``retry_delay`` s apart.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from statectl.run.devices.base import finite_number

__all__ = [
    "MAX_INPUTS",
    "MAX_REGISTERS",
    "REGISTER_TYPES",
    "Action",
    "Register",
    "modbus_option_problems",
    "parse_actions",
    "parse_registers",
]

#: The most discrete inputs one read may ask for (Modbus allows 2000).
MAX_INPUTS = 2000
#: The most registers one read may ask for (Modbus allows 125).
MAX_REGISTERS = 125
#: Register type -> how many 16-bit registers it takes and its struct code (big-endian).
REGISTER_TYPES: Mapping[str, tuple[int, str]] = {
    "int16": (1, "h"),
    "uint16": (1, "H"),
    "int32": (2, "i"),
    "float32": (2, "f"),
}
ORDERS = ("big", "little")
TABLES = ("holding", "input")
PARITIES = ("N", "E", "O")
UNTIL_BOUNDS = ("at_least", "at_most")


@dataclass(frozen=True, slots=True)
class Register:
    """One named register value: where it is, how its words become a number (rule 1)."""

    name: str
    table: str  # holding or input
    address: int
    type: str = "uint16"
    scale: float = 1.0
    offset: float = 0.0
    byte_order: str = "big"
    word_order: str = "big"

    @property
    def width(self) -> int:
        """How many 16-bit registers the value takes."""
        return REGISTER_TYPES[self.type][0]


@dataclass(frozen=True, slots=True)
class Action:
    """What one observer method does (rule 2)."""

    set: tuple[tuple[str, bool | float], ...]
    until: tuple[tuple[str, Any], ...]  # input -> bool, register -> (bound, number)
    done: str | None
    data: tuple[str, ...] | None = None  # None: every input and register
    fault: str | None = None


def _is_int(value: Any, low: int, high: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and low <= value <= high


def _address_problems(kind: str, points: Any) -> list[str]:
    if not isinstance(points, Mapping):
        return [f"{kind} must map names to addresses (got {points!r})"]
    return [
        f"{kind}.{name}: address must be a number 0-{MAX_INPUTS - 1} (got {addr!r})"
        for name, addr in points.items()
        if not _is_int(addr, 0, MAX_INPUTS - 1)
    ]


def _register_problems(registers: Any) -> list[str]:
    """Rule 1: each register's table, address, type, scale and orders; one read per table."""
    if not isinstance(registers, Mapping):
        return [f"registers must map names to {{table, address, type, ...}} (got {registers!r})"]
    problems: list[str] = []
    known = {"table", "address", "type", "scale", "offset", "byte_order", "word_order"}
    for name, spec in registers.items():
        where = f"registers.{name}"
        if not isinstance(spec, Mapping):
            problems.append(f"{where} must be a mapping such as {{table: input, address: 0}}")
            continue
        problems += [
            f"{where}: unknown key {k!r} (has {', '.join(sorted(known))})"
            for k in spec
            if k not in known
        ]
        if spec.get("table") not in TABLES:
            problems.append(f"{where}.table must be holding or input (got {spec.get('table')!r})")
        if not _is_int(spec.get("address"), 0, 65535):
            problems.append(
                f"{where}.address must be a number 0-65535 (got {spec.get('address')!r})"
            )
        if spec.get("type", "uint16") not in REGISTER_TYPES:
            kinds = ", ".join(REGISTER_TYPES)
            problems.append(f"{where}.type must be one of {kinds} (got {spec.get('type')!r})")
        for key, default in (("scale", 1.0), ("offset", 0.0)):
            if not finite_number(spec.get(key, default)):
                problems.append(f"{where}.{key} must be a finite number (got {spec.get(key)!r})")
        if spec.get("scale", 1.0) == 0:
            problems.append(f"{where}.scale must not be 0")
        for key in ("byte_order", "word_order"):
            if spec.get(key, "big") not in ORDERS:
                problems.append(f"{where}.{key} must be big or little (got {spec.get(key)!r})")
    if problems:
        return problems
    for table in TABLES:
        regs = parse_registers({n: s for n, s in registers.items() if s["table"] == table})
        if regs:
            low = min(r.address for r in regs.values())
            high = max(r.address + r.width for r in regs.values())
            if high - low > MAX_REGISTERS:
                problems.append(
                    f"registers: the {table} registers span {high - low} addresses "
                    f"({low}-{high - 1}); one read takes at most {MAX_REGISTERS}: "
                    "use a second device entry for the rest"
                )
    return problems


def _link_problems(options: Mapping[str, Any]) -> list[str]:
    """Rule 3: the transport and its settings, the retry bound and the times."""
    problems: list[str] = []
    transport = options.get("transport", "tcp")
    if transport not in ("tcp", "rtu"):
        problems.append(f"transport must be tcp or rtu (got {transport!r})")
    if transport == "rtu":
        serial = options.get("serial")
        if not (isinstance(serial, str) and serial):
            problems.append(f"serial must be the serial port, e.g. /dev/ttyUSB0 (got {serial!r})")
    port = options.get("port", 502)
    if not _is_int(port, 1, 65535):
        problems.append(f"port must be a number 1-65535 (got {port!r})")
    host = options.get("host", "127.0.0.1")
    if not (isinstance(host, str) and host):
        problems.append(f"host must be a host name or address, e.g. 127.0.0.1 (got {host!r})")
    if not _is_int(options.get("unit", 1), 0, 255):
        problems.append(f"unit must be a Modbus device id 0-255 (got {options.get('unit')!r})")
    if not _is_int(options.get("baudrate", 19200), 1, 10_000_000):
        problems.append(
            f"baudrate must be bits per second, e.g. 19200 (got {options.get('baudrate')!r})"
        )
    if options.get("parity", "N") not in PARITIES:
        problems.append(f"parity must be N, E or O (got {options.get('parity')!r})")
    if options.get("stopbits", 1) not in (1, 2) or isinstance(options.get("stopbits"), bool):
        problems.append(f"stopbits must be 1 or 2 (got {options.get('stopbits')!r})")
    if options.get("bytesize", 8) not in (7, 8) or isinstance(options.get("bytesize"), bool):
        problems.append(f"bytesize must be 7 or 8 (got {options.get('bytesize')!r})")
    if not _is_int(options.get("retries", 3), 0, 100):
        problems.append(
            f"retries must be a number of retries 0-100 (got {options.get('retries')!r})"
        )
    for key in ("period", "timeout", "stale_after", "retry_delay"):
        v = options.get(key, 1.0)
        if not (finite_number(v) and v > 0):
            problems.append(f"{key} must be seconds > 0 (got {v!r})")
    return problems


def _set_problems(method: str, points: Any, coils: Any, holding: set[str]) -> list[str]:
    if not isinstance(points, Mapping):
        return [f"actions.{method}.set must map coils to true/false and registers to numbers"]
    problems = []
    for name, val in points.items():
        if name in holding:
            if not finite_number(val):
                problems.append(f"actions.{method}.set.{name} must be a number (a register)")
        elif not isinstance(coils, Mapping) or name not in coils:
            problems.append(
                f"actions.{method}.set: {name!r} is not one of the coils or holding registers"
            )
        elif not isinstance(val, bool):
            problems.append(f"actions.{method}.set.{name} must be true or false")
    return problems


def _until_problems(method: str, points: Any, inputs: Any, registers: set[str]) -> list[str]:
    if not isinstance(points, Mapping):
        return [f"actions.{method}.until must map inputs to true/false, registers to bounds"]
    problems = []
    for name, val in points.items():
        if name in registers:
            ok = isinstance(val, Mapping) and len(val) == 1
            ok = ok and next(iter(val)) in UNTIL_BOUNDS and finite_number(next(iter(val.values())))
            if not ok:
                problems.append(
                    f"actions.{method}.until.{name} must be {{at_least: <number>}} or "
                    f"{{at_most: <number>}} (got {val!r})"
                )
        elif not isinstance(inputs, Mapping) or name not in inputs:
            problems.append(
                f"actions.{method}.until: {name!r} is not one of the inputs or registers"
            )
        elif not isinstance(val, bool):
            problems.append(f"actions.{method}.until.{name} must be true or false")
    return problems


def _action_problems(options: Mapping[str, Any]) -> list[str]:
    """Rule 2: each action's keys and the points they name."""
    actions = options.get("actions", {})
    if not isinstance(actions, Mapping):
        return [f"actions must map observer methods to actions (got {actions!r})"]
    coils, inputs = options.get("coils", {}), options.get("inputs", {})
    registers = options.get("registers", {})
    registers = registers if isinstance(registers, Mapping) else {}
    holding = {
        n for n, s in registers.items() if isinstance(s, Mapping) and s.get("table") == "holding"
    }
    named = set(registers) | (set(inputs) if isinstance(inputs, Mapping) else set())
    problems: list[str] = []
    for method, spec in actions.items():
        if not isinstance(spec, Mapping):
            problems.append(f"actions.{method} must be a mapping with set/until/done/data/fault")
            continue
        for key in spec:
            if key not in ("set", "until", "done", "data", "fault"):
                problems.append(
                    f"actions.{method}: unknown key {key!r} (has set, until, done, data, fault)"
                )
        problems += _set_problems(method, spec.get("set", {}), coils, holding)
        problems += _until_problems(method, spec.get("until", {}), inputs, set(registers))
        for key in ("done", "fault"):
            if key in spec and not isinstance(spec[key], str):
                problems.append(f"actions.{method}.{key} must be an event name")
        data = spec.get("data", [])
        if not (isinstance(data, list) and all(isinstance(n, str) for n in data)):
            problems.append(f"actions.{method}.data must be a list of input and register names")
        else:
            problems += [
                f"actions.{method}.data: {n!r} is not one of the inputs or registers"
                for n in data
                if n not in named
            ]
    return problems


def modbus_option_problems(options: Mapping[str, Any]) -> Sequence[str]:
    """Problems with a ``modbus`` driver's options (D511), all at once."""
    problems = _address_problems("coils", options.get("coils", {}))
    problems += _address_problems("inputs", options.get("inputs", {}))
    problems += _register_problems(options.get("registers", {}))
    problems += _link_problems(options)
    return problems + _action_problems(options)


def parse_registers(registers: Mapping[str, Mapping[str, Any]]) -> dict[str, Register]:
    """Checked register specs (rule 1) as values."""
    return {
        name: Register(
            name,
            spec["table"],
            spec["address"],
            spec.get("type", "uint16"),
            float(spec.get("scale", 1.0)),
            float(spec.get("offset", 0.0)),
            spec.get("byte_order", "big"),
            spec.get("word_order", "big"),
        )
        for name, spec in registers.items()
    }


def parse_actions(actions: Mapping[str, Mapping[str, Any]]) -> dict[str, Action]:
    """Checked action specs (rule 2) as values."""
    parsed = {}
    for method, spec in actions.items():
        until = tuple(
            (n, next(iter(v.items())) if isinstance(v, Mapping) else v)
            for n, v in spec.get("until", {}).items()
        )
        data = spec.get("data")
        parsed[method] = Action(
            tuple(spec.get("set", {}).items()),
            until,
            spec.get("done"),
            None if data is None else tuple(data),
            spec.get("fault"),
        )
    return parsed
