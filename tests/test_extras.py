"""A command that needs an optional extra which is missing says which one: one line, exit 2.

The missing module is simulated, not uninstalled: the command runs in a subprocess
whose ``sys.modules`` maps it to None, so importing it raises ImportError as it would
on a base install (src/statectl/channels/cli/extras.py).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
MOTOR = str(EX / "motor" / "motor.yaml")
NODES = str(EX / "pick-and-place" / "cell-nodes.yaml")

#: A command line with the modules taken away: ``statectl`` with each one None.
RUNNER = """
import sys
for name in sys.argv[1].split(","):
    sys.modules[name] = None
from statectl.channels.cli import main
sys.exit(main(sys.argv[2:]))
"""

#: (modules missing, argv, the extra the message names)
CASES = [
    ("asyncua", ["run", MOTOR, "--opcua"], "opcua"),
    ("aiohttp", ["run", MOTOR, "--dashboard"], "dashboard"),
    ("aiohttp", ["dashboard", NODES], "dashboard"),
    ("zenoh", ["node", NODES, "--node", "arm"], "zenoh"),
    ("zenoh", ["dashboard", NODES], "zenoh"),
    ("canopen,can", ["run", MOTOR, "--driver", "cia402-sim", "--realtime"], "canopen"),
    ("canopen,can", ["demo", "--driver", "cia402-sim"], "canopen"),
    ("pymodbus", ["run", MOTOR, "--driver", "modbus"], "modbus"),
    ("psycopg", ["journal", "ship", "{tmp}/run.db", "--to", "postgresql://h/db"], "postgres"),
    ("psycopg", ["journal", "show", "postgresql://h/db"], "postgres"),
    ("hypothesis", ["testgen", MOTOR, "--hypothesis", "--out", "{tmp}/tests"], "test"),
    ("pygls", ["lsp"], "lsp"),
]


@pytest.mark.parametrize(
    ("missing", "argv", "extra"), CASES, ids=[c[0] + " " + c[1][0] for c in CASES]
)
def test_a_missing_extra_is_one_line_and_exit_2(
    missing: str, argv: list[str], extra: str, tmp_path: Path
) -> None:
    """Exit 2, one line naming the extra to install, nothing started or written."""
    args = [a.format(tmp=tmp_path) for a in argv]
    done = subprocess.run(
        [sys.executable, "-c", RUNNER, missing, *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        check=False,
    )
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.splitlines()) == 1, done.stderr
    assert f"pip install 'statectl[{extra}]'" in done.stderr, done.stderr
    assert done.stdout == "" and list(tmp_path.iterdir()) == []


def test_a_config_section_needing_a_missing_extra_is_exit_2(tmp_path: Path) -> None:
    """A run config's opcua: section (no --opcua flag) without asyncua: one line, exit 2."""
    config = tmp_path / "run.yaml"
    config.write_text("opcua:\n  endpoint: opc.tcp://127.0.0.1:48499\n", encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-c", RUNNER, "asyncua", "run", MOTOR, "--config", str(config)],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        check=False,
    )
    assert (done.returncode, "pip install 'statectl[opcua]'" in done.stderr) == (2, True), done


def test_all_installs_every_extra_a_command_names() -> None:
    """``statectl[all]`` holds every extra the commands name, and ``test`` holds pytest."""
    from statectl.channels.cli.extras import MODULES

    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    extras = project["optional-dependencies"]
    (everything,) = extras["all"]
    named = set(everything.split("[", 1)[1].rstrip("]").split(","))
    assert set(MODULES) <= named and named <= set(extras)
    assert any(d.startswith("pytest") for d in extras["test"])
