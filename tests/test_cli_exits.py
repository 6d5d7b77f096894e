"""Ordinary mistakes end in a clear message and an exit code that tells the truth.

Every case runs the real command line in a subprocess (so a traceback, a hang or
a stray temporary file is seen as a user would see it): exit 1 for bad input or
a failed run, 2 for a usage error, never a traceback, nothing half-written.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

from statectl.channels.runconfig import load_run_config
from statectl.front.builder.build import load_and_build
from statectl.kernel.errors import StatectlError
from statectl.run.devices import make_driver
from statectl.run.runtime import SimClock, Subject

ROOT = Path(__file__).resolve().parents[1]
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"
PICK = ROOT / "examples" / "pick-and-place"
GRIPPER = PICK / "gripper.yaml"
CELL = PICK / "cell.yaml"
BUGGY = PICK / "cell-buggy.yaml"


def statectl(argv: list[str], tmp: Path, stdin: str = "") -> subprocess.CompletedProcess[str]:
    """Run ``statectl ARGV`` with ``{tmp}`` and ``{file}`` (an existing file) filled in."""
    existing = tmp / "existing.txt"
    existing.write_text("keep me\n", encoding="utf-8")
    args = [a.format(tmp=tmp, file=existing) for a in argv]
    return subprocess.run(
        [sys.executable, "-m", "statectl", *args],
        input=stdin,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )


CASES = [
    # (argv, stdin, exit code, text expected on stderr)
    (["codegen", str(MOTOR), "--out", "{file}"], "", 1, "T110"),
    (["codegen", str(MOTOR), "--out", "{file}/sub"], "", 1, "T110"),
    (["scxml", "export", str(MOTOR), "--out", "{file}/x.scxml"], "", 1, "T110"),
    (["verify", str(BUGGY), "--traces", "{file}"], "", 1, "T110"),
    (["verify", str(CELL), "--export", "promela", "-o", "{file}/x.pml"], "", 1, "T110"),
    (["run", str(MOTOR), "--dashboard", "--port", "99999"], "", 2, "--port"),
    (["run", str(MOTOR), "--opcua", "http://127.0.0.1:4840"], "", 2, "--opcua"),
    (["run", str(CELL), "--walk", "-5"], "", 2, "--walk must be 0 or more"),
    (["journal", "export", "{tmp}/j.db", "-o", "{file}/x.jsonl"], "", 1, "is not a directory"),
    (["testgen", str(MOTOR), "--out", "{file}/x"], "", 1, "cannot write"),
    (["run", str(MOTOR)], "Movement {amount: \n", 1, "line 1:"),
    (["run", str(MOTOR)], "Movement {amount: 5}\nNoSuch: Movement\n", 1, "line 2:"),
    (["run", str(MOTOR)], "Bogus\n", 1, "unknown"),
    (["run", str(GRIPPER), "--driver", "sim-motor"], "Grip\n", 1, "Grip(), Release()"),
]


@pytest.mark.parametrize(("argv", "stdin", "code", "says"), CASES)
def test_mistake_ends_cleanly(
    argv: list[str], stdin: str, code: int, says: str, tmp_path: Path
) -> None:
    """A mistake gives its message and exit code, no traceback, no file left half-written."""
    if "{tmp}/j.db" in argv:
        journal = tmp_path / "j.db"
        statectl(["run", str(MOTOR), "--journal", str(journal)], tmp_path, "Movement\n")
        # the journal is an input of the case, not something it wrote: move it aside
        journal.rename(tmp_path.parent / f"{tmp_path.name}-j.db")
        argv = [
            a.replace("{tmp}/j.db", str(tmp_path.parent / f"{tmp_path.name}-j.db")) for a in argv
        ]
    done = statectl(argv, tmp_path, stdin)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == code, done.stderr
    assert says in done.stderr, done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing.txt"]
    assert (tmp_path / "existing.txt").read_text(encoding="utf-8") == "keep me\n"


#: A device whose name is too long for a file name (codegen and testgen name files after it).
LONG_NAMED = MOTOR.read_text(encoding="utf-8").replace("device: Motor", "device: " + "M" * 300)

BAD_FILES = [
    # codegen and testgen cap the file names they make from a name at 64 characters
    # (docs/limits.md), so a long device name writes there: tests/test_escape.py
    ("m.yaml", LONG_NAMED, ["render", "{input}", "--out", "out/diagrams/"], 1, "T110"),
    ("m.yaml", LONG_NAMED, ["tables", "{input}", "--to", "csv", "--out", "out/csv/"], 1, "T108"),
    # (name, content of an input file in tmp, argv naming it as {input}, exit code, stderr says)
    ("t.json", "{\n", ["run", str(CELL), "--replay", "{input}"], 1, "t.json:2: T101"),
    ("t.json", "steps: 3\n", ["run", str(CELL), "--replay", "{input}"], 1, "'steps:' (a list)"),
    (
        "t.json",
        "steps: [{to: gripper, event: Grip, deliveries: 5}]\n",
        ["run", str(CELL), "--replay", "{input}"],
        1,
        "step 1: 'deliveries' must be a list",
    ),
    (
        "t.json",
        "steps: [{to: gripper, event: Grip, source: link}]\n",
        ["run", str(CELL), "--replay", "{input}"],
        1,
        "step 1: source must be one of",
    ),
]


@pytest.mark.parametrize(("name", "content", "argv", "code", "says"), BAD_FILES)
def test_bad_input_file_ends_cleanly(
    name: str, content: str, argv: list[str], code: int, says: str, tmp_path: Path
) -> None:
    """A malformed input file is bad input: its message, exit 1, no traceback, nothing written."""
    (tmp_path / name).write_text(content, encoding="utf-8")
    done = statectl([a.replace("{input}", name) for a in argv], tmp_path)
    assert "Traceback" not in done.stderr, done.stderr
    assert (done.returncode, says in done.stderr) == (code, True), done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["existing.txt", name])


NOT_REGULAR = [
    # (argv naming {fifo}, a FIFO whose name has the suffix the command expects)
    ["check", "{fifo}.yaml"],
    ["check", "{fifo}.md"],
    ["check", "{fifo}.xlsx"],
    ["check", "{fifo}.states.csv"],
    ["build", "{fifo}.yaml"],
    ["codegen", "{fifo}.yaml", "--out", "{tmp}/out"],
    ["testgen", "{fifo}.yaml", "--out", "{tmp}/out"],
    ["verify", "{tmp}/cell.yaml"],
    ["run", str(MOTOR), "--config", "{fifo}.yaml"],
    ["coverage", "{fifo}.db", str(MOTOR)],
    ["coverage", "{fifo}.json", str(MOTOR)],
    ["scxml", "run", "{fifo}.scxml"],
    ["scxml", "import", "{fifo}.scxml"],
    ["scxml", "export", "{fifo}.yaml"],
]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
@pytest.mark.parametrize("argv", NOT_REGULAR)
def test_a_fifo_for_an_input_file_is_refused_unread(argv: list[str], tmp_path: Path) -> None:
    """A FIFO named like an input file is exit 1, 'not a regular file': no read that hangs."""
    fifo = tmp_path / "f"
    for arg in argv:
        if "{fifo}" in arg:
            os.mkfifo(arg.format(fifo=fifo, tmp=tmp_path))
    (tmp_path / "f.events.csv").write_text("event,old,new\n", encoding="utf-8")
    (tmp_path / "cell.yaml").write_text("cell: C\ndevices:\n  a: f.yaml\n", encoding="utf-8")
    if "{tmp}/cell.yaml" in argv:
        os.mkfifo(tmp_path / "f.yaml")
    args = [a.format(fifo=fifo, tmp=tmp_path) for a in argv]
    done = subprocess.run(
        [sys.executable, "-m", "statectl", *args],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=60,  # without the check the read waits for a writer that never comes
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    text = done.stdout + done.stderr
    assert "Traceback" not in text, text
    assert (done.returncode, "not a regular file" in text) == (1, True), text
    assert not (tmp_path / "out").exists()


def test_clean_run_exits_0(tmp_path: Path) -> None:
    """A batch run whose every line was accepted exits 0 (the rule 9 count starts at zero)."""
    done = statectl(["run", str(MOTOR)], tmp_path, "Movement {amount: 5}\n+2\n")
    assert (done.returncode, done.stderr) == (0, "")


def test_driver_mismatch_is_refused_before_anything_runs(tmp_path: Path) -> None:
    """A driver lacking a method the chart calls starts nothing: no state entered, no trace."""
    done = statectl(["run", str(GRIPPER), "--driver", "sim-motor"], tmp_path, "Grip\n")
    assert "enter" not in done.stdout and "final state" not in done.stdout, done.stdout
    assert "available: Error(), Initialization(), Movement()" in done.stderr


@pytest.mark.parametrize(
    ("argv", "db"),
    [
        (["run", str(MOTOR)], False),
        (["journal", "export", "{tmp}/j.db"], True),
        (["journal", "show", "{tmp}/j.db"], True),
        (["verify", str(CELL), "--json"], False),
    ],
)
def test_closed_pipe_ends_quietly(argv: list[str], db: bool, tmp_path: Path) -> None:
    """A reader that stops early (``| head -1``) ends the command quietly: no traceback."""
    lines = "Movement {amount: 5}\n+2\n" * 400
    if db:
        statectl(["run", str(MOTOR), "--journal", "{tmp}/j.db"], tmp_path, lines)
    args = [a.format(tmp=tmp_path) for a in argv]
    proc = subprocess.Popen(
        [sys.executable, "-m", "statectl", *args],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    assert proc.stdin is not None and proc.stdout is not None and proc.stderr is not None
    proc.stdin.write(lines if not db else "")
    proc.stdin.close()
    assert proc.stdout.readline()  # the reader takes one line and goes away
    proc.stdout.close()
    err = proc.stderr.read()
    code = proc.wait(timeout=120)
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert code in (0, 141), err  # 141: as if ended by SIGPIPE, as a shell tool would be


def _subject(path: Path) -> Subject:
    chart, diags = load_and_build(str(path))
    assert chart is not None, diags
    return Subject(chart, clock=SimClock(), name=chart.name)


SHIPPED = [
    (MOTOR, "sim-motor", None),
    (MOTOR, "sim-stepper", None),
    (MOTOR, "cia402-sim", None),
    (MOTOR, "cia402", ROOT / "examples" / "motor" / "cia402-socketcan.yaml"),
    (GRIPPER, "modbus", PICK / "gripper-modbus.yaml"),
    *(
        (ROOT / "examples" / "modbus" / "clamp.yaml", "modbus", ROOT / "examples" / "modbus" / c)
        for c in ("clamp-tcp.yaml", "clamp-rtu.yaml")
    ),
    (ROOT / "examples" / "motor" / "axis-cia402.yaml", "cia402-sim", None),
    (
        ROOT / "examples" / "motor" / "axis-cia402.yaml",
        "cia402",
        ROOT / "examples" / "motor" / "axis-cia402-socketcan.yaml",
    ),
    *((PICK / f"{name}.yaml", "sim-twin", None) for name in ("arm", "conveyor", "sensor")),
    (GRIPPER, "sim-twin", None),
]


@pytest.mark.parametrize(("device", "driver", "config"), SHIPPED)
def test_shipped_drivers_serve_their_charts(device: Path, driver: str, config: Path | None) -> None:
    """Each shipped driver serves every observer method of the chart it is used with."""
    subject = _subject(device)
    options = None
    if config is not None:
        drivers = load_run_config(str(config)).drivers
        assert drivers is not None
        name, options = drivers[subject.name]
        assert name == driver
    from statectl.run.devices.base import check_serves

    made = make_driver(driver, options, chart=subject.chart)
    check_serves(subject, made)  # raises when a method is missing
    assert set(made.serves()) >= {i.method for i in subject.chart.invokes}  # type: ignore[attr-defined]


def test_check_serves_names_missing_and_available() -> None:
    """The bind-time check names the missing methods and the ones the driver has."""
    from statectl.run.devices.base import check_serves

    subject = _subject(GRIPPER)
    with pytest.raises(StatectlError, match=r"Grip\(\), Release\(\).*available: Error\(\)"):
        check_serves(subject, make_driver("sim-motor"))


MISSING = [
    # (argv naming an input file that does not exist, the words that say so)
    (["check", "{gone}"], "no such file"),
    (["build", "{gone}"], "no such file"),
    (["observers", "{gone}"], "no such file"),
    (["render", "{gone}"], "no such file"),
    (["tables", "{gone}", "--to", "csv"], "no such file"),
    (["codegen", "{gone}", "--out", "{tmp}/out"], "no such file"),
    (["verify", "{gone}"], "no such file"),
    (["run", "{gone}"], "no such file"),
    (["run", str(MOTOR), "--config", "{gone}"], "no such file"),
    (["run", str(CELL), "--replay", "{gone}"], "no such trace file"),
    (["demo", "--config", "{gone}"], "no such file"),
    (["journal", "show", "{gone}"], "no journal at"),
    (["journal", "export", "{gone}"], "no journal at"),
    (["journal", "replay", "{gone}"], "no journal at"),
    (["journal", "ship", "{gone}", "--to", "postgresql://127.0.0.1:1/x"], "no journal at"),
    (["scxml", "run", "{gone}"], "no such file"),
    (["scxml", "import", "{gone}"], "no such file"),
    (["scxml", "export", "{gone}"], "no such file"),
    (["testgen", "{gone}", "--out", "{tmp}/out"], "no such file"),
    (["coverage", "{gone}", str(MOTOR)], "no such file"),
    (["coverage", str(MOTOR), "{gone}"], "no such file"),
    (["node", "{gone}", "--node", "a"], "statectl node: "),
    (["dashboard", "{gone}"], "statectl dashboard: "),
]


@pytest.mark.parametrize(("argv", "says"), MISSING)
def test_missing_input_is_exit_2(argv: list[str], says: str, tmp_path: Path) -> None:
    """A missing input file is exit 2 in every command (README: usage error), never 1."""
    gone = tmp_path / "gone.yaml"
    done = statectl([a.replace("{gone}", str(gone)) for a in argv], tmp_path)
    assert "Traceback" not in done.stderr, done.stderr
    assert (done.returncode, says in done.stderr) == (2, True), done.stderr
    assert str(gone) in done.stderr, done.stderr


OVERWRITES_INPUT = [
    # (argv naming the input {in} again as the output)
    ["render", "{in}", "--out", "{in}"],
    ["render", "{in}", "--format", "svg", "--out", "./{in}"],
    ["scxml", "export", "{in}", "--out", "{in}"],
    ["tables", "{in}", "--to", "yaml", "--out", "{in}"],
    ["tables", "{in}", "--to", "md", "--out", "{in}"],
    ["verify", "{cell}", "--export", "promela", "-o", "{cell}"],
    ["journal", "export", "{db}", "-o", "{db}"],
]


@pytest.mark.parametrize("argv", OVERWRITES_INPUT)
def test_an_output_that_is_the_input_is_refused(argv: list[str], tmp_path: Path) -> None:
    """--out naming the input file is a usage error (exit 2): the input stays as it was."""
    device = tmp_path / "m.yaml"
    device.write_text(MOTOR.read_text(encoding="utf-8"), encoding="utf-8")
    cell = tmp_path / "c.yaml"
    cell.write_text("cell: C\ndevices:\n  m: m.yaml\n", encoding="utf-8")
    db = tmp_path / "j.db"
    if "{db}" in argv:
        statectl(["run", str(MOTOR), "--journal", str(db)], tmp_path, "Movement\n")
    (tmp_path / "existing.txt").write_text("keep me\n", encoding="utf-8")  # as statectl() does
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    args = [
        a.replace("{in}", "m.yaml").replace("{cell}", "c.yaml").replace("{db}", "j.db")
        for a in argv
    ]
    done = statectl(args, tmp_path)
    assert "Traceback" not in done.stderr, done.stderr
    assert (done.returncode, "is an input of this command" in done.stderr) == (2, True), done.stderr
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before


def test_missing_input_table_covers_every_command() -> None:
    """Every command of the parser appears in the missing-input table (a new one must too)."""
    import argparse

    from statectl.channels.cli import build_parser

    def commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...]) -> set[tuple[str, ...]]:
        found: set[tuple[str, ...]] = set()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    found |= commands(sub, (*prefix, name)) or {(*prefix, name)}
        return found

    listed = {tuple(a for a in argv[:2] if a.isalpha()) for argv, _ in MISSING}
    listed |= {(argv[0],) for argv, _ in MISSING}
    assert commands(build_parser(), ()) - TAKES_NO_INPUT <= listed


#: Commands that read no input file: they list or write from what the package ships (or,
#: lsp, read what an editor sends).
TAKES_NO_INPUT = {("profiles",), ("new",), ("schema",), ("lsp",)}


MOTOR_XLSX = ROOT / "examples" / "motor" / "motor.xlsx"
RUN_CONFIG = ROOT / "examples" / "motor" / "drivers.yaml"

WRONG_KIND = [
    # (argv, the code, the command it points to)
    (["check", str(CELL)], "C415", f"use statectl verify {CELL}"),
    (["check", str(MOTOR), str(CELL)], "C415", f"use statectl verify {CELL}"),
    (["check", str(RUN_CONFIG)], "C415", f"use statectl run MODEL --config {RUN_CONFIG}"),
    (["verify", str(MOTOR)], "C416", f"use statectl check {MOTOR}"),
    (["verify", str(MOTOR_XLSX)], "C416", f"use statectl check {MOTOR_XLSX}"),
    (["verify", "{tmp}/m.scxml"], "C416", "use statectl scxml run"),
]


@pytest.mark.parametrize(("argv", "code", "says"), WRONG_KIND)
def test_a_file_of_the_other_kind_says_which_command_takes_it(
    argv: list[str], code: str, says: str, tmp_path: Path
) -> None:
    """check on a cell / verify on a device file: one diagnostic naming the command, exit 1."""
    if "{tmp}/m.scxml" in argv:
        done = statectl(
            ["scxml", "export", str(MOTOR), "--out", str(tmp_path / "m.scxml")], tmp_path
        )
        assert done.returncode == 0, done.stderr
    done = statectl(argv, tmp_path)
    text = done.stdout + done.stderr
    assert "Traceback" not in text
    assert done.returncode == 1, text
    assert [line for line in text.splitlines() if f" {code} error: " in line and says in line], text
    assert "V802" not in text and "T102" not in text, text


VALVE = """\
from typing import ClassVar

