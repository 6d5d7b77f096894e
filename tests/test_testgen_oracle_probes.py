"""The Hypothesis module drives the implementation beside the specification: time, faults,
monitors and API calls go through the implementation (statectl.out.testgen.oracle).

Each generated module runs in-process on a device made here (the plugin's fixtures
stand in by two callables), so a failure's message can be read: the mutants the fixed
suites' probes catch (a driver that never or late completes, a fault check that never
or always reports, a fault turned into a command, a dropped ``monitoring required``,
a stray API call or a wrong argument) fail it, naming what went wrong; the right
device passes, whatever the seed.
"""

from __future__ import annotations

import importlib.util
import re
import shutil
import textwrap
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import mutation
from statectl.front.builder.build import load_chart
from statectl.kernel.model import Chart
from statectl.out.testgen.adapters.python import PythonImpl
from statectl.out.testgen.generator import generate_hypothesis
from statectl.out.testgen.harness import DeviceUnderTest
from statectl.out.testgen.oracle import RuleSkipped, Specification
from statectl.run.devices import SimTwin
from support import MOTOR, ROOT
from test_testgen import counts, run_pytest
from test_testgen_adapters import _harness

PRESS = ROOT / "examples" / "press" / "press.yaml"
MODBUS_CLAMP = ROOT / "examples" / "modbus" / "clamp.yaml"
#: A clamp with a timeout and a deferred event (Release is kept while Closing).
TIMED_CLAMP = ROOT / "examples" / "clamp" / "clamp.yaml"
HAND = ROOT / "examples" / "motor" / "hand_motor.py"
GXX = shutil.which("g++")


def run(
    tables: Path,
    tmp_path: Path,
    chart: Chart | None = None,
    driver: Callable[[Chart], Any] | None = None,
    impl: Callable[[], Any] | None = None,
    seed: int | None = None,
    event_data: dict[str, Any] | None = None,
) -> None:
    """Generate the Hypothesis module of ``tables`` and run its test on the device
    ``chart`` (default: the tables') with ``driver`` (default: its twin) or ``impl``."""
    path = generate_hypothesis(tables, tmp_path)
    spec = importlib.util.spec_from_file_location(f"oracle_{path.stem}_{id(tmp_path)}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    test = next(f for n, f in vars(module).items() if n.endswith("_follows_the_specification"))
    right = load_chart(tables)
    runs = chart if chart is not None else right

    def device() -> DeviceUnderTest:
        made = driver(runs) if driver is not None else None
        made_impl = impl() if impl is not None else None
        return DeviceUnderTest(runs, made, impl=made_impl, event_data=event_data)

    with pytest.MonkeyPatch.context() as patch:
        if seed is not None:  # what pytest --hypothesis-seed sets
            patch.setattr("hypothesis.core.global_force_seed", seed)
        test(statectl_device_factory=device, statectl_spec=lambda: Specification(right))


def fails(tables: Path, tmp_path: Path, **kwargs: Any) -> str:
    """The message the module fails with on the device ``kwargs`` make."""
    with pytest.raises(AssertionError) as caught:
        run(tables, tmp_path, **kwargs)
    return str(caught.value)


def driver_mutant(tables: Path, kind: str) -> Callable[[Chart], Any]:
    found = next(m for m in mutation.driver_mutants(load_chart(tables)) if m.kind == kind)
    assert found.driver is not None
    return found.driver


def table_mutant(tables: Path, kind: str, name: str) -> Chart:
    return next(
        m.chart
        for m in mutation.table_mutants(load_chart(tables))
        if m.kind == kind and m.name == name
    )


class NeverFaults(SimTwin):
    """A twin whose fault check never reports."""

    def poll_fault(self) -> str | None:
        return None


class AlwaysFaults(SimTwin):
    """A twin whose fault check always reports."""

    def poll_fault(self) -> str | None:
        return "a fault the device does not have"


# -- the right devices pass ---------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize(
    "tables", [MOTOR, PRESS, MODBUS_CLAMP, TIMED_CLAMP], ids=lambda p: f"{p.parent.name}-{p.stem}"
)
def test_the_right_device_passes_whatever_the_seed(tmp_path: Path, tables: Path, seed: int) -> None:
    """On the tables' twin, time, faults and monitor checks agree with the specification:
    the completions come, the monitor raises the fault, deferred events are released."""
    run(tables, tmp_path, seed=seed)


