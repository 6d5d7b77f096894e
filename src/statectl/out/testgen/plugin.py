"""The statectl pytest plugin: fixtures for tests of a device against its tables.

Registered under the ``pytest11`` entry point, so ``pip install statectl`` makes
these fixtures available to every test suite; generated modules use nothing else.

- ``statectl_chart``: the chart of the module's ``STATECTL_TABLES`` (a path
  relative to the module), loaded once per module.
- ``statectl_new_driver``: makes a fresh driver for a chart; its default makes
  ``None``, which means the simulated twin derived from the tables. Override it in
  a conftest.py to test a real driver (the Hypothesis module needs one per example).
- ``statectl_driver``: the driver under test, by default ``statectl_new_driver``'s;
  override it instead when only example-based modules run.
- ``statectl_event_data``: event name -> the data sent with it (default: none),
  for drivers that need it (a SimMotor's Movement needs ``{"amount": x}``).
- ``statectl_api``: observer method -> the API function the driver must call
  (``None``: the driver's own ``methods`` table, else the method's name).
- ``statectl_device``: a started :class:`~statectl.out.testgen.harness.DeviceUnderTest`
  (the Subject wired to the driver); the ``statectl_data(name=value, ...)``
  marker gives the datamodel values it starts with; under the ``statectl_strict``
  marker an event the tables neither handle nor ignore in the device's state fails.
- ``statectl_device_factory``: makes a new started device with a fresh driver per
  call (what a Hypothesis state machine needs for each example).
- ``statectl_recorder``: that device's record list, in order.
- ``statectl_spec``: makes the specification of the module's ``STATECTL_TABLES``,
  the kernel stepping the tables' chart on its own
  (:class:`~statectl.out.testgen.oracle.Specification`): the Hypothesis module's
  oracle. It reads the file itself, so a ``statectl_chart`` override (the chart the
  implementation runs) does not change it.
- ``--statectl-impl SPEC`` / ``statectl_impl``: the implementation under test
  (:mod:`statectl.out.testgen.adapters`): ``runtime`` (default), ``cpp:PROGRAM``,
  ``opcua:URL`` or ``python:MODULE:CLASS``; ``statectl_completion_bound`` the seconds a
  completion may take where its state has no timeout; ``statectl_recovery`` the
  Recovery rows of the tables (what the runtime resumes with).
- ``statectl_cell``: a started :class:`~statectl.out.testgen.cellharness.CellUnderTest`,
  the devices of the module's ``STATECTL_CELL`` on one System with the cell's links
  (``send(device, event)``, ``given``, ``expect``, ``advance``, ``assert_state``,
  ``assert_called``, ``assert_invariants``); ``statectl_cell_new_drivers`` makes
  the drivers (default: each device's twin), ``statectl_cell_factory`` a fresh
  cell per call (a Hypothesis example each).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import pytest

from statectl.cell.model import Cell, load_cell
from statectl.front.builder.build import load_chart
from statectl.front.tables import RecoveryRow
from statectl.front.tables import load as load_tables
from statectl.front.tables.csv_io import input_exists
from statectl.kernel.errors import DiagnosticError, Severity, StatectlError
from statectl.kernel.model import Chart
from statectl.out.testgen.adapters import Implementation, parse_spec
from statectl.out.testgen.cellharness import CellUnderTest
from statectl.out.testgen.coverage import Tally
from statectl.out.testgen.generator import write_atomic
from statectl.out.testgen.harness import COMPLETION_BOUND, DeviceUnderTest
from statectl.out.testgen.oracle import Specification
from statectl.run.runtime import Record

__all__ = [
    "CellMaker",
    "DeviceMaker",
    "pytest_addoption",
    "pytest_configure",
    "pytest_sessionfinish",
    "statectl_api",
    "statectl_cell",
    "statectl_cell_event_data",
    "statectl_cell_factory",
    "statectl_cell_model",
    "statectl_cell_new_drivers",
    "statectl_chart",
    "statectl_completion_bound",
    "statectl_device",
    "statectl_device_factory",
    "statectl_driver",
    "statectl_event_data",
    "statectl_impl",
    "statectl_new_driver",
    "statectl_recorder",
    "statectl_recovery",
    "statectl_spec",
]


#: chart name -> what this run's devices of that chart exercised (--statectl-coverage)
_TALLIES = pytest.StashKey[dict[str, Tally]]()


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.getgroup("statectl").addoption(
        "--statectl-coverage",
        metavar="PATH",
        default=None,
        help="write which rows, states and transitions the statectl devices of this run "
        "exercised, as JSON for `statectl coverage PATH FILE`",
    )
    parser.getgroup("statectl").addoption(
        "--statectl-impl",
        metavar="SPEC",
        default="runtime",
        help="the implementation the generated tests check: runtime (statectl's, with the "
        "driver of the fixtures; default), cpp:PROGRAM (a harness statectl codegen "
        "--harness wrote), opcua:opc.tcp://HOST:PORT, python:MODULE:CLASS",
    )


def pytest_sessionfinish(session: pytest.Session) -> None:
    path = session.config.getoption("statectl_coverage", None)
    if not path:
        return
    tallies = session.config.stash.get(_TALLIES, {})
    doc = {"statectl_coverage": 1, "charts": {k: t.to_json() for k, t in tallies.items()}}
    write_atomic(Path(path), json.dumps(doc, indent=1) + "\n")


def _tally(config: pytest.Config, chart: Chart) -> Tally | None:
    """The run's tally for ``chart`` when --statectl-coverage asks for one."""
    if not config.getoption("statectl_coverage", None):
        return None
    tallies = config.stash.setdefault(_TALLIES, {})
    tally = tallies.setdefault(chart.name, Tally(chart))
    return tally if tally.chart == chart else None  # another chart of that name: not counted


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "statectl_data(**values): datamodel values the statectl_device starts with"
    )
    config.addinivalue_line(
        "markers",
        "statectl_strict: fail when an event meets a state the tables neither handle nor ignore",
    )