from statectl.run.devices import Driver


class Valve(Driver):
    methods: ClassVar[dict[str, str]] = {"Grip": "close", "Release": "open"}
    completions: ClassVar[dict[str, str]] = {"Grip": "Grip completion"}

    def close(self) -> None:
        self.log_call("close")
        self.complete("Grip")

    def open(self) -> None:
        self.log_call("open")
"""


@pytest.mark.parametrize("where", ["model", "config"])
def test_a_driver_module_beside_the_model_or_config_is_found(where: str, tmp_path: Path) -> None:
    """``--driver valve:Valve`` (or a config naming it) imports valve.py beside that file."""
    model_dir, config_dir, cwd = tmp_path / "model", tmp_path / "config", tmp_path / "elsewhere"
    for d in (model_dir, config_dir, cwd):
        d.mkdir()
    (model_dir / "gripper.yaml").write_text(GRIPPER.read_text(encoding="utf-8"), encoding="utf-8")
    home = model_dir if where == "model" else config_dir
    (home / "valve.py").write_text(VALVE, encoding="utf-8")
    argv = ["run", str(model_dir / "gripper.yaml")]
    if where == "model":
        argv += ["--driver", "valve:Valve"]
    else:
        config = config_dir / "run.yaml"
        config.write_text("devices:\n  Gripper: {driver: 'valve:Valve'}\n", encoding="utf-8")
        argv += ["--config", str(config)]
    done = statectl(argv, cwd, "Grip\n")
    assert done.returncode == 0, done.stderr
    assert "Valve.close()" in done.stdout and "final state Closed" in done.stdout, done.stdout


def test_a_driver_module_found_nowhere_says_what_to_do(tmp_path: Path) -> None:
    """A module neither on the path nor beside the model: exit 1, saying where to put it."""
    done = statectl(["run", str(GRIPPER), "--driver", "nosuch_valve:Valve"], tmp_path, "Grip\n")
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert "put nosuch_valve.py" in done.stderr and "beside the model file" in done.stderr
    assert "PYTHONPATH" in done.stderr


FAILS_MADE = """\
from statectl.run.devices import Driver


