"""Deferred events: the ``defer`` cell kept while its state is active, released after it."""

from __future__ import annotations

from pathlib import Path

import pytest

from statectl.cell.explore import verify_cell
from statectl.front.builder.build import load_and_build, load_chart
from statectl.front.rules import check_chart, check_paths
from statectl.kernel.errors import Severity
from statectl.kernel.model import MAX_DEFERRED, Chart, State, StateKind, Transition
from statectl.out.codegen.cpp import render
from statectl.out.codegen.flatten import flatten
from statectl.run.runtime import SimClock, Subject
from statectl.run.runtime.records import EventReceived, EventRejected, MicrostepTaken, Record

ROOT = Path(__file__).resolve().parents[1]
CLAMP = ROOT / "examples" / "clamp" / "clamp.yaml"

#: A press: Stop and Eject given while Pressing wait for the stroke to end.
PRESS = """\
device: Press
states:
  - {state: Idle, control: default, ignore: [all others]}
  - {state: Pressing, defer: [Stop, Eject], ignore: [Go]}
  - {state: Done, ignore: [Go, Stroke done]}
  - {state: Stopped, ignore: [all others]}
events:
  - {event: Go, old: Idle, new: Pressing, api: Stroke}
  - {event: Stroke done, old: Pressing, new: Done, kind: completion, api: Stroke}
  - {event: Stop, old: Done, new: Stopped}
  - {event: Eject, old: Done, new: Idle}
  - {event: Reset, old: Stopped, new: Idle}
  - {event: Reset, old: Pressing, new: Idle}
  - {event: Reset, old: Done, new: Idle}
"""


def press(tmp_path: Path, text: str = PRESS) -> Path:
    path = tmp_path / "press.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def run(chart: Chart) -> tuple[Subject, list[Record]]:
    subject = Subject(chart, clock=SimClock(), policy="error")
    records: list[Record] = []
    subject.listen(records.append)
    subject.start()
    return subject, records


def received(records: list[Record]) -> list[str]:
    return [r.event for r in records if isinstance(r, EventReceived)]


def test_a_deferred_event_is_delivered_once_the_state_is_left() -> None:
    """The clamp keeps a Release given while Closing and releases once Clamped."""
    subject, records = run(load_chart(CLAMP))
    subject.dispatch("Close")
    subject.dispatch("Release")
    assert subject.configuration == {"Closing"}
    subject.dispatch("Closed")
    assert subject.configuration == {"Released"}
    assert received(records) == ["Close", "Release", "Closed", "Release"]


def test_deferred_events_come_back_in_arrival_order_before_queued_ones(tmp_path: Path) -> None:
    """Kept events are delivered in the order they came, ahead of events queued meanwhile."""
    chart = load_chart(press(tmp_path))
    subject, records = run(chart)
    subject.dispatch("Go")
    subject.dispatch("Stop")
    subject.dispatch("Eject")
    subject.post("Stroke done")
    subject.post("Reset")  # queued behind Stroke done, but after the kept events
    subject.run_until_idle()
    assert received(records)[-4:] == ["Stroke done", "Stop", "Eject", "Reset"]
    # Stop took Done to Stopped; Eject found Stopped ignoring everything; Reset -> Idle
    assert subject.configuration == {"Idle"}


def test_a_kept_event_never_outlives_its_state(tmp_path: Path) -> None:
    """Leaving for a state that ignores the event drops it: it is not carried further."""
    chart = load_chart(press(tmp_path))
    subject, records = run(chart)
    subject.dispatch("Go")
    subject.dispatch("Stop")
    subject.dispatch("Reset")  # Pressing -> Idle, which ignores Stop: released, ignored
    subject.dispatch("Go")
    subject.dispatch("Stroke done")  # Done: a Stop carried this far would stop the press
    assert subject.configuration == {"Done"}
    assert received(records).count("Stop") == 2


def test_deferring_is_not_an_error_under_policy_error(tmp_path: Path) -> None:
    """A deferred arrival is declared ignored by the kernel, so policy 'error' raises nothing."""
    subject, records = run(load_chart(press(tmp_path)))
    subject.dispatch("Go")
    subject.dispatch("Eject")
    assert not any(isinstance(r, EventRejected) for r in records)


def test_the_released_event_keeps_its_data() -> None:
    """The data given with a deferred event arrives with it when it is released."""
    chart = load_chart(CLAMP)
    subject, records = run(chart)
    subject.dispatch("Close")
    subject.dispatch("Release", {"by": "operator"})
    subject.dispatch("Closed")
    last = [r for r in records if isinstance(r, EventReceived)][-1]
    assert (last.event, last.data) == ("Release", {"by": "operator"})


