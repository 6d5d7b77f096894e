"""Verifying cells: the composed state space, its findings and their shortest traces."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest

from statectl.cell.explore import Kind, Report, explore, to_mermaid, to_plantuml, write_traces
from statectl.cell.explore.replay import run_cell
from statectl.cell.model import load_cell_or_raise
from statectl.channels.cli.replay import run_main
from statectl.channels.cli.verify import verify_main

PICK = Path(__file__).resolve().parents[1] / "examples" / "pick-and-place"

TOGGLE = """\
device: Toggle
states:
  - {state: P, control: default}
  - {state: Q, control: event trigger required}
events:
  - {event: Flip, old: P, new: Q, kind: command, api: Flip}
  - {event: Flip, old: Q, new: P, kind: command, api: Flip}
"""

ONESHOT = """\
device: OneShot
states:
  - {state: Idle, control: default}
  - {state: Done, control: event trigger required, ignore: [Go]}
events:
  - {event: Go, old: Idle, new: Done, kind: command, api: Go}
"""

VALVE = """\
device: Valve
data: {pressure: null}
states:
  - {state: Closed, control: default, ignore: [Close]}
  - {state: Open, control: event trigger required, ignore: [Open]}
events:
  - {event: Open, old: Closed, new: Open, kind: command, api: Open, guard: pressure < 5}
  - {event: Close, old: Open, new: Closed, kind: command, api: Close}
"""

TRAP = """\
device: Machine
states:
  - {state: Idle, control: default, ignore: [Stop, Poke]}
  - {state: Running, control: [event trigger required, monitoring required], ignore: [Go, Poke]}
  - {state: Broken, control: event trigger required, ignore: [Go, Stop]}
  - {state: Stuck, control: event trigger required, ignore: [Go, Stop]}
events:
  - {event: Go, old: Idle, new: Running, kind: command, api: Go}
  - {event: Stop, old: Running, new: Idle, kind: command, api: Go}
  - {event: Break, old: Running, new: Broken, kind: fault, api: Go}
  - {event: Poke, old: Broken, new: Stuck, kind: command, api: Go}
  - {event: Poke, old: Stuck, new: Broken, kind: command, api: Go}
"""


def cell_of(tmp_path: Path, devices: dict[str, str], body: str) -> Path:
    """Write device files and a cell naming them; return the cell's path."""
    lines = ["devices:"]
    for name, text in devices.items():
        (tmp_path / f"{name}.yaml").write_text(text, encoding="utf-8")
        lines.append(f"  {name}: {name}.yaml")
    path = tmp_path / "cell.yaml"
    path.write_text("\n".join(lines) + "\n" + body, encoding="utf-8")
    return path


def run(path: Path, **kw: int) -> Report:
    return explore(load_cell_or_raise(path), **kw)  # type: ignore[arg-type]


def kinds(report: Report) -> dict[Kind, int]:
    """Each finding kind and the length of its trace."""
    return {f.kind: len(f.trace) if f.trace else -1 for f in report.findings}


def test_buggy_example_fails_with_short_traces() -> None:
    """The seeded interlock bug (4 steps) and the missed Release (6 steps) are found.

    The Release trace was 4 steps while the explorer let the arm answer a fault's
    Error() call with Initialization completion, which no arm does (issue 27); the
    shortest real run has the gripper slip while the arm returns.
    """
    report = run(PICK / "cell-buggy.yaml")
    assert kinds(report) == {Kind.INVARIANT: 4, Kind.UNHANDLED: 6}
    assert report.verdict == "fails"


def test_fixed_example_holds() -> None:
    """The fixed cell verifies clean: every property holds, every device state is reached."""
    report = run(PICK / "cell.yaml")
    assert report.findings == ()
    assert report.verdict == "holds"
    assert all(v == "holds" for _, v in report.properties)


