"""Device tables with hierarchy: superstates, parallel regions, history and final states."""

from __future__ import annotations

from pathlib import Path

import pytest

from statectl.front.builder.build import build, load_chart
from statectl.front.observers import Notification
from statectl.front.rules import check_paths
from statectl.front.tables import DeviceTables, EventRow, StateRow, load, save, strip_locations
from statectl.kernel.errors import Severity
from statectl.kernel.model import ControlKind, EventKind, StateKind
from statectl.kernel.semantics import Machine, initial, step
from statectl.run.runtime import SimClock, Subject

ROOT = Path(__file__).resolve().parent.parent
GANTRY = ROOT / "examples" / "gantry" / "gantry.yaml"
MOTOR = ROOT / "examples" / "motor"

D = (ControlKind.DEFAULT,)


def row(state: str, parent: str = "", type: StateKind | None = None, **kw: object) -> StateRow:
    fields: dict[str, object] = {
        "component": "Dev",
        "api": "",
        "controls": (),
        "description": "",
        "ignore": (),
    }
    fields.update(kw)
    return StateRow(state=state, parent=parent, type=type, **fields)  # type: ignore[arg-type]


def ev(event: str, old: str, new: str) -> EventRow:
    return EventRow(event, "", "", old, new, EventKind.COMMAND, "")


def tables(states: list[StateRow], events: list[EventRow]) -> DeviceTables:
    return DeviceTables("Dev", tuple(states), tuple(events))


# a compound Top (A default, B), a parallel P with regions R1 (X) and R2 (Y), history H in Top
GOOD = [
    row("Top", controls=D),
    row("A", "Top", controls=D),
    row("B", "Top"),
    row("H", "Top", StateKind.HISTORY_DEEP),
    row("P", type=StateKind.PARALLEL),
    row("R1", "P"),
    row("X", "R1", controls=D),
    row("R2", "P"),
    row("Y", "R2", controls=D),
    row("Done", type=StateKind.FINAL),
]
GOOD_EVENTS = [
    ev("go", "A", "B"),
    ev("par", "Top", "P"),
    ev("back", "P", "H"),
    ev("end", "P", "Done"),
]


@pytest.mark.parametrize(
    ("state", "kind", "initial", "history_default"),
    [
        ("Top", StateKind.COMPOUND, ("A",), ()),
        ("A", StateKind.ATOMIC, (), ()),
        ("H", StateKind.HISTORY_DEEP, (), ("A",)),
        ("P", StateKind.PARALLEL, (), ()),
        ("R1", StateKind.COMPOUND, ("X",), ()),
        ("Done", StateKind.FINAL, (), ()),
    ],
)
def test_type_and_parent_columns_build_state_kinds(
    state: str, kind: StateKind, initial: tuple[str, ...], history_default: tuple[str, ...]
) -> None:
    """Parent makes a compound, type makes parallel/final/history; a blank history default
    is its parent's initial child."""
    chart, diags = build(tables(GOOD, GOOD_EVENTS))
    assert chart is not None, [str(d) for d in diags]
    s = chart.state(state)
    assert (s.kind, s.initial, s.history_default) == (kind, initial, history_default)


def test_history_in_a_parallel_defaults_to_every_region() -> None:
    """A blank default of a history inside a parallel state enters all its regions."""
    states = [*GOOD, row("PH", "P", StateKind.HISTORY_SHALLOW)]
    chart, diags = build(tables(states, [*GOOD_EVENTS, ev("again", "Done", "PH")][:-1]))
    assert chart is not None, [str(d) for d in diags]
    assert chart.state("PH").history_default == ("R1", "R2")


@pytest.mark.parametrize(
    ("states", "events", "code"),
    [
        # history at the top level, with children, with a control, or a default outside
        ([row("T", controls=D), row("H", type=StateKind.HISTORY_SHALLOW)], [], "B212"),
        (
            [
                row("T", controls=D),
                row("H", "T", StateKind.HISTORY_SHALLOW),
                row("K", "H", controls=D),
            ],
            [],
            "B212",
        ),
        (
            [
                row("T", controls=D),
                row("K", "T"),
                row("H", "T", StateKind.HISTORY_SHALLOW, controls=D),
            ],
            [],
            "B212",
        ),
        (
            [
                row("T", controls=D),
                row("K", "T"),
                row("H", "T", StateKind.HISTORY_SHALLOW, default=("Z",)),
                row("Z"),
            ],
            [ev("e", "K", "Z")],
            "B212",
        ),
        # shallow history defaulting to a grandchild
        (
            [
                row("T", controls=D),
                row("K", "T"),
                row("G", "K", controls=D),
                row("H", "T", StateKind.HISTORY_SHALLOW, default=("G",)),
            ],
            [],
            "B212",
        ),
        (
            [row("T", controls=D), row("F", type=StateKind.FINAL), row("K", "F", controls=D)],
            [],
            "B213",
        ),
        ([row("P", type=StateKind.PARALLEL, controls=D), row("K", "P", controls=D)], [], "B214"),
        ([row("T", type=StateKind.ATOMIC, controls=D), row("K", "T", controls=D)], [], "B215"),
        ([row("T", type=StateKind.COMPOUND, controls=D)], [], "B215"),
        ([row("T", controls=D), row("F", type=StateKind.FINAL)], [ev("e", "F", "T")], "B216"),
        (
            [row("T", controls=D), row("K", "T"), row("H", "T", StateKind.HISTORY_SHALLOW)],
            [ev("e", "H", "K")],
            "B216",
        ),
        ([row("T", controls=D, default=("T",))], [], "B217"),
    ],
)
def test_hierarchy_misuse_is_reported(
    states: list[StateRow], events: list[EventRow], code: str
) -> None:
    """Each misuse of type, parent or default gives its B2xx error and no chart."""
    chart, diags = build(tables(states, events or [ev("noop", states[0].state, states[0].state)]))
    assert chart is None
    assert code in [d.code for d in diags if d.severity is Severity.ERROR]


