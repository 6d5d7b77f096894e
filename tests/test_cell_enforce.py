"""What verify assumes, run enforces: environment `when`, invariants, cross-device guards,
link data and harmless link events, the same in `statectl run`, the System and `verify`."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from statectl.cell.explore import Composed, Kind, explore
from statectl.cell.explore.enforce import Refused
from statectl.cell.explore.replay import ReplayStep, run_cell
from statectl.cell.model import InputKind, load_cell, load_cell_or_raise
from statectl.channels.cli.run import run
from statectl.run.journal import Journal
from statectl.run.runtime import SimClock
from statectl.run.system import DeviceSetup, System

ROOT = Path(__file__).resolve().parents[1]
PACKML = ROOT / "examples" / "packml"
DATA = (ROOT / "tests" / "data" / "cells").as_posix()


def _run(cell: Path, lines: str, journal: str | None = None) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = run(str(cell), events=io.StringIO(lines), out=out, err=err, journal=journal)
    return code, out.getvalue(), err.getvalue()


def _system(path: Path) -> System:
    cell = load_cell_or_raise(path)
    setups = [DeviceSetup(d.name, d.chart) for d in cell.devices]
    system = System(setups, SimClock(), cell=cell)
    system.start()
    return system


def _states(system: System) -> dict[str, str]:
    return {n: "+".join(sorted(s.configuration)) for n, s in system.subjects.items()}


@pytest.mark.parametrize(
    ("lines", "code", "unit", "said"),
    [
        ("unit: Start\n", 1, "Idle", "unit: Start refused"),
        ("axis1: Power On\nunit: Start\n", 1, "Idle", "axis2.Standstill"),
        ("axis1: Power On\naxis2: Power On\nunit: Start\n+2\n", 0, "Execute", ""),
    ],
)
def test_run_refuses_a_start_verify_never_offers(
    lines: str, code: int, unit: str, said: str
) -> None:
    """A Start whose `when` is false (axes disabled) is refused with the reason; exit 1."""
    got, out, err = _run(PACKML / "cell.yaml", lines)
    assert got == code, err
    assert f"final unit: {unit}" in out
    assert said in err
    if code:
        assert "environment command(s) refused" in err


def test_the_system_refuses_through_post() -> None:
    """System.post raises Refused naming the false condition and the global state."""
    system = _system(PACKML / "cell.yaml")
    with pytest.raises(Refused, match=r"unit=Idle, axis1=Disabled, axis2=Disabled"):
        system.post("unit", "Start")
    system.post("axis1", "Power On")  # an entry without `when` is never refused
    system.drain()
    assert _states(system)["axis1"] == "Standstill"


@pytest.mark.parametrize("journalled", [False, True])
def test_a_when_is_judged_after_what_was_posted_before_it(tmp_path: Path, journalled: bool) -> None:
    """Start then Part in, posted back to back with no drain between (a live run's
    reader): Part in's `when` (conveyor Running) is judged once Start has run, as
    verify takes the sequence, so it is accepted, not refused against a stale state."""
    cell = load_cell_or_raise(ROOT / "examples" / "pick-and-place" / "cell.yaml")
    setups = [DeviceSetup(d.name, d.chart) for d in cell.devices]
    journal = Journal(tmp_path / "j.db") if journalled else None
    system = System(setups, SimClock(), cell=cell, journal=journal)
    system.start()
    try:
        system.post("conveyor", "Start")
        system.post("sensor", "Part in")  # refused before: conveyor was still Stopped
        system.quiesce()
        assert _states(system)["sensor"] == "Detected"
    finally:
        system.close()


def test_a_when_judged_after_an_event_a_driver_refused_is_still_judged() -> None:
    """The drain before a `when` is judged runs an earlier event whose observer raises:
    that failure goes to on_failure (rule 7), as the live owner loop reports it, and
    the command is judged and posted, not refused with the earlier event's error."""
    from statectl.kernel.errors import StatectlError

    class Refusing:  # refuses its first call (Start's), takes the later ones
        refused = False

        def update(self, notification: object) -> None:
            if not self.refused:
                self.refused = True
                raise StatectlError("the belt drive refused")

    system = _system(ROOT / "examples" / "pick-and-place" / "cell.yaml")
    failures: list[str] = []
    system.on_failure.append(lambda exc: failures.append(str(exc)))
    system.subjects["conveyor"].attach(Refusing())
    try:
        system.post("conveyor", "Start")
        system.post("sensor", "Part in")  # Start ran (and its driver failed) first
        system.quiesce()
        assert failures == ["the belt drive refused"]
        assert _states(system)["sensor"] == "Detected"
    finally:
        system.close()


