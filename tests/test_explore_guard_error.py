"""A guard that raises: the explorer gets the kernel's answer, as the runtime does.

The runtime refuses an event whose guard raises (``Unhandled.GUARD_ERROR``); the
explorer must neither read it as false (taking the row below) nor stay silent.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from statectl import SimClock, Subject, load
from statectl.cell.explore import Composed, Kind, explore, export_promela
from statectl.cell.explore.local import LocalSpace
from statectl.cell.model import load_cell_or_raise
from statectl.kernel.model import Transition
from statectl.kernel.semantics import Machine, Run, Unhandled, initial, step
from statectl.kernel.semantics.eventview import GuardError

# Go takes Fast when its guard holds, else Slow (the row below); GUARD is replaced.
GATE = """\
device: Gate
data: {scale: SCALE}
states:
  - {state: Idle, control: default, ignore: [Done]}
  - {state: Fast, control: event trigger required, ignore: [Go]}
  - {state: Slow, control: event trigger required, ignore: [Go]}
events:
  - {event: Go, old: Idle, new: Fast, kind: command, api: Go, guard: "GUARD"}
  - {event: Go, old: Idle, new: Slow, kind: command, api: Go}
  - {event: Done, old: Fast, new: Idle, kind: completion, api: Go}
  - {event: Done, old: Slow, new: Idle, kind: completion, api: Go}
"""

# Sends Go to the gate through a link when it is poked.
POKER = """\
device: Poker
states:
  - {state: Ready, control: default}
events:
  - {event: Poke, old: Ready, new: Ready, kind: command, api: Poke}
"""

MIXED = "_event.data.speed > 1 and 10 / scale > 1"  # the tracked part raises if scale is 0
TRACKED = "10 / scale > 1"


def gate(tmp_path: Path, guard: str, scale: int) -> Path:
    path = tmp_path / "gate.yaml"
    text = GATE.replace("GUARD", guard).replace("SCALE", str(scale))
    path.write_text(text, encoding="utf-8")
    return path


def cell(tmp_path: Path, guard: str, scale: int, linked: bool) -> Path:
    """The gate alone (the environment sends Go) or poked through a link without data."""
    gate(tmp_path, guard, scale)
    (tmp_path / "poker.yaml").write_text(POKER, encoding="utf-8")
    if linked:
        body = (
            "devices: {gate: gate.yaml, poker: poker.yaml}\n"
            "links:\n  - {from: poker, raises: Poke, to: gate, send: Go,"
            " ignore_if_unhandled: yes}\n"
            "environment:\n  - {send: Poke, to: poker}\n"
        )
    else:
        body = "devices: {gate: gate.yaml}\nenvironment:\n  - {send: Go, to: gate}\n"
    path = tmp_path / "cell.yaml"
    path.write_text(body, encoding="utf-8")
    return path


def verify(tmp_path: Path, guard: str, scale: int, linked: bool) -> dict[Kind, tuple[int, ...]]:
    """Each failing finding kind with the lengths of its traces."""
    report = explore(load_cell_or_raise(cell(tmp_path, guard, scale, linked)))
    out: dict[Kind, list[int]] = {}
    for f in report.failures:
        out.setdefault(f.kind, []).append(len(f.trace) if f.trace is not None else -1)
    return {k: tuple(v) for k, v in out.items()}


@pytest.mark.parametrize(
    ("guard", "scale", "linked", "expected"),
    [
        # the free part true, then 10 / 0: refused, not the Slow row
        (MIXED, 0, False, {Kind.GUARD_ERROR: (0,)}),
        # a guard over tracked data alone: refused in every run, so nothing else happens
        (TRACKED, 0, False, {Kind.GUARD_ERROR: (0,), Kind.DEADLOCK: (0,)}),
        # delivered by a link: ignore_if_unhandled does not excuse a guard error
        (MIXED, 0, True, {Kind.GUARD_ERROR: (1,)}),
        (TRACKED, 0, True, {Kind.GUARD_ERROR: (1,)}),
        # the same guards that do not raise: nothing to report
        (MIXED, 1, False, {}),
        (TRACKED, 1, True, {}),
    ],
)
def test_raising_guard_is_a_finding(
    tmp_path: Path, guard: str, scale: int, linked: bool, expected: dict[Kind, tuple[int, ...]]
) -> None:
    """A guard that raises in a reachable state is a guard error finding with its trace."""
    assert verify(tmp_path, guard, scale, linked) == expected


@pytest.mark.parametrize(
    ("linked", "why"),
    [
        # the environment's data is free: the guard raises once the free part is true
        (False, "ZeroDivisionError: division by zero when _event.data.speed > 1 is True"),
        # the link sends no data: reading the field raises first, as at run time
        (True, "AttributeError: 'NoneType' object has no attribute 'speed';"),
    ],
)
def test_guard_error_message_says_why(tmp_path: Path, linked: bool, why: str) -> None:
    """The finding names the guard's row (file:line), the runtime's exception and the choices."""
    report = explore(load_cell_or_raise(cell(tmp_path, MIXED, 0, linked)))
    (finding,) = report.failures
    assert finding.name == "gate.Go"
    assert "gate.yaml:8" in finding.message and why in finding.message
    assert ("no guard raises", "fails") in report.properties


@pytest.mark.parametrize("guard", [MIXED, TRACKED])
def test_fast_successors_report_guard_errors_as_branches_do(tmp_path: Path, guard: str) -> None:
    """The search's successors and the detailed branches agree on a link's guard error."""
    model = Composed(load_cell_or_raise(cell(tmp_path, guard, 0, linked=True)))
    (g,) = model.initial
    (s,) = [s for s in model.stimuli if s.event == "Poke"]
    slow = [(b.state, b.unhandled, b.livelock) for b in model.branches(g, s)]
    assert model.successors(g, s) == slow
    assert [u[3] < 0 for _, bad, _ in slow for u in bad] == [True]  # one, marked ~link


def runtime(path: Path, speed: float) -> str:
    """Where the runtime's Gate is after Go with ``speed``, or ``guard error``."""
    subject = Subject(load(path), clock=SimClock())
    subject.start()
    try:
        subject.dispatch("Go", {"speed": speed})
    except GuardError:
        assert subject.snapshot.active == frozenset({"Idle"})  # refused: left where it was
        return str(Unhandled.GUARD_ERROR)
    (state,) = subject.snapshot.active
    return state