def test_a_simulated_motor_passes(tmp_path: Path) -> None:
    """A driver with its own API and arguments (SimMotor) passes: only the tables' own twin
    has its calls' arguments checked."""
    from statectl.run.devices.motor import SimMotor

    run(MOTOR, tmp_path, driver=lambda chart: SimMotor(), event_data={"Movement": {"amount": 10}})


# -- driver mutants: what the fixed suites' probes see, and the API calls ------------------------

#: What the failure says (a pattern: which call shrinking ends on may vary).
OVERDUE = r"\w+\(\) called by \w+ at [\d.]+ s: the device reported none of \['[\w ]+'\] within 5 s"
DRIVERS = [
    (MOTOR, "never completes", OVERDUE),
    (PRESS, "never completes", r"Stroke\(\) called by Press at [\d.]+ s: the device reported none"),
    (MOTOR, "completes late", OVERDUE),
    (PRESS, "completes late", r"none of \['Stroke completion'\] within 5 s"),
    (MOTOR, "extra API call", r"stray API call ExtraCall\.Extra\(\) serving \w+\(\): the tables"),
    (PRESS, "extra API call", r"stray API call ExtraCall\.Extra\(\)"),
    (MODBUS_CLAMP, "extra API call", r"stray API call ExtraCall\.Extra\(\)"),
    (MOTOR, "wrong argument", r"API call WrongArgument\.\w+\(-1\): wrong argument, the tables"),
    (PRESS, "wrong argument", r"API call WrongArgument\.Stroke\(-1\): wrong argument"),
    (MODBUS_CLAMP, "wrong argument", r"WrongArgument\.\w+\(-1\): wrong argument"),
]


@pytest.mark.parametrize(("tables", "kind", "said"), DRIVERS, ids=lambda x: getattr(x, "stem", x))
def test_a_buggy_driver_fails_naming_what_it_did(
    tmp_path: Path, tables: Path, kind: str, said: str
) -> None:
    """The driver mutants tests/mutation.py makes fail the module, which names the call."""
    assert re.search(said, fails(tables, tmp_path, driver=driver_mutant(tables, kind)))


def test_a_fault_check_that_never_reports_fails(tmp_path: Path) -> None:
    message = fails(MOTOR, tmp_path, driver=NeverFaults)
    assert "the device reported a fault in Moving, which requires monitoring; its monitor " in (
        message
    )
    assert "raised nothing within 0.5 s (the tables expect Error)" in message


def test_a_fault_check_that_always_reports_fails(tmp_path: Path) -> None:
    message = fails(MOTOR, tmp_path, driver=AlwaysFaults)
    assert "the device took Error by itself in ['Moving'], but no fault was reported" in message


SLOW_CONFTEST = """\
import pytest
from statectl.run.devices import SimTwin


@pytest.fixture
def statectl_new_driver():
    return lambda chart: SimTwin(chart, delay=8.0)
"""


def test_the_completion_bound_is_the_suites(tmp_path: Path) -> None:
    """A twin taking 8 s per call fails the module under pytest; with the conftest's
    statectl_completion_bound at 10 s it passes (the fixture reaches the module's devices)."""
    generate_hypothesis(MOTOR, tmp_path)
    (tmp_path / "conftest.py").write_text(SLOW_CONFTEST, encoding="utf-8")
    result = run_pytest(tmp_path)
    assert counts(result) == {"failed": 1}, result.stdout[-3000:]
    assert re.search(OVERDUE, result.stdout)
    bound = "\n\n@pytest.fixture\ndef statectl_completion_bound():\n    return 10.0\n"
    (tmp_path / "conftest.py").write_text(SLOW_CONFTEST + bound, encoding="utf-8")
    result = run_pytest(tmp_path)
    assert counts(result) == {"passed": 1}, result.stdout[-3000:]


# -- table mutants: a fault made a command, monitoring dropped ----------------------------------