@pytest.mark.parametrize("journalled", [False, True])
def test_an_invariant_violation_is_reported_reacted_to_and_fails_the_run(
    tmp_path: Path, journalled: bool
) -> None:
    """Powering an axis off while producing: VIOLATED in the trace, Abort sent, exit 1
    (with a journal, the Abort is accepted into it once the cascade settled)."""
    lines = "axis1: Power On\naxis2: Power On\nunit: Start\n+2\naxis1: Power Off\n+2\n"
    db = str(tmp_path / "j.db") if journalled else None
    code, out, err = _run(PACKML / "cell-buggy.yaml", lines, db)
    assert code == 1
    assert "VIOLATED invariant axes-powered-while-producing" in out
    assert "sending unit: Abort" in out
    assert "final unit: Aborted" in out
    assert "1 invariant violation(s)" in err


def test_the_same_run_on_the_fixed_cell_refuses_instead() -> None:
    """The fixed cell's `when` refuses the Power Off: no violation, the unit produces."""
    lines = "axis1: Power On\naxis2: Power On\nunit: Start\n+2\naxis1: Power Off\n+2\n"
    code, out, err = _run(PACKML / "cell.yaml", lines)
    assert code == 1
    assert "VIOLATED" not in out
    assert "final unit: Execute" in out
    assert "axis1: Power Off refused" in err


def test_verify_finds_the_violation_run_reports() -> None:
    """verify fails the buggy cell's invariant and holds on the fixed one."""
    for name, fails in (("cell-buggy.yaml", True), ("cell.yaml", False)):
        report = explore(load_cell_or_raise(PACKML / name))
        assert any(f.kind is Kind.INVARIANT for f in report.failures) is fails, name


# -- a device guard reading another device ----------------------------------------------------


def test_a_guard_reading_another_device_is_honoured_by_run() -> None:
    """Reset clears an aborted unit only once both axes stand still (In('axis1.Standstill'))."""
    system = _system(PACKML / "cell.yaml")
    for device, event in [("axis1", "Power On"), ("unit", "Abort"), ("unit", "Abort completion")]:
        system.post(device, event)
        system.settle()
    assert _states(system)["unit"] == "Aborted"
    system.post("unit", "Reset")
    system.settle()
    assert _states(system)["unit"] == "Aborted"  # axis2 is still disabled
    system.post("axis2", "Power On")
    system.post("unit", "Reset")
    system.settle()
    assert _states(system)["unit"] == "Idle"


def test_verify_decides_a_guard_reading_another_device_from_the_global_state() -> None:
    """From Aborted, Reset leads to Idle exactly when both axes stand still."""
    model = Composed(load_cell_or_raise(PACKML / "cell.yaml"))
    report = explore(model.cell, model=model)
    assert report.complete
    reset = next(s for s in model.stimuli if s.event == "Reset" and model.names[s.device] == "unit")
    seen = 0
    for g in _reachable(model):
        labels = dict(zip(model.names, model.labels(g), strict=True))
        if labels["unit"] != "Aborted":
            continue
        seen += 1
        after = {
            dict(zip(model.names, model.labels(h), strict=True))["unit"]
            for h, _, _ in model.successors(g, reset)
        }
        both = labels["axis1"] == labels["axis2"] == "Standstill"
        assert after == ({"Idle"} if both else set()), labels
    assert seen > 1


def _reachable(model: Composed) -> set[int]:
    seen = set(model.initial)
    todo = list(seen)
    while todo:
        g = todo.pop()
        for s in model.enabled(g):
            for h, _, _ in model.successors(g, s):
                if h not in seen:
                    seen.add(h)
                    todo.append(h)
    return seen


@pytest.mark.parametrize(
    ("guard", "message"),
    [
        ("In('axis9.Standstill')", "the cell has no device 'axis9'"),
        ("In('axis1.Flying')", "device 'axis1' has no state 'Flying'"),
    ],
)
def test_a_guard_naming_an_unknown_device_or_state_is_v831(
    tmp_path: Path, guard: str, message: str
) -> None:
    """The cell checks a device guard's In('device.State') against its devices at load."""
    text = (PACKML / "unit.yaml").read_text(encoding="utf-8")
    (tmp_path / "unit.yaml").write_text(
        text.replace("In('axis1.Standstill')", guard), encoding="utf-8"
    )
    cell = (
        (PACKML / "cell.yaml")
        .read_text(encoding="utf-8")
        .replace("axis.yaml", (PACKML / "axis.yaml").as_posix())
    )
    (tmp_path / "cell.yaml").write_text(cell, encoding="utf-8")
    loaded, diags = load_cell(tmp_path / "cell.yaml")
    assert loaded is None
    found = [d for d in diags if d.code == "V831"]
    assert len(found) == 1 and message in found[0].message
    assert found[0].where.file.endswith("unit.yaml")


# -- link data and harmless link events -------------------------------------------------------