def test_at_most_max_deferred_events_are_kept(tmp_path: Path) -> None:
    """One event more than MAX_DEFERRED is dropped with an EventRejected record."""
    subject, records = run(load_chart(press(tmp_path)))
    subject.dispatch("Go")
    for _ in range(MAX_DEFERRED + 1):
        subject.dispatch("Eject")
    rejected = [r for r in records if isinstance(r, EventRejected)]
    assert [r.event for r in rejected] == ["Eject"]
    subject.dispatch("Stroke done")
    # the first kept Eject ejects (Done -> Idle); the other 15 meet Idle, which ignores them
    assert received(records).count("Eject") == 2 * MAX_DEFERRED + 1
    assert [r.entered for r in records if isinstance(r, MicrostepTaken)][-1] == ("Idle",)


def test_the_chart_answers_which_events_a_configuration_defers(tmp_path: Path) -> None:
    """One answer for the runtime, the explorer and testgen's oracle: each event once, by
    state name and then as the defer cell lists them; nothing for states that defer none."""
    text = PRESS.replace(
        "{state: Stopped, ignore: [all others]}", "{state: Stopped, defer: [Eject, Stop]}"
    )
    chart = load_chart(press(tmp_path, text))
    assert chart.deferring({"Pressing"}) == ("Stop", "Eject")
    assert chart.deferring({"Stopped"}) == ("Eject", "Stop")
    assert chart.deferring({"Stopped", "Pressing"}) == ("Stop", "Eject")  # Pressing's first
    assert chart.deferring({"Idle", "Done"}) == ()
    motor = load_chart(ROOT / "examples" / "motor" / "motor.yaml")
    assert motor.deferring({"Blocked"}) == ()


def test_a_chart_without_defer_keeps_nothing() -> None:
    """The Motor has no defer cells: an unhandled event is simply ignored, never re-delivered."""
    subject, records = run(load_chart(ROOT / "examples" / "motor" / "motor.yaml"))
    subject.dispatch("Movement completion")
    subject.dispatch("Movement")
    assert received(records) == ["Movement completion", "Movement"]


# -- build and check ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("change", "code"),
    [
        ("defer: [Stop, Eject]", None),
        ("defer: [Stop, Ejekt]", "B226"),  # unknown event
        ("defer: [Stop, Reset]", "B227"),  # Pressing handles Reset
        ("defer: [Stop, Go]", "B227"),  # Pressing ignores Go
    ],
)
def test_build_checks_defer_cells(tmp_path: Path, change: str, code: str | None) -> None:
    """A defer cell names known events that the state neither handles nor ignores."""
    path = press(tmp_path, PRESS.replace("defer: [Stop, Eject]", change))
    errors = [d.code for d in load_and_build(path)[1] if d.severity is Severity.ERROR]
    assert errors == ([code] if code else [])


def test_defer_on_a_final_state_is_b225(tmp_path: Path) -> None:
    """A final state is never active with events to keep: B225."""
    text = PRESS.replace(
        "  - {state: Stopped, ignore: [all others]}",
        "  - {state: Stopped, type: final, defer: [Go]}",
    ).replace("  - {event: Reset, old: Stopped, new: Idle}\n", "")
    errors = [d.code for d in load_and_build(press(tmp_path, text))[1]]
    assert "B225" in errors


def test_check_warns_when_leaving_drops_a_deferred_event(tmp_path: Path) -> None:
    """C410: Reset leaves Pressing for Idle, where a kept Stop or Eject would be lost,
    unless Idle ignores them; a deferred event counts as handled for C404."""
    text = PRESS.replace(
        "{state: Idle, control: default, ignore: [all others]}",
        "{state: Idle, control: default, ignore: [Stroke done, Reset, Stop]}",
    )
    diags = check_paths([str(press(tmp_path, text))])
    c410 = [d for d in diags if d.code == "C410"]
    assert len(c410) == 1 and "'Eject'" in c410[0].message and "'Idle'" in c410[0].message
    assert c410[0].severity is Severity.WARNING
    missed = [d.message for d in diags if d.code == "C404"]
    assert not any("'Pressing'" in m for m in missed), missed
    clean = check_paths([str(press(tmp_path))])
    assert [d.code for d in clean if d.code in ("C404", "C410")] == []


def test_generated_code_has_a_deferral_array_only_when_needed(tmp_path: Path) -> None:
    """The clamp's header keeps deferred events; the Motor's has no trace of deferral."""
    for path, present in ((CLAMP, True), (ROOT / "examples" / "motor" / "motor.yaml", False)):
        flat, _ = flatten(load_chart(path))
        assert flat is not None
        header = "".join(t for name, t in render(flat).items() if name.endswith(".hpp"))
        assert ("kDeferred" in header and "defer_release" in header) is present


