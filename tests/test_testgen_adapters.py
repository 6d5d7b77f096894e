"""One generated suite, many implementations; faults, monitors, completions, API calls and
recovery tested through the implementation, each kind shown to catch its mutant
(docs/testing.md, "Other implementations" and "Faults, monitors, completions, recovery")."""

from __future__ import annotations

import shutil
import socket
import subprocess
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from statectl.front.builder.build import load_chart
from statectl.kernel.errors import StatectlError
from statectl.out.testgen import generate
from statectl.out.testgen.adapters import parse_spec
from statectl.out.testgen.adapters.python import PythonImpl, load_class
from statectl.out.testgen.harness import DeviceUnderTest
from support import MOTOR, ROOT
from test_testgen import counts, functions, run_pytest

HAND = ROOT / "examples" / "motor" / "hand_motor.py"
GXX = shutil.which("g++")

#: The probes of the Motor's modules (one fault and one monitor test for Moving, a
#: completion test per call, a recovery test per Recovery row).
PROBES = {
    "test_fault_01_moving",
    "test_monitor_01_moving",
    "test_completion_01_movement_after_movement",
    "test_completion_02_error_after_error",
    "test_completion_03_initialization_after_initialization",
    "test_recovery_01_moving",
    "test_recovery_02_returning",
}


def _motor(tmp_path: Path) -> tuple[Path, Path, int]:
    """The Motor's rows module generated from a copy of its tables: (tables, out, tests)."""
    tables = tmp_path / "motor.yaml"
    tables.write_text(MOTOR.read_text(encoding="utf-8"), encoding="utf-8")
    out = tmp_path / "gen"
    made = generate(tables, "rows", out)
    return tables, out, made.tests + made.probes


def test_the_motor_module_has_a_probe_of_each_kind(tmp_path: Path) -> None:
    """Fault, monitor, completion and recovery tests, each saying what it checks."""
    _, out, _ = _motor(tmp_path)
    found = functions(out / "test_motor_rows.py")
    assert set(found) >= PROBES, sorted(found)
    assert "requires monitoring" in found["test_fault_01_moving"]
    assert "reports Movement completion" in found["test_completion_01_movement_after_movement"]
    assert "Recovery row 2" in found["test_recovery_02_returning"]


# -- the same suite on each implementation ---------------------------------------------------


def test_the_suite_passes_on_the_runtime(tmp_path: Path) -> None:
    """statectl's runtime on the twin passes every test, the probes included."""
    _, out, tests = _motor(tmp_path)
    result = run_pytest(out, "--statectl-impl", "runtime")
    assert counts(result) == {"passed": tests}, result.stdout[-3000:]


def test_the_suite_passes_on_a_hand_written_class(tmp_path: Path) -> None:
    """examples/motor/hand_motor.py, its own state logic, passes every test."""
    _, out, tests = _motor(tmp_path)
    shutil.copy(HAND, out / "hand_motor.py")
    result = run_pytest(out, "--statectl-impl", "python:hand_motor:HandMotor")
    assert counts(result) == {"passed": tests}, result.stdout[-3000:]


@pytest.mark.skipif(GXX is None, reason="no g++ on this machine")
def test_the_suite_passes_on_the_generated_cpp(tmp_path: Path) -> None:
    """The harness codegen --harness writes, compiled, passes: its twin reports the
    completions and faults, its monitors poll; restart (no journal in C++) is skipped."""
    _, out, tests = _motor(tmp_path)
    program = _harness(tmp_path, MOTOR)
    result = run_pytest(out, "--statectl-impl", f"cpp:{program}", "-rs")
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result) == {"passed": tests - 2, "skipped": 2}
    assert "the C++ harness keeps no journal to resume from" in result.stdout


