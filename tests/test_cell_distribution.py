"""verify explores what distribution adds: link events lost or overtaken; SPIN agrees on
the cell-level guards (another device's state, link data) the export now carries."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
from pathlib import Path
from types import SimpleNamespace
from typing import cast

import pytest

from statectl.cell.explore import Composed, Kind, explore, export_promela, write_traces
from statectl.cell.explore.promela import STEP_MARK
from statectl.cell.explore.replay import load_replay, run_cell
from statectl.cell.model import Cell, InputKind, load_cell_or_raise

ROOT = Path(__file__).resolve().parents[1]
PICK = ROOT / "examples" / "pick-and-place"
PACKML = ROOT / "examples" / "packml"
DATA = (ROOT / "tests" / "data" / "cells").as_posix()
HAVE_SPIN = shutil.which("spin") is not None and shutil.which("gcc") is not None
needs_spin = pytest.mark.skipif(not HAVE_SPIN, reason="SPIN (Debian package spin) or gcc absent")


def _copy(tmp_path: Path, source: Path, old: str, new: str) -> Path:
    """A copy of a cell file beside its devices, with one text replaced."""
    text = source.read_text(encoding="utf-8")
    assert old in text
    path = source.parent / f".{tmp_path.name}-{source.name}"
    path.write_text(text.replace(old, new), encoding="utf-8")
    return path


@pytest.fixture
def lossless(tmp_path: Path) -> object:
    path = _copy(tmp_path, PICK / "cell-lossy.yaml", ", lossy: true", "")
    yield path
    path.unlink()


def test_a_bug_that_needs_a_lost_link_is_found(tmp_path: Path) -> None:
    """The lossy pick-and-place copy fails only through the lost 'Part out'; the trace says so."""
    report = explore(load_cell_or_raise(PICK / "cell-lossy.yaml"))
    [failure] = report.failures
    assert failure.kind is Kind.INVARIANT and failure.name == "no-part-left-on-a-running-belt"
    assert failure.trace is not None
    lost = [d for s in failure.trace.steps for d in s.deliveries if d.fate == "lost"]
    assert [(d.receiver, d.event) for d in lost] == [("sensor", "Part out")]
    assert "(link LOST on the way)" in "\n".join(failure.trace.lines())


def test_the_same_cell_without_loss_holds(lossless: Path) -> None:
    """Without `lossy: true` on the link the same cell verifies: the bug needs the loss."""
    report = explore(load_cell_or_raise(lossless))
    assert report.complete and not report.failures


def test_the_lost_link_trace_replays_on_the_runtime(tmp_path: Path) -> None:
    """The written trace replays: the runtime drops the same link event, breaks the invariant."""
    cell = load_cell_or_raise(PICK / "cell-lossy.yaml")
    report = explore(cell)
    [path] = [p for p in write_traces(report, tmp_path) if p.name.endswith(".trace.json")]
    doc = json.loads(path.read_text(encoding="utf-8"))
    fates = [d["fate"] for s in doc["steps"] for d in s["deliveries"] if "fate" in d]
    assert fates == ["lost"]
    out: list[str] = []
    result = run_cell(cell, out.append, replay=load_replay(path))
    assert not result.divergences
    assert [v.split(": ")[1] for v in result.violations] == [
        "invariant no-part-left-on-a-running-belt fails in conveyor=Running, arm=Blocked, "
        "gripper=Open, sensor=Detected"
    ]
    assert any("link lost: gripper enters Closed -> sensor.Part out" in t for t in out)


def _lever_cell(tmp_path: Path, flag: str) -> Path:
    path = tmp_path / "cell.yaml"
    path.write_text(
        f"""\
devices: {{button: {DATA}/button.yaml, lever: {DATA}/lever.yaml}}
links:
  - {{from: button, enters: Pressed, to: lever, send: Up{flag}}}
  - {{from: button, enters: Pressed, to: lever, send: Down}}
  - {{from: button, enters: Idle, to: lever, send: Down}}
environment:
  - {{send: Press, to: button}}
  - {{send: Release, to: button}}
invariants:
  - {{name: low-while-idle-or-pressed, holds: "In('lever.Low')"}}
