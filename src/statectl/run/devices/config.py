"""Which driver runs which device: configuration, so a hardware change touches no model file.

Rules:
1. A driver is named by a registry name (:data:`DRIVERS`: ``sim-motor``,
   ``sim-stepper``, ``sim-twin``; the bus drivers ``cia402``, ``cia402-sim``,
   ``modbus``, docs/drivers.md) or by an entry string ``package.module:Class``.
2. A driver config file is YAML::

       devices:
         Motor: {driver: sim-motor, options: {speed: 10}}

   :func:`statectl.channels.runconfig.load_driver_config` reports every problem at
   once as D5xx diagnostics with the file and line, raising one
   :class:`~statectl.kernel.errors.DiagnosticError` if any is an error.
3. Options are checked against the driver's constructor when the file loads,
   so a misspelt option is a diagnostic, not a ``TypeError`` at start-up; a
   driver with a ``check_options(options) -> problems`` attribute (``sim-twin``)
   has its option values checked too (D509); a bus driver's option values are
   D511, and a bus driver whose library is not installed is D512.
4. A driver whose constructor takes ``chart`` is given the device's chart by
   :func:`make_driver` (a twin derives itself from the tables); ``chart`` is
   never an option a config file sets.
5. The same file carries the other sections of a run config (dashboard, OPC UA,
   shipping, who may command): each is parsed by the package that uses it, and
   :mod:`statectl.channels.runconfig` reads the whole file. This module parses the
   ``devices:`` section (:func:`parse_devices`).
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import yaml

from statectl.kernel.errors import StatectlError, did_you_mean
from statectl.kernel.model import Chart
from statectl.run.devices.cia402 import Cia402Driver, Cia402SimDriver
from statectl.run.devices.cia402.options import cia402_option_problems
from statectl.run.devices.modbus import ModbusIO, modbus_option_problems
from statectl.run.devices.motor import SimMotor, motor_option_problems
from statectl.run.devices.protocol import DeviceDriver
from statectl.run.devices.stepper import SimStepper, stepper_option_problems
from statectl.run.devices.twin import SimTwin, twin_option_problems

__all__ = [
    "DEVICE_KEYS",
    "DRIVERS",
    "OPTION_CHECKS",
    "DriverConfig",
    "SectionError",
    "make_driver",
    "parse_devices",
    "resolve_driver",
]

#: The drivers statectl ships, by the name a config file uses.
DRIVERS: Mapping[str, Callable[..., DeviceDriver]] = {
    "sim-motor": SimMotor,
    "sim-stepper": SimStepper,
    "sim-twin": SimTwin,
    "cia402": Cia402Driver,
    "cia402-sim": Cia402SimDriver,
    "modbus": ModbusIO,
}

#: Checks of a bus driver's option values (D511), by driver name.
BUS_OPTION_CHECKS: Mapping[str, Callable[[Mapping[str, Any]], Sequence[str]]] = {
    "cia402": cia402_option_problems,
    "cia402-sim": cia402_option_problems,
    "modbus": modbus_option_problems,
}

#: The library each bus driver needs, by driver name: (module, extra) for D512.
BUS_LIBRARIES: Mapping[str, tuple[str, str]] = {
    "cia402": ("canopen", "canopen"),
    "cia402-sim": ("canopen", "canopen"),
    "modbus": ("pymodbus", "modbus"),
}


#: Checks of option values, by driver name: each returns the problems it finds.
OPTION_CHECKS: Mapping[str, Callable[[Mapping[str, Any]], Sequence[str]]] = {
    "sim-twin": twin_option_problems,
    "sim-motor": motor_option_problems,
    "sim-stepper": stepper_option_problems,
}

#: What to do about a D509, by driver name.
OPTION_HINTS: Mapping[str, str] = {
    "sim-twin": "give seconds as numbers >= 0, e.g. {delay: 0.5, faults: {Moving: 0.4}}",
    "sim-motor": "give numbers, e.g. {speed: 10, position: 0}",
    "sim-stepper": "give numbers, e.g. {steps_per_unit: 100, pulse_rate: 1000, step: 0}",
}

#: Constructor parameters statectl supplies itself, never a config file.
SUPPLIED = ("chart",)

#: device -> (driver name, options)
DriverConfig = dict[str, tuple[str, dict[str, Any]]]

#: The keys of a device entry (the JSON Schema, out/schema.py, reads them).
DEVICE_KEYS = ("driver", "options")


def _available() -> str:
    return ", ".join(DRIVERS) + ", or an entry 'package.module:Class'"


def resolve_driver(name: str) -> Callable[..., DeviceDriver]:
    """The driver class a registry name or ``package.module:Class`` entry names."""
    if name in DRIVERS:
        return DRIVERS[name]
    module_name, sep, attr = name.partition(":")
    if not sep or not module_name or not attr:
        maybe = did_you_mean(name, list(DRIVERS))
        raise StatectlError(f"unknown driver {name!r}; {maybe}available: {_available()}")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        top = module_name.split(".")[0]
        raise StatectlError(
            f"driver {name!r}: cannot import {module_name!r} ({exc}); put {top}.py (or the "
            f"package {top}/) beside the model file, or add the directory that holds it to "
            "PYTHONPATH"
        ) from None
    except SyntaxError as exc:
        raise StatectlError(
            f"{exc.filename}:{exc.lineno}: driver {name!r}: {module_name!r} is not valid "
            f"Python ({exc.msg}); fix the module"
        ) from None
    except Exception as exc:  # the module's own code failed: say where, not a traceback
        raise StatectlError(
            f"{_where(exc)}driver {name!r}: importing {module_name!r} failed: "
            f"{type(exc).__name__}: {exc}; fix the module"
        ) from None
    obj = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise StatectlError(f"driver {name!r}: {module_name!r} has no {attr!r}")
        obj = getattr(obj, part)
    if not (
        isinstance(obj, type)
        and all(callable(getattr(obj, m, None)) for m in ("update", "bind", "poll_fault"))
    ):
        raise StatectlError(
            f"driver {name!r} is not a device driver class "
            "(needs update(), bind() and poll_fault(); see statectl.run.devices.DeviceDriver)"
        )
    factory: Callable[..., DeviceDriver] = obj
    return factory


def make_driver(
    name: str, options: Mapping[str, Any] | None = None, *, chart: Chart | None = None
) -> DeviceDriver:
    """Create the driver ``name`` with keyword ``options``; ``chart`` if it takes one (rule 4)."""
    factory = resolve_driver(name)
    kwargs = dict(options or {})
    problem = _option_problem(factory, kwargs) or "; ".join(_value_problems(name, kwargs))
    if problem:
        raise StatectlError(f"driver {name!r}: {problem}")
    if _takes_chart(factory):
        if chart is None:
            raise StatectlError(f"driver {name!r} is derived from the device's chart; pass chart=")
        kwargs["chart"] = chart
    if name in DRIVERS:
        return factory(**kwargs)
    try:
        return factory(**kwargs)
    except StatectlError:
        raise
    except Exception as exc:  # a driver of the user's own failed: say where, not a traceback
        raise StatectlError(
            f"{_where(exc)}driver {name!r} failed while it was made: "
            f"{type(exc).__name__}: {exc}; fix the driver or its options"
        ) from None


def _where(exc: BaseException) -> str:
    """``file:line: `` of the innermost frame that raised ``exc`` (empty if unknown)."""
    tb = exc.__traceback__
    if tb is None:
        return ""
    while tb.tb_next is not None:
        tb = tb.tb_next
    return f"{tb.tb_frame.f_code.co_filename}:{tb.tb_lineno}: "


def _takes_chart(factory: Callable[..., Any]) -> bool:
    try:
        return "chart" in inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return False


def _value_problems(name: str, options: Mapping[str, Any]) -> Sequence[str]:
    check = OPTION_CHECKS.get(name) or BUS_OPTION_CHECKS.get(name)
    return check(options) if check is not None else ()


def _missing_library(name: str) -> str | None:
    """The ``pip install`` a bus driver still needs, or None (D512)."""
    need = BUS_LIBRARIES.get(name)
    if need is None or importlib.util.find_spec(need[0]) is not None:
        return None
    return f"pip install 'statectl[{need[1]}]'"


def _option_problem(factory: Callable[..., Any], options: Mapping[str, Any]) -> str | None:
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):  # no signature to check against: let the call decide
        return None
    params = signature.parameters.values()
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    accepted = [
        p.name
        for p in params
        if p.kind in (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
        and p.name not in SUPPLIED
    ]
    unknown = [k for k in options if k not in accepted]
    if unknown:
        return f"unknown option(s) {unknown}; it accepts {accepted or 'none'}"
    return None


class SectionError(Protocol):
    """How the sections report a problem: a code, a line, what is wrong, what to do."""

    def __call__(self, code: str, line: int | None, message: str, hint: str = "") -> None: ...


def parse_devices(
    devices_node: yaml.Node | None,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: SectionError,
) -> DriverConfig:
    """The ``devices:`` section: each entry whose driver and options pass every check."""
    result: DriverConfig = {}
    for key, entry in devices_node.value if devices_node is not None else ():
        device = str(value(key))
        found = _device(device, key, entry, value, line_of, error)
        if found is not None:
            result[device] = found
    return result


def _device(
    device: str,
    key: yaml.Node,
    entry: yaml.Node,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: SectionError,
) -> tuple[str, dict[str, Any]] | None:
    """One device's (driver, options), or None once its first problem is reported."""
    here = line_of(key)
    if not isinstance(entry, yaml.MappingNode):
        error(
            "D504",
            here,
            f"device {device!r}: entry must be a mapping (got {value(entry)!r})",
            "write '{driver: <name>, options: {...}}'",
        )
        return None
    fields = {str(value(k)): (k, v) for k, v in entry.value}
    for name, (k, _) in fields.items():
        if name not in DEVICE_KEYS:
            error(
                "D507",
                line_of(k),
                f"device {device!r}: unknown key {name!r}",
                f"an entry has {', '.join(DEVICE_KEYS)}",
            )
    if "driver" not in fields:
        error("D504", here, f"device {device!r}: no 'driver'", f"name one of: {_available()}")
        return None
    dnode = fields["driver"][1]
    driver = value(dnode)
    options: dict[str, Any] = {}
    if "options" in fields:
        onode = fields["options"][1]
        raw = value(onode)
        if raw is None:
            raw = {}
        if not isinstance(raw, dict) or not all(isinstance(k, str) for k in raw):
            error(
                "D506",
                line_of(onode),
                f"device {device!r}: options must be a mapping of names to values (got {raw!r})",
            )
            return None
        options = raw
    if not isinstance(driver, str):
        error("D505", line_of(dnode), f"device {device!r}: driver must be a name (got {driver!r})")
        return None
    if not _driver_fits(device, driver, dnode, fields, options, line_of, error):
        return None
    return driver, options