def _latch_cell(tmp_path: Path, link: str) -> Path:
    path = tmp_path / "cell.yaml"
    path.write_text(
        f"""\
devices: {{button: {DATA}/button.yaml, latch: {DATA}/latch.yaml}}
links:
  - {{from: button, enters: Pressed, to: latch, {link}}}
environment:
  - {{send: Press, to: button}}
  - {{send: Release, to: button}}
  - {{send: Lock, to: latch}}
""",
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize(
    ("link", "opens"),
    [
        ('send: "Reset {status: true}"', True),
        ("send: Reset, data: {status: true}", True),
        ('send: "Reset {status: false}"', False),
        ("send: Reset", False),
    ],
)
def test_link_data_decides_a_data_guard_alike_in_run_and_verify(
    tmp_path: Path, link: str, opens: bool
) -> None:
    """A link's data satisfies (or not) the target's data guard, in run and in verify."""
    path = _latch_cell(tmp_path, link)
    system = _system(path)
    failures: list[Exception] = []
    system.on_failure.append(failures.append)
    system.post("button", "Press")
    system.drain()
    assert (_states(system)["latch"] == "Open") is opens
    # sent without data, the guard cannot read it: refused as a guard error, said (rule 7)
    assert [type(f).__name__ for f in failures] == (["GuardError"] if link == "send: Reset" else [])
    model = Composed(load_cell_or_raise(path))
    reached = {
        dict(zip(model.names, model.labels(g), strict=True))["latch"] for g in _reachable(model)
    }
    assert ("Open" in reached) is opens


@pytest.mark.parametrize(("status", "opens"), [(True, True), (False, False)])
def test_forwarded_data_reaches_the_target(tmp_path: Path, status: bool, opens: bool) -> None:
    """forward_data: true sends the triggering event's data on to the target."""
    system = _system(_latch_cell(tmp_path, "send: Reset, forward_data: true"))
    system.post("button", "Press", {"status": status})
    system.drain()
    assert (_states(system)["latch"] == "Open") is opens


def test_bad_link_data_is_v830(tmp_path: Path) -> None:
    """Data that is not YAML flow style, or given twice, is V830 with the link's line."""
    for link in ('send: "Reset {status: [}"', 'send: "Reset {a: 1}", data: {b: 2}'):
        cell, diags = load_cell(_latch_cell(tmp_path, link))
        assert cell is None
        assert [d.where.line for d in diags if d.code == "V830"] == [3], link


@pytest.mark.parametrize(("flag", "reported"), [("", True), (", ignore_if_unhandled: true", False)])
def test_ignore_if_unhandled_tells_a_harmless_event_from_a_missed_one(
    tmp_path: Path, flag: str, reported: bool
) -> None:
    """A second Reset to an open latch is a missed transition unless the link says harmless."""
    path = _latch_cell(tmp_path, 'send: "Reset {status: true}"' + flag)
    cell = load_cell_or_raise(path)
    report = explore(cell)
    assert any(f.kind is Kind.UNHANDLED for f in report.failures) is reported
    assert (
        "every link-delivered event is handled or ignored",
        "holds" if not reported else "fails",
    ) in report.properties
    steps = [ReplayStep(InputKind.COMMAND, "button", e) for e in ("Press", "Release", "Press")]
    result = run_cell(cell, replay=steps)
    assert bool(result.unhandled) is reported


def test_links_with_data_are_refused_with_a_journal(tmp_path: Path) -> None:
    """The journal's link rows hold no data yet: such a cell is refused, nothing runs."""
    path = _latch_cell(tmp_path, 'send: "Reset {status: true}"')
    code, out, err = _run(path, "button: Press\n", str(tmp_path / "j.db"))
    assert code == 1
    assert "links that carry event data" in err and "run without --journal" in err
    assert "final" not in out


def _follow_cell(tmp_path: Path) -> Path:
    """A lever that follows a button through a link: apart only inside the link cascade."""
    path = tmp_path / "follow.yaml"
    path.write_text(
        f"""cell: Follow
devices:
  button: {DATA}/button.yaml
  lever: {DATA}/lever.yaml
links:
  - {{from: button, enters: Pressed, to: lever, send: Up}}
  - {{from: button, enters: Idle, to: lever, send: Down}}
environment:
  - {{send: Press, to: button}}
  - {{send: Release, to: button}}
invariants:
  - name: lever-follows-button
    holds: >-
      not (In('button.Pressed') and In('lever.Low'))
      and not (In('button.Idle') and In('lever.High'))
""",
        encoding="utf-8",
    )
    return path


def test_an_invariant_is_checked_when_the_cascade_settles_as_verify_checks_it(
    tmp_path: Path,
) -> None:
    """Between the button's step and the lever's linked step the invariant is false for a
    moment; verify takes a stimulus and its links as one move and finds it holds, so run
    must not report that moment (it checks once the cascade settled)."""
    path = _follow_cell(tmp_path)
    report = explore(load_cell_or_raise(path))
    assert [f.kind for f in report.failures if f.kind is Kind.INVARIANT] == []
    code, out, err = _run(path, "button: Press\nbutton: Release\nbutton: Press\n")
    assert (code, "VIOLATED" in out) == (0, False), err
    assert "final lever: High" in out
