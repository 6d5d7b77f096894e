"""C++ code generation: flat tables, diagnostics, the example, the CMake target."""

from __future__ import annotations

import filecmp
import io
import shutil
import subprocess
from pathlib import Path

import pytest

from codegen_support import CLANG, FLAGS, GXX, needs_gxx
from statectl.channels.cli.codegen import run_codegen
from statectl.channels.cli.demo import run_demo
from statectl.front.builder.build import load_chart
from statectl.kernel.errors import Severity
from statectl.kernel.model import (
    Assign,
    Chart,
    DataItem,
    EventDef,
    InvokeNumber,
    Log,
    Notify,
    Script,
    State,
    Transition,
)
from statectl.kernel.semantics import Unhandled
from statectl.out.codegen import flatten, generate
from statectl.out.codegen.cpp_names import identifiers
from statectl.out.codegen.flat import Decision, FlatStep

ROOT = Path(__file__).resolve().parent.parent
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"
EXAMPLE = ROOT / "examples" / "motor" / "cpp"


def _two_states(**changes: object) -> Chart:
    base: dict[str, object] = {
        "name": "Dev",
        "states": (State("A"), State("B")),
        "transitions": (Transition("A", ("go",), ("B",)),),
        "initial": ("A",),
        "events": (EventDef("go"),),
    }
    base.update(changes)
    return Chart(**base)  # type: ignore[arg-type]


def test_motor_flattens_to_six_configurations() -> None:
    """The Motor's states times the previous state its guard reads: six configurations."""
    flat, diags = flatten(load_chart(MOTOR))
    assert flat is not None and diags == []
    labels = [c.label for c in flat.configurations]
    assert labels == [
        "Blocked (previous -)",
        "Moving (previous Blocked)",
        "Blocked (previous Moving)",
        "Returning (previous Moving)",
        "Returning (previous Blocked)",
        "Blocked (previous Returning)",
    ]
    assert flat.guards == ()  # previous == 'Moving' is decided per configuration


@pytest.mark.parametrize(
    ("config", "event", "expected"),
    [
        (0, "Initialization", Unhandled.DECLARED_IGNORED),  # guard false: ignored as listed
        (2, "Initialization", None),
        (0, "Error", Unhandled.DECLARED_IGNORED),
    ],
)
def test_motor_outcomes_say_why_unhandled(
    config: int, event: str, expected: Unhandled | None
) -> None:
    """An unhandled event keeps the Python Subject's reason."""
    flat, _ = flatten(load_chart(MOTOR))
    assert flat is not None
    cell = flat.dispatch[config][flat.events.index(event)]
    assert isinstance(cell, FlatStep) and cell.unhandled is expected


def test_guard_over_context_becomes_a_runtime_decision() -> None:
    """A guard reading an int context field is a Decision evaluated in C++."""
    chart = _two_states(
        transitions=(Transition("A", ("go",), ("B",), guard="limit > 2"),),
        data=(DataItem("limit", "3"),),
    )
    flat, diags = flatten(chart)
    assert flat is not None and diags == []
    cell = flat.dispatch[0][0]
    assert isinstance(cell, Decision)
    assert [g.cpp for g in flat.guards] == ["(V(((c.limit) > (V(2))))) != 0"]
    assert [(f.name, f.initial) for f in flat.context] == [("limit", 3)]