def _driver_fits(
    device: str,
    driver: str,
    dnode: yaml.Node,
    fields: dict[str, tuple[yaml.Node, yaml.Node]],
    options: dict[str, Any],
    line_of: Callable[[yaml.Node], int],
    error: SectionError,
) -> bool:
    """Whether the named driver exists, takes these options with sane values (D505,
    D508, D509, D511) and has its library installed (D512): so start-up cannot fail."""
    try:
        factory = resolve_driver(driver)
    except StatectlError as exc:
        error("D505", line_of(dnode), f"device {device!r}: {exc}")
        return False
    problem = _option_problem(factory, options)
    if problem:
        error("D508", line_of(fields["options"][1]), f"device {device!r}: {problem}")
        return False
    missing = _missing_library(driver)
    if missing is not None:
        error(
            "D512",
            line_of(dnode),
            f"device {device!r}: driver {driver!r} needs a library that is not installed",
            missing,
        )
        return False
    if driver in BUS_OPTION_CHECKS:
        bad = _value_problems(driver, options)
        for text in bad:
            error(
                "D511",
                line_of(fields["options"][1]),
                f"device {device!r}: {text}",
                "see docs/drivers.md for the driver's options",
            )
        if bad:
            return False
    bad = _value_problems(driver, options)
    for text in bad:
        error(
            "D509",
            line_of(fields["options"][1]),
            f"device {device!r}: {text}",
            OPTION_HINTS.get(driver, ""),
        )
    return not bad