def test_deadlock(tmp_path: Path) -> None:
    """A state where no input changes anything is a deadlock, with its shortest trace."""
    path = cell_of(tmp_path, {"shot": ONESHOT}, "environment:\n  - {send: Go, to: shot}\n")
    report = run(path)
    assert kinds(report) == {Kind.DEADLOCK: 1}
    assert report.findings[0].trace is not None
    assert report.findings[0].trace.end == ("Done",)


def test_free_guard_explores_both_outcomes(tmp_path: Path) -> None:
    """A guard over data the model does not track is a free choice, and the report says so."""
    body = "environment:\n  - {send: Open, to: v}\n  - {send: Close, to: v}\n"
    report = run(cell_of(tmp_path, {"v": VALVE}, body))
    assert report.states == 2 and report.findings == ()
    assert [g.parts for g in report.free_guards] == [("pressure < 5",)]
    assert "free choice" in report.to_text()


def test_tracked_guard_is_not_free() -> None:
    """The Motor's guard on ``previous`` is decided by the snapshot, not chosen freely."""
    report = run(PICK / "cell.yaml")
    assert report.free_guards == ()


def test_max_states_makes_it_incomplete() -> None:
    """A search stopped by --max-states says incomplete and does not pass."""
    report = run(PICK / "cell.yaml", max_states=5)
    assert (report.states, report.complete, report.verdict) == (5, False, "incomplete")
    assert "incomplete" in report.to_text()


def test_verify_is_bounded_unless_told_otherwise(monkeypatch: pytest.MonkeyPatch) -> None:
    """`statectl verify` without --max-states stops at DEFAULT_MAX_STATES (exit 1, the
    report says how to go further): a cell too big for memory used to run until the
    machine ran out of it."""
    import statectl.channels.cli.verify as cli_verify

    monkeypatch.setattr(cli_verify, "DEFAULT_MAX_STATES", 5)
    out = io.StringIO()
    assert verify_main(str(PICK / "cell.yaml"), out=out, err=io.StringIO()) == 1
    said = out.getvalue()
    assert "stopped at its bound of 5 states" in said and "0 for no bound" in said, said
    out = io.StringIO()
    assert verify_main(str(PICK / "cell.yaml"), max_states=0, out=out, err=io.StringIO()) == 0


def test_recovery_failure(tmp_path: Path) -> None:
    """A state from which the named goal can never be reached fails recovery."""
    body = (
        "environment:\n  - {send: Go, to: m}\n  - {send: Stop, to: m}\n"
        "  - {send: Poke, to: m}\n  - {fault: Break, to: m}\n"
        "recovery:\n  - {name: home, to: \"In('m.Idle')\"}\n"
    )
    report = run(cell_of(tmp_path, {"m": TRAP}, body))
    assert kinds(report) == {Kind.RECOVERY: 2}
    assert report.findings[0].count == 2  # Broken and Stuck


def test_recovery_from_restricts_the_start(tmp_path: Path) -> None:
    """With ``from``, only the states where it holds must get back."""
    body = (
        "environment:\n  - {send: Go, to: m}\n  - {send: Stop, to: m}\n"
        "  - {fault: Break, to: m}\n"
        "recovery:\n  - {name: home, to: \"In('m.Idle')\", from: \"In('m.Running')\"}\n"
    )
    report = run(cell_of(tmp_path, {"m": TRAP}, body))
    assert Kind.RECOVERY not in kinds(report)
    assert (
        "recovery home: always able to reach In('m.Idle') from In('m.Running')",
        "holds",
    ) in report.properties


def test_unreached_device_state(tmp_path: Path) -> None:
    """A device state the cell never enters is reported as a warning, not a failure."""
    body = "environment:\n  - {send: Go, to: m}\n  - {send: Stop, to: m}\n"
    report = run(cell_of(tmp_path, {"m": TRAP}, body))
    assert sorted(f.name for f in report.findings) == ["m.Broken", "m.Stuck"]
    assert report.verdict == "holds"