def _beside(request: pytest.FixtureRequest, given: str, what: str) -> Path:
    """``given`` relative to the test module; a missing file fails the test saying so."""
    path = (Path(request.module.__file__).parent / given).resolve()
    if not input_exists(path):  # NAME.csv: the CSV pair, as testgen writes it
        pytest.fail(f"{request.module.__name__}: {what} {path}: no such file", pytrace=False)
    return path


def _chart_of(request: pytest.FixtureRequest, given: str, what: str) -> Chart:
    path = _beside(request, given, what)
    try:
        return load_chart(path)
    except DiagnosticError as exc:
        shown = "\n".join(str(d) for d in exc.diagnostics if d.severity is not Severity.INFO)
    pytest.fail(f"{what} {path} does not load:\n{shown}", pytrace=False)


@pytest.fixture(scope="module")
def statectl_chart(request: pytest.FixtureRequest) -> Chart | None:
    """The chart of the test module's ``STATECTL_TABLES`` (relative to the module).

    ``None`` when the module names none: ``statectl_device`` is then the callable
    ``statectl_device("motor.yaml", driver=...)``.
    """
    tables = _module_path(request, "STATECTL_TABLES", "the device file's path")
    return None if tables is None else _chart_of(request, tables, "STATECTL_TABLES")


def _module_path(request: pytest.FixtureRequest, name: str, what: str) -> str | None:
    """The path a test module names in ``name`` (relative to it), ``None`` when it names none."""
    given = getattr(request.module, name, None)
    if given is not None and not isinstance(given, str):
        pytest.fail(
            f"{request.module.__name__}: {name} must be {what} (relative to the module)",
            pytrace=False,
        )
    return given


