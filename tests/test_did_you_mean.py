"""Wherever a name is looked up, a mistyped one gets "did you mean" (kernel/errors.py).

``check`` suggested the closest column, kind or profile; ``run``'s event lines, its
``--driver``, ``node --node`` and the dashboard's post did not. One helper says it.
"""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from statectl.channels.cli import main
from statectl.kernel.errors import did_you_mean

ROOT = Path(__file__).resolve().parents[1]
MOTOR = str(ROOT / "examples" / "motor" / "motor.yaml")
CELL = str(ROOT / "examples" / "pick-and-place" / "cell.yaml")
NODES = str(ROOT / "examples" / "pick-and-place" / "cell-nodes.yaml")

#: (argv, stdin, exit code, the suggestion said on stderr)
CASES = [
    (
        ["run", MOTOR],
        "Movment\n",
        1,
        "line 1: Motor has no event 'Movment'; did you mean 'Movement'?",
    ),
    (["run", CELL], "gripper: Gripp\n", 1, "did you mean 'Grip'?"),
    (["run", CELL], "Grippr: Grip\n", 1, "no device 'Grippr'; did you mean 'gripper'?"),
    (["run", MOTOR, "--driver", "sim-motr"], "", 1, "did you mean 'sim-motor'?"),
    (["node", NODES, "--node", "armm"], "", 2, "did you mean 'arm'?"),
]


@pytest.mark.parametrize(("argv", "stdin", "code", "says"), CASES)
def test_a_mistyped_name_gets_the_closest(
    argv: list[str], stdin: str, code: int, says: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The command exits as before and names the closest known name."""
    monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    out, err = io.StringIO(), io.StringIO()
    assert main(argv, out, err) == code, err.getvalue()
    assert says in err.getvalue(), err.getvalue()


def test_nothing_close_suggests_nothing() -> None:
    """A name like none of the choices gets no guess (the list of known names follows)."""
    assert (did_you_mean("Zzz", ["Movement", "Error"]), did_you_mean("Eror", ["Error"])) == (
        "",
        "did you mean 'Error'? ",
    )


def test_a_live_run_prints_the_final_states_as_a_batch_run_does(tmp_path: Path) -> None:
    """`run --realtime` (live: events fed while the devices run) ends with 'final state',
    as a batch run does; it used to end without one."""
    out, err = io.StringIO(), io.StringIO()
    from statectl.channels.cli.run import run

    code = run(MOTOR, realtime=True, events=io.StringIO("Movement {amount: 0}\n"), out=out, err=err)
    assert code == 0, err.getvalue()
    assert "final state " in out.getvalue(), out.getvalue()


def test_new_and_journal_lookups_suggest_too(tmp_path: Path) -> None:
    """`new --profile` and `journal show --device` name the closest too."""
    out, err = io.StringIO(), io.StringIO()
    assert main(["new", "X", "--profile", "cia40", "--out", str(tmp_path)], out, err) == 2
    assert "did you mean 'cia402'?" in err.getvalue()
    db = tmp_path / "run.db"
    main(["run", MOTOR, "--journal", str(db)], io.StringIO(), io.StringIO())
    err = io.StringIO()
    assert main(["journal", "show", str(db), "--device", "Motr"], io.StringIO(), err) == 1
    assert "did you mean 'Motor'?" in err.getvalue()