""",
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize(("flag", "fails"), [("", False), (", delayed: true", True)])
def test_a_delayed_link_event_may_be_overtaken(tmp_path: Path, flag: str, fails: bool) -> None:
    """Up then Down leaves the lever low; a delayed Up overtaken by Down leaves it high."""
    cell = load_cell_or_raise(_lever_cell(tmp_path, flag))
    report = explore(cell)
    assert any(f.kind is Kind.INVARIANT for f in report.failures) is fails
    if fails:
        trace = report.failures[0].trace
        assert trace is not None and len(trace) == 1
        order = [(d.event, d.fate) for d in trace.steps[0].deliveries[1:]]
        assert order == [("Down", ""), ("Up", "overtaken")]
        paths = write_traces(report, tmp_path / "traces")
        replay = load_replay(next(p for p in paths if p.name.endswith(".trace.json")))
        result = run_cell(cell, replay=replay)
        assert not result.divergences and result.violations


# -- SPIN agrees on the guards a cell decides ----------------------------------------------------


def _spin(text: str, folder: Path) -> tuple[bool, int]:
    (folder / "m.pml").write_text(text, encoding="utf-8")
    subprocess.run(["spin", "-a", "m.pml"], cwd=folder, check=True, capture_output=True)
    subprocess.run(
        ["gcc", "-O2", "-DBFS", "-DSAFETY", "-DNOREDUCE", "-o", "pan", "pan.c"],
        cwd=folder,
        check=True,
        capture_output=True,
    )
    pan = subprocess.run(["./pan", "-E"], cwd=folder, capture_output=True, text=True)
    if "errors: 0" in pan.stdout:
        return False, 0
    trail = subprocess.run(["spin", "-t", "m.pml"], cwd=folder, capture_output=True, text=True)
    return True, trail.stdout.count(STEP_MARK)


@needs_spin
@pytest.mark.parametrize(
    ("holds", "fails"),
    [
        # holds only if Reset's In('axis1.Standstill') guard is decided by axis1's state
        ("not (In('unit.Idle') and In('axis1.ErrorStop'))", False),
        ("not (In('unit.Aborted') and In('axis1.ErrorStop'))", True),
    ],
)
def test_spin_agrees_on_a_guard_reading_another_device(
    tmp_path: Path, holds: str, fails: bool
) -> None:
    """The export carries In('axis1.Standstill') of a device row; SPIN and verify agree."""
    path = _copy(
        tmp_path,
        PACKML / "cell.yaml",
        "  - name: axes-powered-while-producing",
        f'  - name: probe\n    holds: "{holds}"\n  - name: axes-powered-while-producing',
    )
    try:
        model = Composed(load_cell_or_raise(path))
    finally:
        path.unlink()
    report = explore(model.cell, model=model)
    mine = [f for f in report.failures if f.kind is Kind.INVARIANT]
    assert bool(mine) is fails
    failed, steps = _spin(export_promela(model, unhandled=False), tmp_path)
    assert failed is fails
    if mine:
        assert steps == min(len(f.trace) for f in mine if f.trace is not None)


@needs_spin
@pytest.mark.parametrize(("data", "fails"), [("true", True), ("false", False)])
def test_spin_agrees_on_link_data(tmp_path: Path, data: str, fails: bool) -> None:
    """A link's data decides the target's data guard in the export as in verify."""
    path = tmp_path / "cell.yaml"
    path.write_text(
        f"""\
devices: {{button: {DATA}/button.yaml, latch: {DATA}/latch.yaml}}
links:
  - {{from: button, enters: Pressed, to: latch, send: "Reset {{status: {data}}}",
     ignore_if_unhandled: true}}
environment:
  - {{send: Press, to: button}}
  - {{send: Release, to: button}}
invariants:
  - {{name: stays-locked, holds: "In('latch.Locked')"}}