class DeviceMaker:
    """``statectl_device("motor.yaml", driver=...)``: a started device of any device file.

    What ``statectl_device`` is in a module without ``STATECTL_TABLES``; the path is
    relative to the test module, ``driver`` ``None`` is the tables' simulated twin.
    """

    def __init__(
        self,
        request: pytest.FixtureRequest,
        event_data: Mapping[str, Any],
        api: Mapping[str, str | None] | None,
    ) -> None:
        self._request = request
        self._event_data = event_data
        self._api = api

    def __call__(
        self,
        tables: str,
        driver: Any = None,
        *,
        data: Mapping[str, Any] | None = None,
        event_data: Mapping[str, Any] | None = None,
        api: Mapping[str, str | None] | None = None,
        strict: bool | None = None,
    ) -> DeviceUnderTest:
        request = self._request
        chart = _chart_of(request, tables, "statectl_device")
        if strict is None:
            strict = request.node.get_closest_marker("statectl_strict") is not None
        return DeviceUnderTest(
            chart,
            driver,
            data=data,
            event_data=self._event_data if event_data is None else event_data,
            api=self._api if api is None else api,
            strict=strict,
            tally=_tally(request.config, chart),
            where=request.node.nodeid,
        )

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        pytest.fail(
            f"statectl_device.{name}: this module names no STATECTL_TABLES; set it to the "
            "device file, or make a device with statectl_device('motor.yaml', driver=...)",
            pytrace=False,
        )


@pytest.fixture
def statectl_new_driver() -> Callable[[Chart], Any]:
    """Makes a fresh driver for a chart; ``None`` from it means the tables' simulated twin."""
    return lambda chart: None


@pytest.fixture
def statectl_driver(
    statectl_new_driver: Callable[[Chart], Any], statectl_chart: Chart | None
) -> Any:
    """The driver under test (by default ``statectl_new_driver``'s; ``None``: the twin)."""
    return statectl_new_driver(statectl_chart) if statectl_chart is not None else None


@pytest.fixture
def statectl_event_data() -> Mapping[str, Any]:
    """Event name -> the data sent with it."""
    return {}


@pytest.fixture
def statectl_api() -> Mapping[str, str | None] | None:
    """Observer method -> the API function the driver must call (``None``: its own table)."""
    return None


@pytest.fixture
def statectl_impl(request: pytest.FixtureRequest) -> Callable[[Chart], Implementation | None]:
    """Makes the implementation under test for a chart; ``None`` is statectl's runtime
    with the fixtures' driver. Chosen by ``--statectl-impl`` (override it to choose in code)."""
    spec = request.config.getoption("statectl_impl", "runtime") or "runtime"
    try:
        kind, rest = parse_spec(spec)
    except StatectlError as exc:
        pytest.fail(str(exc), pytrace=False)
    return lambda chart: _make_impl(kind, rest, chart)


def _make_impl(kind: str, rest: str, chart: Chart) -> Implementation | None:
    """The adapter of one ``--statectl-impl`` spec (imported only when chosen)."""
    try:
        if kind == "python":
            from statectl.out.testgen.adapters.python import PythonImpl, load_class

            return PythonImpl(load_class(rest))
        if kind == "cpp":
            from statectl.out.testgen.adapters.cpp import CppImpl

            return CppImpl(rest, chart)
        if kind == "opcua":
            from statectl.out.testgen.adapters.opcua import OpcuaImpl

            return OpcuaImpl(rest, chart)
    except StatectlError as exc:
        pytest.fail(f"--statectl-impl {kind}:{rest}: {exc}", pytrace=False)
    return None


@pytest.fixture
def statectl_completion_bound() -> float:
    """Seconds a device may take to report a completion where its state has no timeout."""
    return COMPLETION_BOUND


@pytest.fixture(scope="module")
def statectl_recovery(request: pytest.FixtureRequest) -> tuple[RecoveryRow, ...]:
    """The Recovery rows of the module's ``STATECTL_TABLES`` (none without it)."""
    tables = _module_path(request, "STATECTL_TABLES", "the device file's path")
    if tables is None:
        return ()
    loaded, _ = load_tables(_beside(request, tables, "STATECTL_TABLES"))
    return tuple(loaded.recovery) if loaded is not None else ()