def _harness(tmp_path: Path, tables: Path, work: str | None = None) -> Path:
    """The harness of ``tables`` compiled; ``work``: its twin's seconds per call instead."""
    from statectl.channels.cli import main

    cpp = tmp_path / "cpp"
    assert main(["codegen", str(tables), "--out", str(cpp), "--harness"]) == 0
    source = cpp / f"{tables.stem}_harness.cpp"
    if work is not None:
        text = source.read_text(encoding="utf-8")
        assert "kWork = 1.0;" in text
        source.write_text(text.replace("kWork = 1.0;", f"kWork = {work};"), encoding="utf-8")
    program = cpp / f"{tables.stem}_harness"
    flags = ["-std=c++17", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-fno-exceptions"]
    cmd = [GXX or "g++", *flags, "-fno-rtti", "-DSTATECTL_TRACE=1", "-I", str(cpp)]
    done = subprocess.run(
        [*cmd, str(cpp / f"{tables.stem}_harness.cpp"), "-o", str(program)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return program


@pytest.mark.skipif(GXX is None, reason="no g++ on this machine")
def test_the_clamps_timeouts_run_on_the_cpp_harness(tmp_path: Path) -> None:
    """A chart with a timeout and a deferred event: the harness ticks the device's timers."""
    clamp = ROOT / "examples" / "clamp" / "clamp.yaml"
    made = generate(clamp, "rows", tmp_path / "gen")
    program = _harness(tmp_path, clamp)
    result = run_pytest(tmp_path / "gen", "--statectl-impl", f"cpp:{program}")
    assert result.returncode == 0, result.stdout[-3000:]
    assert counts(result).get("passed") == made.tests + made.probes - counts(result).get(
        "skipped", 0
    )


@pytest.mark.skipif(GXX is None, reason="no g++ on this machine")
def test_a_cpp_twin_that_never_completes_fails(tmp_path: Path) -> None:
    """The C++ harness built with the twin's work made endless: the completion test fails."""
    _, out, _ = _motor(tmp_path)
    program = _harness(tmp_path, MOTOR, work="1e9")
    result = run_pytest(out, "--statectl-impl", f"cpp:{program}", "-k", "completion_01")
    assert counts(result).get("failed") == 1, result.stdout[-3000:]
    assert "expected the device to report Movement completion within 5 s" in result.stdout


OPCUA_CONFTEST = '''
import socket

import pytest

from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
from statectl.out.testgen.adapters.opcua import OpcuaImpl
from statectl.run.devices import SimTwin
from statectl.run.runtime import SimClock
from statectl.run.system import DeviceSetup, System

USER, PASSWORD = "tester", "a-long-password-1"


class Served(OpcuaImpl):
    """The served device on a simulated clock this test moves (no wall time)."""

    def __init__(self, url, chart, system):
        super().__init__(url, chart)
        self.system = system

    def advance(self, seconds):
        before = self.states()
        self.system.advance(seconds)
        after = self.states()
        return super().advance(0) if after == before else type(super().advance(0))(
            events=self._events(before, after)
        )


@pytest.fixture
def statectl_impl(request):
    def make(chart):
        system = System((DeviceSetup(chart.name, chart, driver=SimTwin(chart)),), SimClock())
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        url = f"opc.tcp://127.0.0.1:{port}"
        settings = OpcuaSettings(endpoint=url, user=USER, password=PASSWORD, security=("None",))
        server = OpcuaServer(system, settings)
        server.start()
        system.start()
        server.refresh()
        halt = system.start_owner(paced=False)

        def stop():
            halt()
            server.stop()
            system.close()

        request.addfinalizer(stop)
        return Served(f"opc.tcp://{USER}:{PASSWORD}@127.0.0.1:{port}", chart, system)

    return make
'''


def test_the_suite_passes_on_the_opcua_server(tmp_path: Path) -> None:
    """The server statectl run --opcua gives, a fresh one per test: the command events are
    its methods; completions and faults are the device's (skipped, saying so)."""
    pytest.importorskip("asyncua")
    _, out, _ = _motor(tmp_path)
    (out / "conftest.py").write_text(OPCUA_CONFTEST, encoding="utf-8")
    # three tests: a server takes seconds to start (the whole module: docs/testing.md)
    result = run_pytest(out, "-rs", "-k", "row_01 or completion_01 or fault_01")
    assert counts(result) == {"passed": 2, "skipped": 1}, result.stdout[-3000:]
    assert "a fault cannot be injected over OPC UA" in result.stdout


def test_the_fault_test_runs_on_a_served_device_whose_driver_is_at_hand(tmp_path: Path) -> None:
    """Served in the test's process, the driver behind the server takes the fault; the
    monitor raising it is read over OPC UA. Monitors stay unseen: that test is skipped."""
    pytest.importorskip("asyncua")
    _, out, _ = _motor(tmp_path)
    behind = "super().__init__(url, chart, behind=system.setups[0].driver)"
    conftest = OPCUA_CONFTEST.replace("super().__init__(url, chart)", behind)
    assert conftest != OPCUA_CONFTEST
    (out / "conftest.py").write_text(conftest, encoding="utf-8")
    result = run_pytest(out, "-rs", "-k", "fault_01 or monitor_01")
    assert counts(result) == {"passed": 1, "skipped": 1}, result.stdout[-3000:]
    assert "the OPC UA address space shows no monitors" in result.stdout


def _returned(impl: Any, system: Any, then: Callable[[], object]) -> tuple[str, ...]:
    """The events ``impl`` reads over OPC UA for the Motor's way back to Blocked, after
    ``then`` sent it into Returning; the served System's simulated clock is moved."""
    deadline = time.monotonic() + 10
    then()
    while impl.states() != ("Returning",):
        assert time.monotonic() < deadline, impl.states()
        system.advance(0.1)
        time.sleep(0.01)
    system.advance(5.0)  # the twin arrives: a completion takes Returning to Blocked
    while impl.states() != ("Blocked",):
        assert time.monotonic() < deadline, impl.states()
        time.sleep(0.01)
    events: tuple[str, ...] = impl._events(("Returning",), ("Blocked",))
    return events


def test_the_opcua_adapter_reads_which_of_two_transitions_the_server_took() -> None:
    """Initialization completion and Error completion both take Returning to Blocked: the
    state change alone cannot tell them apart (the Hypothesis module against OPC UA failed
    on it); the machine's LastTransition can."""
    pytest.importorskip("asyncua")
    from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings
    from statectl.out.testgen.adapters.opcua import OpcuaImpl
    from statectl.run.devices import SimTwin
    from statectl.run.runtime import SimClock
    from statectl.run.system import DeviceSetup, System

    chart = load_chart(MOTOR)
    twin = SimTwin(chart)
    system = System((DeviceSetup("Motor", chart, driver=twin),), SimClock())
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    user, password = "tester", "a-long-password-1"
    url = f"opc.tcp://127.0.0.1:{port}"
    server = OpcuaServer(system, OpcuaSettings(url, user, password, ("None",)))
    server.start()
    system.start()
    server.refresh()
    halt = system.start_owner(paced=False)
    try:
        impl = OpcuaImpl(f"opc.tcp://{user}:{password}@127.0.0.1:{port}", chart, behind=twin)

        def error() -> None:
            impl.send("Movement")
            twin.inject_fault("stuck")

        assert _returned(impl, system, error) == ("Error completion",)

        def initialization() -> None:
            impl.send("Movement")
            while impl.states() != ("Blocked",):  # Movement completion, then back
                system.advance(0.5)
                time.sleep(0.01)
            impl.send("Initialization")

        assert _returned(impl, system, initialization) == ("Initialization completion",)
        impl.client.disconnect()
    finally:
        halt()
        server.stop()
        system.close()


# -- each kind of test catches its mutant -----------------------------------------------------

#: (what is wrong, conftest body, the test that must fail, what its message says)
DRIVERS = [
    (
        "the fault check never reports",
        "class Broken(SimTwin):\n    def poll_fault(self):\n        return None\n",
        "test_fault_01_moving",
        "raised: expected ['Error'], the device took []",
    ),
    (
        "the fault check always reports",
        "class Broken(SimTwin):\n    def poll_fault(self):\n        return 'stuck'\n",
        "test_monitor_01_moving",
        "the device took Error (a fault its monitor raised though none was reported) and is "
        "in ['Returning']",
    ),
    (
        "the completion is never reported",
        "class Broken(SimTwin):\n    def report(self, event, data=None):\n        pass\n",
        "test_completion_01_movement_after_movement",
        "expected the device to report Movement completion within 5 s; it reported nothing",
    ),
    (
        "the completion comes late",
        "class Broken(SimTwin):\n    def __init__(self, chart):\n"
        "        super().__init__(chart, delay=8.0)\n",
        "test_completion_01_movement_after_movement",
        "expected the device to report Movement completion within 5 s; it reported nothing",
    ),
]


@pytest.mark.parametrize(("bug", "body", "test", "message"), DRIVERS, ids=[d[0] for d in DRIVERS])
def test_a_driver_bug_fails_its_probe(
    tmp_path: Path, bug: str, body: str, test: str, message: str
) -> None:
    """The probe fails, naming what the device did, when a conftest supplies the bug."""
    _, out, _ = _motor(tmp_path)
    conftest = "import pytest\nfrom statectl.run.devices import SimTwin\n\n\n" + body
    conftest += "\n\n@pytest.fixture\ndef statectl_new_driver():\n    return Broken\n"
    (out / "conftest.py").write_text(conftest, encoding="utf-8")
    result = run_pytest(out, "-k", test)
    assert counts(result).get("failed") == 1, result.stdout[-3000:]
    assert message in result.stdout, result.stdout[-3000:]


#: (what is wrong, (text in motor.yaml, its replacement), the tests that must fail, message)
TABLES = [
    (
        "Moving lost monitoring required",
        (
            "control: [event trigger required, monitoring required]",
            "control: event trigger required",
        ),
        {"test_fault_01_moving", "test_monitor_01_moving"},
        "Moving requires monitoring, but no monitor runs there",
    ),
    (
        "the fault Error became a command",
        ("new: Returning\n    kind: fault", "new: Returning\n    kind: command"),
        {"test_fault_01_moving", "test_monitor_01_moving"},
        "raised: expected ['Error'], the device took []",
    ),
    (
        "Moving's recovery redoes instead of Error",
        ("  - state: Moving\n    event: Error\n    data: {detail: resumed after a restart}",
         "  - state: Moving\n    redo: yes"),
        {"test_recovery_01_moving"},
        "state: expected ['Returning'], device is in ['Moving']",
    ),
    (
        "Returning's redo rule is missing",
        ("  - state: Returning\n    redo: yes\n", ""),
        {"test_recovery_02_returning"},
        "invokes: expected [(2, 'Error')], issued []",
    ),
]  # fmt: skip


@pytest.mark.parametrize(("bug", "edit", "tests", "message"), TABLES, ids=[t[0] for t in TABLES])
def test_tables_the_runtime_runs_wrongly_fail_their_probe(
    tmp_path: Path, bug: str, edit: tuple[str, str], tests: set[str], message: str
) -> None:
    """Generated from the right tables, run on the runtime with one edited: those probes fail."""
    tables, out, _ = _motor(tmp_path)
    text = tables.read_text(encoding="utf-8")
    assert edit[0] in text
    tables.write_text(text.replace(edit[0], edit[1]), encoding="utf-8")
    result = run_pytest(out, "-k", " or ".join(sorted(PROBES)))
    failed = {line.split("::")[1].split(" ")[0] for line in result.stdout.splitlines()
              if line.startswith("FAILED")}  # fmt: skip
    assert failed == tests, result.stdout[-3000:]
    assert message in result.stdout, result.stdout[-3000:]


#: (what is wrong, the HandMotor subclass, what the failure names)
CLASSES = [
    (
        "a stray API call",
        """
        class Wrong(HandMotor):
            def _call(self, method, data):
                super()._call(method, data)
                if method == "Movement":
                    self.api.Error(None)
        """,
        "stray API call Error(): the tables make no such call here",
    ),
    (
        "a wrong argument",
        """
        class Wrong(HandMotor):
            def _call(self, method, data):
                super()._call(method, {"amount": 1} if method == "Movement" else data)
        """,
        "API call Movement({'amount': 1}): wrong argument, the tables give Movement()",
    ),
]


@pytest.mark.parametrize(("bug", "body", "message"), CLASSES, ids=[c[0] for c in CLASSES])
def test_api_calls_come_from_the_tables(tmp_path: Path, bug: str, body: str, message: str) -> None:
    """A class calling its API once too often or with other data fails, naming the call."""
    _, out, _ = _motor(tmp_path)
    shutil.copy(HAND, out / "hand_motor.py")
    module = "from hand_motor import HandMotor\n" + textwrap.dedent(body)
    (out / "wrong_motor.py").write_text(module, encoding="utf-8")
    result = run_pytest(out, "--statectl-impl", "python:wrong_motor:Wrong", "-k", "row_01")
    assert counts(result).get("failed") == 1, result.stdout[-3000:]
    assert message in result.stdout, result.stdout[-3000:]


# -- the adapters themselves -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("ros:x", "unknown kind 'ros'"),
        ("cpp:", "cpp needs what to test"),
        ("python:motor", "give python:MODULE:CLASS"),
        ("runtime:x", "runtime takes nothing after it"),
    ],
)
def test_a_bad_spec_says_what_to_give(spec: str, message: str) -> None:
    with pytest.raises(StatectlError, match=message):
        parse_spec(spec)


def test_a_bad_spec_fails_the_run_with_the_message(tmp_path: Path) -> None:
    """--statectl-impl with a module that does not exist: each test errs saying so."""
    _, out, _ = _motor(tmp_path)
    result = run_pytest(out, "--statectl-impl", "python:no_such_module:Motor", "-k", "row_01")
    assert counts(result) == {"error": 1}, result.stdout[-3000:]
    assert "cannot import 'no_such_module'" in result.stdout


def test_a_missing_program_is_a_clear_error(tmp_path: Path) -> None:
    from statectl.out.testgen.adapters.cpp import CppImpl

    with pytest.raises(StatectlError, match="no such executable"):
        CppImpl(str(tmp_path / "nothing"), load_chart(MOTOR))


def test_a_class_without_inject_fault_skips_the_fault_test() -> None:
    """What an implementation cannot do skips the test that needs it, saying why."""

    class Bare:
        def __init__(self, api: object) -> None:
            self.states = ("Blocked",)

        def send(self, event: str, data: object = None) -> str:
            return "declared ignored"

    d = DeviceUnderTest(load_chart(MOTOR), impl=PythonImpl(Bare))
    with pytest.raises(pytest.skip.Exception, match="Bare has no inject_fault"):
        d.fault()


def test_load_class_names_what_is_missing() -> None:
    with pytest.raises(StatectlError, match="module 'json' has no 'Nothing'"):
        load_class("json:Nothing")


def test_the_hypothesis_module_runs_on_another_implementation(tmp_path: Path) -> None:
    """--statectl-impl chooses the Hypothesis module's devices too: the hand-written class
    passes; with a stray API call it fails, naming the call."""
    from statectl.out.testgen.generator import generate_hypothesis

    generate_hypothesis(MOTOR, tmp_path)
    shutil.copy(HAND, tmp_path / "hand_motor.py")
    result = run_pytest(tmp_path, "--statectl-impl", "python:hand_motor:HandMotor")
    assert counts(result) == {"passed": 1}, result.stdout[-3000:]
    (tmp_path / "wrong_motor.py").write_text(
        "from hand_motor import HandMotor\n" + textwrap.dedent(CLASSES[0][1]), encoding="utf-8"
    )
    result = run_pytest(tmp_path, "--statectl-impl", "python:wrong_motor:Wrong")
    assert counts(result) == {"failed": 1}, result.stdout[-3000:]
    assert "stray API call Error()" in result.stdout