@pytest.mark.parametrize(
    ("changes", "code"),
    [
        ({"transitions": (Transition("A", ("go",), ("B",), actions=(Script("x = 1"),)),)}, "G701"),
        ({"transitions": (Transition("A", ("go",), ("B",), actions=(Assign("x", "1"),)),)}, "G713"),
        (
            {
                "transitions": (Transition("A", ("go",), ("B",), guard="n // 2 > 0"),),
                "data": (DataItem("n", "4"),),
            },
            "G702",
        ),
        (
            {
                "transitions": (Transition("A", ("go",), ("B",), guard="_event.data > 1"),),
                "data": (DataItem("n", "4"),),
            },
            "G703",
        ),
        (
            {
                "transitions": (Transition("A", ("go",), ("B",), guard="name == 'x'"),),
                "data": (DataItem("name", "'y'"),),
            },
            "G704",
        ),
        ({"datamodel": "python"}, "G705"),
        ({"transitions": (Transition("A", ("go",), ("B",), actions=(Log("hello"),)),)}, "G708"),
        (
            {
                "transitions": (
                    Transition("A", ("go",), ("B",), actions=(Notify(7, "X", "Y", "go"),)),
                ),
                "invokes": (InvokeNumber(0, "Z", "Zed"),),
            },
            "G709",
        ),
    ],
)
def test_unsupported_constructs_are_diagnosed(changes: dict[str, object], code: str) -> None:
    """What generated C++ cannot do is a G7xx diagnostic, never dropped in silence."""
    chart = _two_states(**changes)
    _, diags = flatten(chart)
    assert code in [d.code for d in diags], [str(d) for d in diags]


def test_generate_writes_nothing_on_error(tmp_path: Path) -> None:
    """With an error diagnostic no file is written."""
    chart = _two_states(transitions=(Transition("A", ("go",), ("B",), actions=(Script("x = 1"),)),))
    written, diags = generate(chart, tmp_path)
    assert written == [] and any(d.severity is Severity.ERROR for d in diags)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("names", "lower", "expected"),
    [
        (["Movement completion", "Error"], False, ["MovementCompletion", "Error"]),
        (["a b", "a-b", "class"], False, ["AB", "AB2", "Class"]),
        (["Random Dev", "1st"], True, ["random_dev", "s_1st"]),
    ],
)
def test_identifiers_are_distinct_cpp_names(
    names: list[str], lower: bool, expected: list[str]
) -> None:
    """Names become distinct C++ identifiers."""
    assert list(identifiers(names, lower=lower).values()) == expected


def test_regenerating_the_example_gives_identical_files(tmp_path: Path) -> None:
    """examples/motor/cpp/generated is exactly what codegen writes for motor.yaml."""
    written, _ = generate(load_chart(MOTOR), tmp_path)
    rels = sorted(str(p.relative_to(tmp_path)) for p in written)
    committed = sorted(
        str(p.relative_to(EXAMPLE / "generated"))
        for p in (EXAMPLE / "generated").rglob("*")
        if p.is_file()
    )
    assert rels == committed
    _, mismatch, errors = filecmp.cmpfiles(tmp_path, EXAMPLE / "generated", rels, shallow=False)
    assert mismatch == [] and errors == []


def test_run_codegen_reports_unknown_target(tmp_path: Path) -> None:
    """`statectl codegen --target` other than cpp is a usage error (exit 2)."""
    err = io.StringIO()
    assert run_codegen(str(MOTOR), str(tmp_path), "rust", io.StringIO(), err) == 2
    assert "available: cpp" in err.getvalue()


def test_run_codegen_writes_the_files(tmp_path: Path) -> None:
    """`statectl codegen FILE --target cpp --out DIR` lists what it wrote and exits 0."""
    out = io.StringIO()
    assert run_codegen(str(MOTOR), str(tmp_path), "cpp", out, io.StringIO()) == 0
    assert (tmp_path / "motor.hpp").exists() and "motor.hpp" in out.getvalue()