@pytest.fixture
def statectl_device(
    request: pytest.FixtureRequest,
    statectl_chart: Chart | None,
    statectl_driver: Any,
    statectl_event_data: Mapping[str, Any],
    statectl_api: Mapping[str, str | None] | None,
    statectl_impl: Callable[[Chart], Implementation | None],
    statectl_new_driver: Callable[[Chart], Any],
    statectl_recovery: tuple[RecoveryRow, ...],
    statectl_completion_bound: float,
) -> DeviceUnderTest | DeviceMaker:
    """A started device on a simulated clock, wired to the driver under test.

    Without ``STATECTL_TABLES`` it is a :class:`DeviceMaker`:
    ``statectl_device("motor.yaml", driver=...)`` gives the started device.
    """
    if statectl_chart is None:
        return DeviceMaker(request, statectl_event_data, statectl_api)
    marker = request.node.get_closest_marker("statectl_data")
    data = dict(marker.kwargs) if marker is not None else None
    impl = statectl_impl(statectl_chart)
    if impl is not None:
        request.addfinalizer(impl.close)
    device = DeviceUnderTest(
        statectl_chart,
        statectl_driver,
        data=data,
        event_data=statectl_event_data,
        api=statectl_api,
        strict=request.node.get_closest_marker("statectl_strict") is not None,
        tally=_tally(request.config, statectl_chart),
        where=request.node.nodeid,
        impl=impl,
        new_driver=statectl_new_driver,
        recovery=statectl_recovery,
        completion_bound=statectl_completion_bound,
    )
    if device.runtime is not None:
        request.addfinalizer(device.runtime.close)
    return device


@pytest.fixture
def statectl_device_factory(
    statectl_chart: Chart | None,
    statectl_new_driver: Callable[[Chart], Any],
    statectl_event_data: Mapping[str, Any],
    statectl_api: Mapping[str, str | None] | None,
    request: pytest.FixtureRequest,
    statectl_impl: Callable[[Chart], Implementation | None],
    statectl_completion_bound: float,
) -> Callable[[], DeviceUnderTest]:
    """Makes a new started device with a fresh driver each call (a Hypothesis example each),
    on the implementation ``--statectl-impl`` chooses, with the suite's completion bound."""
    chart = statectl_chart
    if chart is None:
        pytest.fail(
            f"{request.module.__name__}: set STATECTL_TABLES to the device file "
            "(relative to the module) or override the statectl_chart fixture",
            pytrace=False,
        )

    def make() -> DeviceUnderTest:
        impl = statectl_impl(chart)
        if impl is not None:
            request.addfinalizer(impl.close)
        return DeviceUnderTest(
            chart,
            statectl_new_driver(chart),
            event_data=statectl_event_data,
            api=statectl_api,
            tally=_tally(request.config, chart),
            where=request.node.nodeid,
            impl=impl,
            completion_bound=statectl_completion_bound,
        )

    return make


@pytest.fixture
def statectl_spec(request: pytest.FixtureRequest) -> Callable[[], Specification]:
    """Makes a fresh specification of ``STATECTL_TABLES`` per call (a Hypothesis example
    each): the oracle the implementation is compared with after every event."""
    tables = _module_path(request, "STATECTL_TABLES", "the device file's path")
    if tables is None:
        pytest.fail(
            f"{request.module.__name__}: set STATECTL_TABLES to the device file "
            "(relative to the module): it is the specification",
            pytrace=False,
        )
    chart = _chart_of(request, tables, "STATECTL_TABLES")
    return lambda: Specification(chart)


@pytest.fixture
def statectl_recorder(statectl_device: DeviceUnderTest | DeviceMaker) -> list[Record]:
    """Every record the device emitted, in order (the notifications among them)."""
    if isinstance(statectl_device, DeviceMaker):
        pytest.fail("statectl_recorder needs STATECTL_TABLES in the module", pytrace=False)
    return statectl_device.recorder.records