def test_rows_that_disagree_on_type_are_t109() -> None:
    """Two rows for one state with different types contradict each other (blank is unsaid)."""
    states = [row("T", controls=D, type=StateKind.ATOMIC), row("T", type=StateKind.FINAL)]
    chart, diags = build(tables(states, [ev("e", "T", "T")]))
    assert chart is None
    assert "T109" in [d.code for d in diags]


def test_unknown_type_word_is_t113(tmp_path: Path) -> None:
    """A type cell that is none of the accepted words is T113 with the row's line."""
    path = tmp_path / "dev.yaml"
    path.write_text(
        "device: Dev\nstates:\n  - state: A\n    control: default\n    type: paralel\n"
        "events:\n  - event: e\n    old: A\n    new: A\n",
        encoding="utf-8",
    )
    _, diags = load(path)
    assert [(d.code, d.where.line) for d in diags] == [("T113", 5)]
    assert "did you mean 'parallel'" in diags[0].hint


def test_removal_takes_a_parent_whose_children_were_removed() -> None:
    """A control-less, untouched parent goes once its control-less children are removed (B207)."""
    states = [row("A", controls=D), row("Box"), row("Inner", "Box")]
    chart, diags = build(tables(states, [ev("e", "A", "A")]))
    assert chart is not None
    assert [s.name for s in chart.states] == ["A"]
    assert [d.code for d in diags].count("B207") == 2


@pytest.mark.parametrize("fmt", ["yaml", "csv", "xlsx", "md"])
def test_gantry_survives_every_format(tmp_path: Path, fmt: str) -> None:
    """The type and default columns round-trip through every format."""
    gantry, diags = load(GANTRY)
    assert gantry is not None, diags
    written = save(gantry, tmp_path / f"gantry.{fmt}", fmt)
    back, diags = load(written[0])
    assert diags == []
    assert back is not None
    assert strip_locations(back) == strip_locations(gantry)


@pytest.mark.parametrize("fmt", ["csv", "md"])
def test_flat_tables_are_written_without_the_hierarchy_columns(tmp_path: Path, fmt: str) -> None:
    """A device without type or default cells is written with the seven flat columns."""
    motor, _ = load(MOTOR / "motor.yaml")
    assert motor is not None
    written = save(motor, tmp_path / f"motor.{fmt}", fmt)
    text = written[0].read_text(encoding="utf-8")
    assert "type" not in text.split("\n")[1 if fmt == "csv" else 4]
    if fmt == "csv":
        assert text == (MOTOR / "motor.states.csv").read_text(encoding="utf-8")


def test_gantry_passes_check() -> None:
    """statectl check finds no error or warning in the gantry example (infos are advice)."""
    found = check_paths([str(GANTRY)])
    assert [str(d) for d in found if d.severity is not Severity.INFO] == []


# (event, active atomic states after it, invoke numbers notified)
GANTRY_RUN = [
    ("Start", {"Traversing", "Closing"}, [0]),
    ("Axis arrived", {"AtTarget", "Closing"}, []),
    ("Pause", {"Paused"}, [1]),
    ("Continue", {"AtTarget", "Closing"}, [1]),  # deep history: both regions as they were
    ("Grip done", {"Idle"}, []),  # both regions final: done.state.Cycle back to Idle
    ("Start", {"Traversing", "Closing"}, [0]),
    ("EStop", {"EStopped"}, [2]),  # the superstate's transition preempts the parallel
    ("Continue", {"EStopped"}, []),  # ignored
    ("Reset", {"Idle"}, [3]),
]


def test_gantry_runs_through_superstate_parallel_and_history() -> None:
    """Step by step: parallel regions, deep history after Pause, E-stop preempting all."""
    chart = load_chart(GANTRY)
    machine = Machine(chart)
    snapshot = initial(machine).target
    atomic = {s.name for s in chart.states if s.kind in (StateKind.ATOMIC, StateKind.FINAL)}
    assert snapshot.active & atomic == {"Idle"}
    seen = []
    for event, _, _ in GANTRY_RUN:
        result = step(machine, snapshot, event)
        snapshot = result.target
        notified = [a.invoke for a in result.actions if hasattr(a, "invoke")]
        seen.append((event, set(snapshot.active & atomic), notified))
    assert seen == [(e, set(s), n) for e, s, n in GANTRY_RUN]


class _Observer:
    def __init__(self) -> None:
        self.calls: list[str] = []

    def update(self, notification: Notification) -> None:
        self.calls.append(notification.method)


def test_gantry_runs_on_the_runtime_with_an_observer() -> None:
    """The Subject notifies the gantry's observer once per API-driving event."""
    subject = Subject(load_chart(GANTRY), clock=SimClock())
    observer = _Observer()
    subject.attach(observer)
    subject.start()
    for event, _, _ in GANTRY_RUN:
        subject.dispatch(event)
    assert observer.calls == ["Start", "Pause", "Pause", "Start", "EStop", "Reset"]
    assert "Idle" in subject.configuration