def _compile(compiler: str, src: Path, include: Path, out: Path, *extra: str) -> None:
    cmd = [compiler, *FLAGS, "-O1", *extra, "-I", str(include), str(src), "-o", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr


@needs_gxx
def test_example_prints_the_same_trace_as_statectl_demo(tmp_path: Path) -> None:
    """The C++ Motor example on its simulated motor prints `statectl demo`'s trace."""
    assert GXX is not None
    binary = tmp_path / "demo"
    _compile(GXX, EXAMPLE / "demo.cpp", EXAMPLE / "generated", binary, "-DSTATECTL_TRACE=1")
    got = subprocess.run([str(binary)], capture_output=True, text=True, check=True).stdout
    expected = io.StringIO()
    run_demo(expected)
    assert got == expected.getvalue()


@pytest.mark.parametrize("compiler", [GXX, CLANG], ids=["g++", "clang++"])
@pytest.mark.parametrize("trace", ["0", "1"])
def test_generated_motor_is_warning_free(tmp_path: Path, compiler: str | None, trace: str) -> None:
    """The generated check program builds with -Wall -Wextra -Wpedantic -Werror."""
    if compiler is None:
        pytest.skip("compiler not found on this machine")
    generate(load_chart(MOTOR), tmp_path)
    binary = tmp_path / "check"
    _compile(compiler, tmp_path / "motor_check.cpp", tmp_path, binary, f"-DSTATECTL_TRACE={trace}")
    out = subprocess.run([str(binary)], capture_output=True, text=True, check=True).stdout
    assert out.startswith("Motor: configuration")


@pytest.mark.skipif(shutil.which("cmake") is None or GXX is None, reason="cmake or g++ missing")
def test_example_configures_and_builds_with_cmake(tmp_path: Path) -> None:
    """examples/motor/cpp (add_subdirectory of the generated target) configures and builds."""
    build = tmp_path / "build"
    for cmd in (
        ["cmake", "-S", str(EXAMPLE), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release"],
        ["cmake", "--build", str(build), "-j", "2"],
    ):
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        assert done.returncode == 0, done.stdout + done.stderr
    assert (build / "motor_demo").exists()
    assert (build / "generated" / "motor_check").exists()


@pytest.mark.skipif(shutil.which("cmake") is None or GXX is None, reason="cmake or g++ missing")
def test_installed_target_is_found_with_find_package(tmp_path: Path) -> None:
    """The generated target installs, and another project links it with find_package()."""
    generated, prefix, consumer = tmp_path / "gen", tmp_path / "prefix", tmp_path / "app"
    generate(load_chart(MOTOR), generated)
    consumer.mkdir()
    (consumer / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.16)\nproject(app LANGUAGES CXX)\n"
        "find_package(motor CONFIG REQUIRED)\nadd_executable(app main.cpp)\n"
        "target_link_libraries(app PRIVATE statectl::motor)\n",
        encoding="utf-8",
    )
    (consumer / "main.cpp").write_text(
        '#include "motor.hpp"\nint main() { motor::Motor device; device.start();\n'
        "  return device.in(motor::State::Blocked) ? 0 : 1; }\n",
        encoding="utf-8",
    )
    steps = (
        [
            "cmake",
            "-S",
            str(generated),
            "-B",
            str(tmp_path / "b1"),
            f"-DCMAKE_INSTALL_PREFIX={prefix}",
            "-DSTATECTL_MOTOR_CHECK=OFF",
        ],
        ["cmake", "--build", str(tmp_path / "b1")],
        ["cmake", "--install", str(tmp_path / "b1")],
        ["cmake", "-S", str(consumer), "-B", str(tmp_path / "b2"), f"-DCMAKE_PREFIX_PATH={prefix}"],
        ["cmake", "--build", str(tmp_path / "b2")],
        [str(tmp_path / "b2" / "app")],
    )
    for cmd in steps:
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        assert done.returncode == 0, " ".join(cmd) + "\n" + done.stdout + done.stderr


_CONTRACTS = r"""
#include "motor.hpp"

#include <cstdlib>
#include <cstring>

namespace {

motor::Motor device;

// Movement(): re-enters dispatch (a contract fault) or posts (the supported path).
class Api final : public motor::MotorApi {
 public:
  bool reenter = false;
  int calls = 0;
  void Movement() noexcept override {
    ++calls;
    if (reenter) {
      device.dispatch(motor::Event::Error);
    } else {
      static_cast<void>(device.post(motor::Event::Error));
    }
  }
  void Initialization() noexcept override { ++calls; }
  void Error() noexcept override { ++calls; }
};

}  // namespace

int main(int argc, char** argv) {
  const char* what = argc > 1 ? argv[1] : "";
  Api api;
  device.attach(api, motor::Invoke::Moving);
  device.attach(api, motor::Invoke::Error);
  api.reenter = std::strcmp(what, "reenter") == 0;
  if (std::strcmp(what, "before-start") != 0) {
    device.start();
  }
  if (std::strcmp(what, "start-twice") == 0) {
    device.start();
  }
  if (std::strcmp(what, "out-of-range") == 0) {
    device.dispatch(static_cast<motor::Event>(motor::kEventCount));
  }
  device.dispatch(motor::Event::Movement);
  const std::size_t ran = device.run_until_idle();
  std::printf("ok %d %zu %d\n", api.calls, ran, device.in(motor::State::Returning) ? 1 : 0);
  return 0;
}
"""


@pytest.fixture(scope="module")
def contracts_binary(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if GXX is None:
        pytest.skip("no g++ on this machine")
    out = tmp_path_factory.mktemp("contracts")
    generate(load_chart(MOTOR), out)
    (out / "contracts.cpp").write_text(_CONTRACTS)
    binary = out / "contracts"
    cmd = [
        GXX,
        *FLAGS,
        "-O2",
        "-DNDEBUG",
        "-I",
        str(out),
        str(out / "contracts.cpp"),
        "-o",
        str(binary),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return binary


@pytest.mark.parametrize(
    ("scenario", "stderr"),
    [
        ("out-of-range", "statectl contract 101 failed: dispatch: event out of range"),
        (
            "reenter",
            "statectl contract 102 failed: dispatch: re-entered from an observer or "
            "hook; post() instead",
        ),
        ("before-start", "statectl contract 103 failed: dispatch: call start() first"),
        ("start-twice", "statectl contract 104 failed: start: the device was started already"),
    ],
)
def test_contract_checks_fire_in_release_builds(
    contracts_binary: Path, scenario: str, stderr: str
) -> None:
    """Each folded dispatch check still names its number and reason at -O2 -DNDEBUG."""
    done = subprocess.run(
        [str(contracts_binary), scenario], capture_output=True, text=True, check=False
    )
    assert done.returncode != 0 and done.stdout == ""
    assert done.stderr.strip() == stderr


def test_post_from_an_observer_runs_after_the_step(contracts_binary: Path) -> None:
    """post() during dispatch is the supported path: the event runs in run_until_idle()."""
    done = subprocess.run(
        [str(contracts_binary), "post"], capture_output=True, text=True, check=True
    )
    assert done.stdout == "ok 2 1 1\n"  # Movement() then Error(); one queued event; Returning


@needs_gxx
@pytest.mark.parametrize(
    "chart",
    [
        _two_states(
            transitions=(
                Transition("A", ("go",), ("B",), guard="limit > 2"),
                Transition("A", ("go",), ("A",), guard="limit < 0"),
            ),
            data=(DataItem("limit", "3"),),
        ),
        _two_states(transitions=(), events=()),
    ],
    ids=["runtime-guards", "no-events"],
)
def test_release_build_of_edge_charts_is_warning_free(tmp_path: Path, chart: Chart) -> None:
    """Guard-decision trees and a chart without events build at -O2 with -Werror."""
    assert GXX is not None
    generate(chart, tmp_path)
    binary = tmp_path / "check"
    cmd = [
        GXX,
        *FLAGS,
        "-O2",
        "-DNDEBUG",
        "-I",
        str(tmp_path),
        str(tmp_path / "dev_check.cpp"),
        "-o",
        str(binary),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    out = subprocess.run([str(binary)], capture_output=True, text=True, check=True).stdout
    assert out.startswith("Dev: configuration")