# -- verify ---------------------------------------------------------------------------------


def test_verify_explores_a_kept_event_coming_back(tmp_path: Path) -> None:
    """Stop is sent only while Pressing, so only its release after the stroke reaches
    Stopped: the invariant fails with the defer cell and holds without it."""
    cell = tmp_path / "cell.yaml"
    cell.write_text(
        "cell: C\ndevices:\n  press: press.yaml\nenvironment:\n"
        "  - {send: Go, to: press}\n"
        "  - {send: Stop, to: press, when: \"In('press.Pressing')\"}\n"
        "  - {send: Reset, to: press}\n"
        "invariants:\n  - {name: never-stopped, holds: \"not In('press.Stopped')\"}\n",
        encoding="utf-8",
    )
    press(tmp_path)
    report, diags = verify_cell(cell)
    assert report is not None, diags
    assert [f.name for f in report.failures] == ["never-stopped"]
    press(tmp_path, PRESS.replace("defer: [Stop, Eject], ", ""))
    report, diags = verify_cell(cell)
    assert report is not None, diags
    assert [f.name for f in report.failures] == []


def test_c410_sees_a_superstate_row_leaving_the_deferring_state(tmp_path: Path) -> None:
    """A row from Pressing's parent leaves Pressing too: the kept Eject meets Halted (C410)."""
    text = PRESS.replace(
        "  - {state: Pressing, defer: [Stop, Eject], ignore: [Go]}",
        "  - {state: Work, ignore: [all others]}\n"
        "  - {state: Pressing, parent: Work, defer: [Stop, Eject], ignore: [Go]}\n"
        "  - {state: Halted, ignore: [Go, Stroke done, Stop, Reset, Abort]}",
    ).replace(
        "  - {event: Go, old: Idle, new: Pressing, api: Stroke}",
        "  - {event: Go, old: Idle, new: Pressing, api: Stroke}\n"
        "  - {event: Abort, old: Work, new: Halted}",
    )
    found = [d for d in check_paths([str(press(tmp_path, text))]) if d.code == "C410"]
    assert [("'Abort'" in d.message, "'Eject'" in d.message) for d in found] == [(True, True)]


# -- C410 and parallel regions: what a transition enters is the kernel's answer --------------


def regions_c410(
    target: str,
    handle: tuple[str, ...] = (),
    ignore: tuple[str, ...] = (),
    defer: tuple[str, ...] = (),
) -> list[str]:
    """The states C410 names when A, deferring x, goes to ``target`` in a chart with a
    parallel P (regions R1: r1a, R2: r2a) and a compound C (c1 first, then c2); the
    states in ``handle`` have an x row, those in ``ignore`` ignore x, those in ``defer``
    defer it too."""
    states = (
        State("A", defer=("x",)),
        State("P", kind=StateKind.PARALLEL),
        State("R1", kind=StateKind.COMPOUND, parent="P", initial=("r1a",)),
        State("r1a", parent="R1", defer=("x",) if "r1a" in defer else ()),
        State("R2", kind=StateKind.COMPOUND, parent="P", initial=("r2a",)),
        State("r2a", parent="R2", defer=("x",) if "r2a" in defer else ()),
        State("C", kind=StateKind.COMPOUND, initial=("c1",)),
        State("c1", parent="C"),
        State("c2", parent="C"),
        State("done"),
    )
    rows = (
        Transition("A", ("go",), (target,)),
        *(Transition(s, ("x",), ("done",)) for s in handle),
        Transition("done", ("back",), ("A",)),
    )
    chart = Chart("T", states, rows, ("A",), ignored=frozenset((s, "x") for s in ignore))
    found = [d for d in check_chart(chart) if d.code == "C410"]
    named = [
        n for d in found for n in ("P", "r1a", "r2a", "c1", "c2") if f"for {n!r}," in d.message
    ]
    assert len(named) == len(found), [d.message for d in found]
    return named


@pytest.mark.parametrize(
    ("target", "handle", "ignore", "defer", "named"),
    [
        ("P", ("r1a",), (), (), []),  # the first region's default child takes x
        ("P", ("r2a",), (), (), []),  # the second region's
        ("P", ("R2",), (), (), []),  # a region itself
        ("P", (), ("r2a",), (), []),  # one region ignores it: losing it is meant
        ("P", (), (), ("r1a",), []),  # one region keeps it
        ("r1a", ("r2a",), (), (), []),  # entering r1a enters the sibling region's r2a too
        ("r2a", ("r1a",), (), (), []),
        ("P", (), (), (), ["P"]),  # no region does anything with x
        ("r1a", (), (), (), ["P"]),
        ("P", ("c1",), (), (), ["P"]),  # a row elsewhere does not help
        ("C", ("c1",), (), (), []),  # compound: its initial child takes x
        ("C", ("c2",), (), (), ["c1"]),  # ...not a sibling that is not entered
        ("c2", ("c1",), (), (), ["c2"]),
    ],
)
def test_c410_asks_the_kernel_what_the_transition_enters(
    target: str,
    handle: tuple[str, ...],
    ignore: tuple[str, ...],
    defer: tuple[str, ...],
    named: list[str],
) -> None:
    """C410 warns only when no state of the configuration a transition enters handles,
    ignores or defers the kept event: every region of a parallel state counts."""
    assert regions_c410(target, handle, ignore, defer) == named