""",
        encoding="utf-8",
    )
    model = Composed(load_cell_or_raise(path))
    report = explore(model.cell, model=model)
    assert bool(report.failures) is fails
    failed, steps = _spin(export_promela(model), tmp_path)
    assert failed is fails
    if fails:
        assert steps == len(report.failures[0].trace or ())


# -- nodes: peers lost, links dropped (the section cell/nodes.py reads) -----------------------


def _on_nodes(
    cell: Cell,
    layout: dict[str, tuple[str, ...]],
    lost: dict[str, tuple[tuple[str, str], ...]],
    drop: dict[int, str | None],
) -> Cell:
    """``cell`` with a nodes section as cell/nodes.py gives it (names, devices, peer_lost,
    one delivery per link), for verify, which reads it by those names only."""
    nodes = SimpleNamespace(
        nodes=tuple(
            SimpleNamespace(name=n, devices=d, peer_lost=lost.get(n, ())) for n, d in layout.items()
        ),
        delivery=tuple(
            SimpleNamespace(on_peer_down="drop" if i in drop else "queue", dropped=drop.get(i))
            for i in range(len(cell.links))
        ),
    )
    fields = {f.name: getattr(cell, f.name) for f in dataclasses.fields(cell)}
    fields["nodes"] = nodes  # Cell.nodes once cell/nodes.py is there
    return cast(Cell, SimpleNamespace(**fields))


def test_a_peer_lost_at_any_point_is_explored(tmp_path: Path) -> None:
    """The lever's node hears its peer is lost (Up) in any state: verify finds the state
    the links alone never reach, and the trace replays."""
    cell = load_cell_or_raise(_lever_cell(tmp_path, ""))
    assert not explore(cell).failures
    spread = _on_nodes(cell, {"a": ("button",), "b": ("lever",)}, {"b": (("lever", "Up"),)}, {})
    report = explore(spread)
    [failure] = report.failures
    assert failure.trace is not None and len(failure.trace) == 1
    step = failure.trace.steps[0]
    assert (step.kind, step.device, step.event) == (InputKind.PEER_LOST, "lever", "Up")
    assert "lever: Up (peer lost)" in "\n".join(failure.trace.lines())
    paths = write_traces(report, tmp_path / "traces")
    replay = load_replay(next(p for p in paths if p.name.endswith(".trace.json")))
    result = run_cell(spread, replay=replay)
    assert not result.divergences and result.violations


def test_a_peer_lost_event_reaches_only_devices_linked_across_nodes(tmp_path: Path) -> None:
    """peer_lost of a device with no link to another node offers nothing."""
    cell = load_cell_or_raise(_lever_cell(tmp_path, ""))
    same = _on_nodes(cell, {"a": ("button", "lever")}, {"a": (("lever", "Up"),)}, {})
    assert not [s for s in Composed(same).stimuli if s.kind is InputKind.PEER_LOST]


@pytest.mark.parametrize(("drop", "fails"), [({}, False), ({4: None}, True), ({4: "Slip"}, False)])
def test_a_dropped_link_event_is_explored_with_its_dropped_event(
    lossless: Path, drop: dict[int, str | None], fails: bool
) -> None:
    """on_peer_down: drop across nodes loses the event (the seeded bug shows); a `dropped`
    event goes to the link's source in its place (the gripper's Slip: the bug no longer
    shows, as the gripper lets go)."""
    cell = load_cell_or_raise(lossless)
    layout = {"line": ("conveyor", "sensor"), "arm": ("arm",), "gripper": ("gripper",)}
    spread = _on_nodes(cell, layout, {}, drop)
    report = explore(spread)
    assert bool(report.failures) is fails
    model = Composed(spread)
    seen, todo, back = set(model.initial), list(model.initial), set()
    while todo:
        g = todo.pop()
        for s in model.enabled(g):
            for br in model.branches(g, s, detail=True):
                back |= {
                    (d.sender, d.receiver, d.event)
                    for d in br.deliveries
                    if d.via.endswith(" dropped")
                }
                if br.state not in seen:
                    seen.add(br.state)
                    todo.append(br.state)
    assert back == ({("sensor", "gripper", "Slip")} if drop.get(4) else set())
    if fails:
        trace = report.failures[0].trace
        assert trace is not None
        lost = [d.event for s in trace.steps for d in s.deliveries if d.fate == "lost"]
        assert lost == ["Part out"]