def test_link_livelock(tmp_path: Path) -> None:
    """Links that keep answering each other within one step are a link livelock."""
    body = (
        "links:\n  - {from: a, raises: Flip, to: b, send: Flip}\n"
        "  - {from: b, raises: Flip, to: a, send: Flip}\n"
        "environment:\n  - {send: Flip, to: a}\n"
    )
    report = run(cell_of(tmp_path, {"a": TOGGLE, "b": TOGGLE}, body))
    assert Kind.LIVELOCK in kinds(report)


def test_link_guard_and_fifo_order(tmp_path: Path) -> None:
    """Link guards read the state after the triggering step; deliveries are first in, first out."""
    body = (
        "links:\n  - {from: a, enters: Q, to: b, send: Flip}\n"
        "  - {from: a, enters: Q, to: c, send: Flip, guard: \"In('b.Q')\"}\n"
        "environment:\n  - {send: Flip, to: a}\n"
        "invariants:\n  - {name: c-never, holds: \"not In('c.Q')\"}\n"
    )
    report = run(cell_of(tmp_path, {"a": TOGGLE, "b": TOGGLE, "c": TOGGLE}, body))
    # the guard is read when a enters Q, before b flips: c first flips on a's second entry
    assert kinds(report) == {Kind.INVARIANT: 3}


def test_unanticipated_summary() -> None:
    """Outside events that reach a state with no row and no ignore are summarised."""
    cell = load_cell_or_raise(PICK / "cell.yaml")
    report = explore(cell)
    assert report.unanticipated == ()  # the example's tables declare their ignores


def test_unanticipated_counts(tmp_path: Path) -> None:
    """An environment event a state neither handles nor ignores counts the states it reaches."""
    sends = "".join(f"  - {{send: {e}, to: m}}\n" for e in ("Go", "Stop", "Break"))
    body = "environment:\n" + sends
    report = run(cell_of(tmp_path, {"m": TRAP.replace(", ignore: [Stop, Poke]", "")}, body))
    assert {(u.state, u.event) for u in report.unanticipated} == {
        ("Idle", "Stop"),
        ("Idle", "Break"),
        ("Broken", "Break"),
    }


@pytest.mark.parametrize(
    ("draw", "head", "message"),
    [
        (to_mermaid, "sequenceDiagram", "environment->>conveyor: Start"),
        (to_plantuml, "@startuml", "environment -> conveyor : Start"),
    ],
)
def test_trace_diagrams(draw: object, head: str, message: str) -> None:
    """A counterexample is drawn as a sequence diagram with one message per delivery."""
    report = run(PICK / "cell-buggy.yaml")
    trace = report.failures[0].trace
    assert trace is not None
    text = draw(trace, "invariant")  # type: ignore[operator]
    assert text.startswith(head) and message in text
    assert "conveyor->>arm: Movement (link)" in text or "conveyor -> arm : Movement (link)" in text


def test_replay_reproduces_the_counterexample(tmp_path: Path) -> None:
    """Replaying a written trace on the runtime reaches the same states and shows the failure."""
    report = run(PICK / "cell-buggy.yaml")
    written = write_traces(report, tmp_path)
    trace = next(p for p in written if p.name.endswith(".trace.json") and "invariant" in p.name)
    out = io.StringIO()
    assert (
        run_main(str(PICK / "cell-buggy.yaml"), replay=str(trace), out=out, err=io.StringIO()) == 0
    )
    assert "invariant belt-still-while-arm-reaches fails" in out.getvalue()


def test_traces_of_a_long_property_name_are_written(tmp_path: Path) -> None:
    """A 300-character invariant name still gives trace files (names stay under 255 bytes)."""
    for source in PICK.glob("*.yaml"):
        (tmp_path / source.name).write_text(source.read_text(encoding="utf-8"), encoding="utf-8")
    buggy = tmp_path / "cell-buggy.yaml"
    long_name = "n" * 300
    buggy.write_text(
        buggy.read_text(encoding="utf-8").replace("belt-still-while-arm-reaches", long_name),
        encoding="utf-8",
    )
    written = write_traces(run(buggy), tmp_path / "traces")
    assert len(written) == 6 and all(p.is_file() for p in written)
    assert max(len(p.name.encode()) for p in written) < 255


