"""C++ code generation: flat tables, diagnostics, the example, the CMake target."""

from __future__ import annotations

import filecmp
import io
import shutil
import subprocess
from pathlib import Path

import pytest

from codegen_support import CLANG, FLAGS, GXX, needs_gxx
from statectl.build import load_chart
from statectl.codegen import flatten, generate, run_codegen
from statectl.codegen.flatten import Decision, Outcome, Unhandled, identifiers
from statectl.demo import run_demo
from statectl.errors import Severity
from statectl.model import (
    Assign,
    Chart,
    DataItem,
    EventDef,
    Invoke,
    Log,
    Notify,
    Script,
    State,
    Transition,
)

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
        "Blocked (previous -)", "Moving (previous Blocked)", "Blocked (previous Moving)",
        "Returning (previous Moving)", "Returning (previous Blocked)",
        "Blocked (previous Returning)",
    ]
    assert flat.guards == ()  # previous == 'Moving' is decided per configuration


@pytest.mark.parametrize(
    ("config", "event", "expected"),
    [
        (0, "Initialization", Unhandled.GUARD_FALSE),
        (2, "Initialization", Unhandled.NONE),
        (0, "Error", Unhandled.DECLARED_IGNORED),
    ],
)
def test_motor_outcomes_say_why_unhandled(config: int, event: str, expected: Unhandled) -> None:
    """An unhandled event keeps the Python Subject's reason."""
    flat, _ = flatten(load_chart(MOTOR))
    assert flat is not None
    cell = flat.dispatch[config][flat.events.index(event)]
    assert isinstance(cell, Outcome) and cell.unhandled is expected


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
        ({"transitions": (Transition("A", ("go",), ("B",), actions=(Script("x = 1"),)),)},
         "G701"),
        ({"transitions": (Transition("A", ("go",), ("B",), actions=(Assign("x", "1"),)),)},
         "G701"),
        ({"transitions": (Transition("A", ("go",), ("B",), guard="n // 2 > 0"),),
          "data": (DataItem("n", "4"),)}, "G702"),
        ({"transitions": (Transition("A", ("go",), ("B",), guard="_event.data > 1"),),
          "data": (DataItem("n", "4"),)}, "G703"),
        ({"transitions": (Transition("A", ("go",), ("B",), guard="name == 'x'"),),
          "data": (DataItem("name", "'y'"),)}, "G704"),
        ({"datamodel": "python"}, "G705"),
        ({"transitions": (Transition("A", ("go",), ("B",), actions=(Log("hello"),)),)},
         "G708"),
        ({"transitions": (Transition("A", ("go",), ("B",), actions=(Notify(7, "X", "Y", "go"),)),),
          "invokes": (Invoke(0, "Z", "Zed"),)}, "G709"),
    ],
)
def test_unsupported_constructs_are_diagnosed(changes: dict[str, object], code: str) -> None:
    """What generated C++ cannot do is a G7xx diagnostic, never dropped in silence."""
    chart = _two_states(**changes)
    _, diags = flatten(chart)
    assert code in [d.code for d in diags], [str(d) for d in diags]


def test_generate_writes_nothing_on_error(tmp_path: Path) -> None:
    """With an error diagnostic no file is written."""
    chart = _two_states(
        transitions=(Transition("A", ("go",), ("B",), actions=(Script("x = 1"),)),)
    )
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
def test_identifiers_are_distinct_cpp_names(names: list[str], lower: bool,
                                            expected: list[str]) -> None:
    """Names become distinct C++ identifiers."""
    assert list(identifiers(names, lower=lower).values()) == expected


def test_regenerating_the_example_gives_identical_files(tmp_path: Path) -> None:
    """examples/motor/cpp/generated is exactly what codegen writes for motor.yaml."""
    written, _ = generate(load_chart(MOTOR), tmp_path)
    rels = sorted(str(p.relative_to(tmp_path)) for p in written)
    committed = sorted(
        str(p.relative_to(EXAMPLE / "generated"))
        for p in (EXAMPLE / "generated").rglob("*") if p.is_file()
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
def test_generated_motor_is_warning_free(tmp_path: Path, compiler: str | None,
                                         trace: str) -> None:
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