TABLES = [
    (MOTOR, "fault as command", "Error"),
    (MOTOR, "monitoring dropped", "Moving"),
    (MODBUS_CLAMP, "fault as command", "Leak"),
    (MODBUS_CLAMP, "fault as command", "Stuck"),
    (MODBUS_CLAMP, "monitoring dropped", "Clamping"),
    (MODBUS_CLAMP, "monitoring dropped", "Clamped"),
    (MODBUS_CLAMP, "monitoring dropped", "Weak"),
]


@pytest.mark.parametrize(("tables", "kind", "name"), TABLES, ids=lambda x: getattr(x, "stem", x))
def test_a_device_whose_monitor_cannot_raise_the_fault_fails(
    tmp_path: Path, tables: Path, kind: str, name: str
) -> None:
    """The implementation runs the mutant tables: no monitor raises the fault (or none runs),
    which the fault or the monitor rule finds; the fixed suites miss the clamp's ones."""
    message = fails(tables, tmp_path, chart=table_mutant(tables, kind, name))
    assert "requires monitoring" in message


# -- other implementations -----------------------------------------------------------------------


def _hand(tmp_path: Path, extra: str = "") -> Callable[[], PythonImpl]:
    """The hand-written Motor (examples/motor), changed by ``extra`` lines."""
    module = tmp_path / "hand.py"
    module.write_text(HAND.read_text(encoding="utf-8") + textwrap.dedent(extra), "utf-8")
    spec = importlib.util.spec_from_file_location(f"hand_{id(tmp_path)}", module)
    assert spec is not None and spec.loader is not None
    loaded = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(loaded)
    cls = getattr(loaded, "Changed", loaded.HandMotor)
    return lambda: PythonImpl(cls)


def test_a_hand_written_class_passes_and_its_slow_copy_fails(tmp_path: Path) -> None:
    """python:MODULE:CLASS: the hand-written Motor passes; with its work 60 s long the
    run rule fails naming the completion."""
    run(MOTOR, tmp_path, impl=_hand(tmp_path))
    slow = "\n\nclass Changed(HandMotor):\n    def _call(self, method, data):\n" + (
        "        super()._call(method, data)\n        self.work = (self.now + 60.0, self.work[1])\n"
    )
    message = fails(MOTOR, tmp_path / "slow", impl=_hand(tmp_path, slow))
    assert re.search(OVERDUE, message)


def test_a_rule_the_implementation_cannot_do_is_skipped_saying_why(tmp_path: Path) -> None:
    """A class without inject_fault and monitoring: the fault and monitor rules are skipped
    with a RuleSkipped warning naming what is missing; the other rules still run."""
    bare = "\n\nclass Changed(HandMotor):\n    inject_fault = None\n    monitoring = None\n"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run(MOTOR, tmp_path, impl=_hand(tmp_path, bare))
    said = {str(w.message) for w in caught if issubclass(w.category, RuleSkipped)}
    assert said == {
        "Motor: the Hypothesis rule 'fault' is skipped: the implementation under test cannot "
        "do this: Changed has no inject_fault()",
        "Motor: the Hypothesis rule 'monitor' is skipped: the implementation under test "
        "cannot do this: Changed has no monitoring()",
    }


@pytest.mark.skipif(GXX is None, reason="no g++ on this machine")
def test_the_cpp_harness_passes_and_fails_when_it_never_completes(tmp_path: Path) -> None:
    """cpp:PROGRAM: the generated C++ passes every rule; built with endless work it fails."""
    from statectl.out.testgen.adapters.cpp import CppImpl

    chart = load_chart(MOTOR)
    good = _harness(tmp_path / "good", MOTOR)
    made: list[CppImpl] = []

    def impl(program: Path) -> Callable[[], CppImpl]:
        def make() -> CppImpl:
            made.append(CppImpl(str(program), chart))
            return made[-1]

        return make

    try:
        run(MOTOR, tmp_path / "a", impl=impl(good))
        endless = _harness(tmp_path / "endless", MOTOR, work="1e9")
        message = fails(MOTOR, tmp_path / "b", impl=impl(endless))
    finally:
        for m in made:
            m.close()
    assert re.search(OVERDUE, message)