def explorer(path: Path, free: bool) -> str:
    """The explorer's outcome of Go in Idle when the free part is ``free``."""
    space = LocalSpace("gate", load(path))
    outs = space.outcomes(0, "Go")
    (out,) = [o for o in outs if dict(o.choices)["_event.data.speed > 1"] is free]
    return str(out.unhandled) if out.unhandled is not None else space.state_of(out.target)


@pytest.mark.parametrize(
    ("scale", "speed", "expected"),
    [
        (0, 3.0, "guard error"),  # 10 / 0 is reached: both refuse
        (0, 0.5, "Slow"),  # short-circuit: 10 / 0 is never evaluated
        (1, 3.0, "Fast"),
        (1, 0.5, "Slow"),
    ],
)
def test_runtime_and_explorer_agree(
    tmp_path: Path, scale: int, speed: float, expected: str
) -> None:
    """For each speed, the runtime's outcome is the explorer's outcome of that free choice."""
    path = gate(tmp_path, MIXED, scale)
    assert runtime(path, speed) == expected
    assert explorer(path, speed > 1) == expected


def test_an_oracle_that_raises_is_a_guard_error(tmp_path: Path) -> None:
    """The kernel refuses a step whose guard oracle raises, as when the guard itself raises."""
    m = Machine(load(gate(tmp_path, TRACKED, 1)))
    start = initial(m).target

    def oracle(run: Run, t: Transition) -> Any:
        raise ZeroDivisionError("forced")

    result = step(m, start, "Go", {"scale": 1}, oracle=oracle)
    assert result.unhandled is Unhandled.GUARD_ERROR and not result.handled
    assert result.failure is not None and "ZeroDivisionError: forced" in result.failure.reason
    assert result.target == start


@pytest.mark.parametrize("guard", [MIXED, TRACKED])
def test_spin_agrees_on_a_link_guard_error(tmp_path: Path, guard: str) -> None:
    """The Promela export fails an assertion where a link's guard raises, as verify fails."""
    from test_promela import HAVE_SPIN, spin

    if not HAVE_SPIN:
        pytest.skip("SPIN (Debian package spin) or gcc absent")
    loaded = load_cell_or_raise(cell(tmp_path, guard, 0, linked=True))
    model = Composed(loaded)
    (finding,) = explore(loaded, model=model).failures
    assert spin(export_promela(model), tmp_path, "-E") == (True, len(finding.trace or ()))