def within_region(
    handle: tuple[str, ...] = (), ignore: tuple[str, ...] = (), defer: tuple[str, ...] = ()
) -> Chart:
    """A parallel P: R1 (r1a deferring x, then r1b on n) beside R2 (r2a, then r2b on m);
    the states in ``handle`` go to ``done`` on x, those in ``ignore`` / ``defer`` do so."""
    states = (
        State("P", kind=StateKind.PARALLEL),
        State("R1", kind=StateKind.COMPOUND, parent="P", initial=("r1a",)),
        State("r1a", parent="R1", defer=("x",)),
        State("r1b", parent="R1"),
        State("R2", kind=StateKind.COMPOUND, parent="P", initial=("r2a",)),
        *(State(n, parent="R2", defer=("x",) if n in defer else ()) for n in ("r2a", "r2b")),
        State("done"),
    )
    rows = (
        Transition("r1a", ("n",), ("r1b",)),
        Transition("r2a", ("m",), ("r2b",)),
        *(Transition(s, ("x",), ("done",)) for s in handle),
        Transition("done", ("back",), ("P",)),
    )
    return Chart("W", states, rows, ("P",), ignored=frozenset((s, "x") for s in ignore))


@pytest.mark.parametrize(
    ("handle", "ignore", "defer", "warned"),
    [
        ((), (), (), True),  # nobody takes x after r1a -> r1b
        (("r1b",), (), (), False),  # the state entered takes it
        (("r2a", "r2b"), (), (), False),  # the other region takes it in every state
        (("R2",), (), (), False),  # ... by a row of the region itself
        (("r2a",), (), (), True),  # r2b beside r1b would lose it
        (("r2a",), ("r2b",), (), False),  # r2b ignores it: losing it there is meant
        (("r2a",), (), ("r2b",), False),  # r2b keeps it again
    ],
)
def test_c410_counts_the_regions_a_transition_inside_one_region_leaves_active(
    handle: tuple[str, ...], ignore: tuple[str, ...], defer: tuple[str, ...], warned: bool
) -> None:
    """Leaving a deferring state inside one region releases the kept event to the whole
    configuration: C410 only when some configuration of the other regions drops it."""
    found = [
        d.message for d in check_chart(within_region(handle, ignore, defer)) if d.code == "C410"
    ]
    assert bool(found) is warned, found
    if warned:
        assert found[0].startswith("'n' leaves 'r1a', which defers 'x', for 'r1b'"), found


def test_the_other_region_takes_the_released_event_at_run_time() -> None:
    """What C410 relies on: after r1a -> r1b, the kernel offers the kept x to R2 as well."""
    subject, records = run(within_region(handle=("r2b",)))
    subject.dispatch("x")  # no state takes x: r1a keeps it
    subject.dispatch("m")
    assert subject.configuration >= {"r1a", "r2b"}, subject.configuration
    subject.dispatch("n")  # leaving r1a releases x; r2b takes it
    assert subject.configuration == {"done"}, [r for r in records if isinstance(r, MicrostepTaken)]


def test_the_testgen_oracle_keeps_and_releases_as_the_runtime(tmp_path: Path) -> None:
    """Testgen's specification keeps deferred events by the runtime's own rule: one more
    than MAX_DEFERRED is dropped, and the kept ones come back in arrival order once the
    state is left (it kept every one before, so a device that dropped the extra failed)."""
    from statectl.out.testgen.oracle import Specification

    chart = load_chart(press(tmp_path))
    spec = Specification(chart)
    device, _ = run(chart)
    for event in ("Go", *(["Eject"] * (MAX_DEFERRED + 1))):
        spec._process(event, None)
        device.dispatch(event)
    taken = spec._process("Stroke done", None)
    device.dispatch("Stroke done")
    assert taken is not None and [s.event for s in taken] == ["Stroke done"] + ["Eject"] * (
        MAX_DEFERRED
    )
    assert spec.kept == [] and set(spec.states) == set(device.configuration) == {"Idle"}