def test_runtime_walk_agrees_with_explorer() -> None:
    """A random walk on the runtime never reaches a state the explorer does not predict."""
    cell = load_cell_or_raise(PICK / "cell-buggy.yaml")
    for seed in range(3):
        result = run_cell(cell, walk=25, seed=seed)
        assert result.divergences == ()


def test_json_report() -> None:
    """--json writes one document with the verdict, the findings and replayable steps."""
    out = io.StringIO()
    code = verify_main(str(PICK / "cell-buggy.yaml"), as_json=True, out=out, err=io.StringIO())
    doc = json.loads(out.getvalue())
    assert code == 1 and doc["verdict"] == "fails"
    steps = doc["findings"][0]["trace"]["steps"]
    assert [(s["source"], s["to"], s["event"]) for s in steps][:2] == [
        ("environment", "conveyor", "Start"),
        ("environment", "sensor", "Part in"),
    ]


@pytest.mark.parametrize(
    ("args", "code"),
    [
        ({"cell": "/nonexistent.yaml"}, 2),
        ({"cell": str(PICK / "cell.yaml"), "max_states": -1}, 2),
        ({"cell": str(PICK / "cell.yaml"), "max_states": 0}, 0),  # no bound
        ({"cell": str(PICK / "cell.yaml"), "export": "nusmv"}, 2),
        ({"cell": str(PICK / "cell.yaml")}, 0),
        ({"cell": str(PICK / "cell-buggy.yaml")}, 1),
        ({"cell": str(PICK / "cell.yaml"), "max_states": 3}, 1),
    ],
)
def test_exit_codes(args: dict[str, object], code: int) -> None:
    """0 all properties hold, 1 one fails or the search was bounded, 2 usage error."""
    assert verify_main(**args, out=io.StringIO(), err=io.StringIO()) == code  # type: ignore[arg-type]


def test_bad_cell_prints_diagnostics(tmp_path: Path) -> None:
    """A cell that does not load prints its diagnostics and exits 1."""
    path = tmp_path / "cell.yaml"
    path.write_text("devices: {}\n", encoding="utf-8")
    err = io.StringIO()
    assert verify_main(str(path), out=io.StringIO(), err=err) == 1
    assert "V815" in err.getvalue()


@pytest.mark.parametrize("name", ["cell.yaml", "cell-buggy.yaml"])
def test_fast_successors_match_branches(name: str) -> None:
    """The search's fast successors give the same ways, in order, as the detailed branches."""
    from statectl.cell.explore import Composed

    model = Composed(load_cell_or_raise(PICK / name))
    seen, frontier, compared = set(model.initial), list(model.initial), 0
    while frontier:
        g = frontier.pop()
        for s in model.stimuli:
            slow = [(b.state, b.unhandled, b.livelock) for b in model.branches(g, s)]
            assert model.successors(g, s) == slow
            compared += 1
            for h, _, _ in slow:
                if h not in seen:
                    seen.add(h)
                    frontier.append(h)
    assert len(seen) > 10 and compared > 100


def test_verify_progress_line_is_rewritten_in_place_and_ended_once() -> None:
    """verify's progress: each report rewrites one line (\\r), done() ends it with one
    newline, and a run that showed nothing writes nothing."""
    from statectl.cell.explore import Progress
    from statectl.channels.cli.progress import ProgressPrinter

    stream = io.StringIO()
    printer = ProgressPrinter(stream)
    printer(Progress(states=1500, expanded=700, depth=4, seconds=0.5))
    printer(Progress(states=3000, expanded=1400, depth=5, seconds=1.0))
    printer.done()
    assert stream.getvalue() == (
        "\rexploring: 1,500 states, 700 expanded, depth 4, 3,000 states/s "
        "\rexploring: 3,000 states, 1,400 expanded, depth 5, 3,000 states/s \n"
    )
    quiet = io.StringIO()
    ProgressPrinter(quiet).done()
    assert quiet.getvalue() == ""