# -- cells ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def statectl_cell_model(request: pytest.FixtureRequest) -> Cell | None:
    """The cell of the test module's ``STATECTL_CELL`` (relative to the module); else ``None``."""
    given = _module_path(request, "STATECTL_CELL", "the cell file's path")
    return None if given is None else _cell_of(request, given, "STATECTL_CELL")


def _cell_of(request: pytest.FixtureRequest, given: str, what: str) -> Cell:
    path = _beside(request, given, what)
    cell, diags = load_cell(path)
    if cell is None:
        shown = "\n".join(str(d) for d in diags if d.severity is not Severity.INFO)
        pytest.fail(f"{what} {path} does not load:\n{shown}", pytrace=False)
    return cell


@pytest.fixture
def statectl_cell_new_drivers() -> Callable[[Cell], Mapping[str, Any]]:
    """Makes fresh drivers for a cell: device name -> driver; a device left out gets its twin."""
    return lambda cell: {}


@pytest.fixture
def statectl_cell_event_data() -> Mapping[str, Mapping[str, Any]]:
    """Device name -> event name -> the data sent with it."""
    return {}


class CellMaker:
    """``statectl_cell("cell.yaml", drivers={...})``: a started cell of any cell file.

    What ``statectl_cell`` is in a module without ``STATECTL_CELL``; the path is
    relative to the test module; a device left out of ``drivers`` runs on its twin.
    """

    def __init__(
        self, request: pytest.FixtureRequest, event_data: Mapping[str, Mapping[str, Any]]
    ) -> None:
        self._request = request
        self._event_data = event_data

    def __call__(
        self,
        cell: str,
        drivers: Mapping[str, Any] | None = None,
        *,
        event_data: Mapping[str, Mapping[str, Any]] | None = None,
        strict: bool | None = None,
    ) -> CellUnderTest:
        request = self._request
        model = _cell_of(request, cell, "statectl_cell")
        if strict is None:
            strict = request.node.get_closest_marker("statectl_strict") is not None
        return CellUnderTest(
            model,
            drivers,
            event_data=self._event_data if event_data is None else event_data,
            strict=strict,
        )

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        pytest.fail(
            f"statectl_cell.{name}: this module names no STATECTL_CELL; set it to the cell "
            "file, or make a cell with statectl_cell('cell.yaml', drivers={...})",
            pytrace=False,
        )


@pytest.fixture
def statectl_cell_factory(
    request: pytest.FixtureRequest,
    statectl_cell_model: Cell | None,
    statectl_cell_new_drivers: Callable[[Cell], Mapping[str, Any]],
    statectl_cell_event_data: Mapping[str, Mapping[str, Any]],
) -> Callable[[], CellUnderTest]:
    """Makes a new started cell with fresh drivers each call."""
    model = statectl_cell_model
    if model is None:
        pytest.fail(
            f"{request.module.__name__}: set STATECTL_CELL to the cell file "
            "(relative to the module) or override the statectl_cell_model fixture",
            pytrace=False,
        )
    strict = request.node.get_closest_marker("statectl_strict") is not None

    def make() -> CellUnderTest:
        return CellUnderTest(
            model,
            statectl_cell_new_drivers(model),
            event_data=statectl_cell_event_data,
            strict=strict,
        )

    return make


@pytest.fixture
def statectl_cell(
    request: pytest.FixtureRequest,
    statectl_cell_model: Cell | None,
    statectl_cell_new_drivers: Callable[[Cell], Mapping[str, Any]],
    statectl_cell_event_data: Mapping[str, Mapping[str, Any]],
) -> CellUnderTest | CellMaker:
    """The cell's devices started on one System with its links, on a simulated clock.

    Without ``STATECTL_CELL`` it is a :class:`CellMaker`:
    ``statectl_cell("cell.yaml", drivers={...})`` gives the started cell.
    """
    if statectl_cell_model is None:
        return CellMaker(request, statectl_cell_event_data)
    return CellUnderTest(
        statectl_cell_model,
        statectl_cell_new_drivers(statectl_cell_model),
        event_data=statectl_cell_event_data,
        strict=request.node.get_closest_marker("statectl_strict") is not None,
    )