class Valve(Driver):
    def __init__(self) -> None:
        raise ValueError("no bus")
"""


@pytest.mark.parametrize(
    ("module", "says"),
    [
        ("def close(:\n", "broken_valve.py:1: driver 'broken_valve:Valve': 'broken_valve' is not"),
        ("raise RuntimeError('no bus')\n", "broken_valve.py:1: driver 'broken_valve:Valve': impo"),
        (FAILS_MADE, "broken_valve.py:6: driver 'broken_valve:Valve' failed while it was made"),
    ],
)
def test_a_driver_module_that_fails_is_one_line_naming_its_file_and_line(
    tmp_path: Path, module: str, says: str
) -> None:
    """A driver of one's own that is not Python, fails at import or in its constructor: exit
    1 with its file:line and the error, no traceback (each used to be a traceback)."""
    (tmp_path / "gripper.yaml").write_text(GRIPPER.read_text(encoding="utf-8"), encoding="utf-8")
    (tmp_path / "broken_valve.py").write_text(module, encoding="utf-8")
    argv = ["run", str(tmp_path / "gripper.yaml"), "--driver", "broken_valve:Valve"]
    done = statectl(argv, tmp_path, "Grip\n")
    assert (done.returncode, "Traceback" in done.stderr) == (1, False), done.stderr
    assert says in done.stderr, done.stderr


SRC = ROOT / "src" / "statectl"
#: Functions that return an int literal that is not an exit status, with why.
NOT_EXIT_STATUSES: set[str] = set()


_EXIT_NAMES = {"OK", "PROBLEMS", "USAGE", "INTERRUPTED", "BROKEN_PIPE"}


def _literal_int(node: ast.expr | None) -> bool:
    """``node`` is an int literal (``True``/``False`` are not exit statuses)."""
    return isinstance(node, ast.Constant) and type(node.value) is int


def _literal_exit_statuses(path: Path) -> list[str]:
    """Where ``path`` writes an exit status as a number instead of a kernel/exits.py name.

    Calls: ``sys.exit(2)``, ``SystemExit(2)``, ``os._exit(1)``, ``parser.exit(2, ...)``,
    anywhere. Returns: ``return 1`` in a function annotated ``-> int`` of a command-line
    module (channels/cli/, or any module that uses kernel/exits.py's names). Assignments:
    ``USAGE = 2`` (or ``OK, PROBLEMS, USAGE = 0, 1, 2``) outside kernel/exits.py.
    """
    rel = path.relative_to(SRC).as_posix()
    text = path.read_text(encoding="utf-8")
    tree = ast.parse(text)
    commands = rel.startswith("channels/cli/") or "statectl.kernel.exits" in text
    found: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign | ast.AnnAssign) and rel != "kernel/exits.py":
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names = {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
            values = (
                [v for v in ast.walk(node.value) if isinstance(v, ast.expr)] if node.value else []
            )
            if names & _EXIT_NAMES and any(_literal_int(v) for v in values):
                found.append(f"{rel}:{node.lineno}")
        if isinstance(node, ast.Call) and node.args and _literal_int(node.args[0]):
            func = node.func
            name = func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")
            if name in {"exit", "_exit", "SystemExit"}:
                found.append(f"{rel}:{node.lineno}")
        if commands and isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            returns_int = isinstance(node.returns, ast.Name) and node.returns.id == "int"
            if not returns_int or f"{rel}:{node.name}" in NOT_EXIT_STATUSES:
                continue
            found += [
                f"{rel}:{r.lineno}"
                for r in ast.walk(node)
                if isinstance(r, ast.Return) and _literal_int(r.value)
            ]
    return found


def test_exit_statuses_are_named_once() -> None:
    """Every exit status in src/ is a name from kernel/exits.py, never a number written again."""
    found = [where for path in sorted(SRC.rglob("*.py")) for where in _literal_exit_statuses(path)]
    assert found == [], "use OK/PROBLEMS/USAGE/... from statectl.kernel.exits"


def test_exit_statuses_are_what_shells_expect() -> None:
    """0/1/2 as the docs say; 130 and 141 are 128 + SIGINT and 128 + SIGPIPE."""
    import signal

    from statectl.kernel import exits

    assert (exits.OK, exits.PROBLEMS, exits.USAGE) == (0, 1, 2)
    assert exits.INTERRUPTED == 128 + signal.SIGINT
    assert exits.BROKEN_PIPE == 128 + signal.SIGPIPE
