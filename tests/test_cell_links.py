"""One cell semantics (issue 26): verify, the System and a node fire the same links.

Whether a step fires a link is statectl.cell.links alone. These tests run random cells
(small devices with a compound state whose final child raises ``done.state.Job``,
``enters`` and ``raises`` links guarded by ``In()``) through the three hosts as each
is wired: the explorer (``Composed``), a :class:`~statectl.run.system.System` and a
:class:`~statectl.channels.distributed.system.NodeSystem` (its devices all on one
node, no wire opened). Every step either host runs is compared, step by step, with
the links the other fired and the explorer's answer for the same step.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from statectl.cell.explore.compose import Composed
from statectl.cell.links import CellLinkRules, Send, triggers
from statectl.cell.model import Cell, Link, Trigger
from statectl.cell.nodes import LinkDelivery, Node, Nodes
from statectl.cell.values import DeviceRef, GlobalExpr
from statectl.channels.distributed.system import NodeSystem
from statectl.front.builder.build import build
from statectl.front.tables import DeviceTables, EventRow, StateRow
from statectl.kernel.errors import Location
from statectl.kernel.model import Chart, ControlKind, EventKind, StateKind
from statectl.kernel.semantics import Microstep
from statectl.run.runtime import SimClock, StepRecord
from statectl.run.system import DeviceSetup, System

HERE = Location("random-cell.yaml", 1)
TOPS = ("A", "B", "C")
INNER = ("Job", "Work", "Done")  # Job's final child Done raises done.state.Job
DONE = "done.state.Job"
STIMULI = ("Go", "Stop", "Finish")
TRIGGER = ControlKind.TRIGGER


def _state(
    name: str, control: ControlKind, *, parent: str = "", kind: StateKind | None = None
) -> StateRow:
    return StateRow("Dev", "", name, (control,), "", (), parent, type=kind)


@st.composite
def devices(draw: st.DrawFn) -> Chart:
    """A device: top states, Job (Work, then the final Done), rows on Go/Stop/Finish and
    done.state.Job, some guarded by In() of its own states."""
    tops = TOPS[: draw(st.integers(2, 3))]
    states = [
        *(_state(n, ControlKind.DEFAULT if n == "A" else TRIGGER) for n in tops),
        _state("Job", TRIGGER),
        _state("Work", ControlKind.DEFAULT, parent="Job"),
        _state("Done", TRIGGER, parent="Job", kind=StateKind.FINAL),
    ]
    rows = [
        EventRow("Go", "", "", tops[0], "Job", EventKind.INTERNAL, ""),
        EventRow("Finish", "", "", "Work", "Done", EventKind.INTERNAL, ""),
        EventRow(DONE, "", "", "Job", draw(st.sampled_from(tops)), EventKind.INTERNAL, ""),
    ]
    for _ in range(draw(st.integers(0, 4))):
        event = draw(st.sampled_from(("Go", "Stop")))
        old = draw(st.sampled_from((*tops, "Job", "Work")))
        new = draw(st.sampled_from((*tops, "Job")))
        guard = draw(st.sampled_from(("", f"In('{tops[1]}')", "not In('Work')")))
        rows.append(EventRow(event, "", guard, old, new, EventKind.INTERNAL, ""))
    chart, diags = build(DeviceTables("Dev", tuple(states), tuple(rows)))
    assert chart is not None, [str(d) for d in diags]
    return chart


@st.composite
def cells(draw: st.DrawFn) -> Cell:
    """2-3 random devices and 1-5 links from a device to a later one (no livelock)."""
    charts = draw(st.lists(devices(), min_size=2, max_size=3))
    names = [f"d{i}" for i in range(len(charts))]
    refs = tuple(DeviceRef(n, f"{n}.yaml", c, HERE) for n, c in zip(names, charts, strict=True))
    links = []
    for _ in range(draw(st.integers(1, 5))):
        s = draw(st.integers(0, len(names) - 2))
        t = draw(st.integers(s + 1, len(names) - 1))
        source = charts[s]
        if draw(st.booleans()):
            states = tuple(x.name for x in source.states)
            trigger, what = Trigger.ENTERS, draw(st.sampled_from(states))
        else:
            # done.state.Job often: a raises link on an event the device raises itself
            events = (DONE, *source.event_names)
            trigger, what = Trigger.RAISES, draw(st.sampled_from(events))
        device = draw(st.sampled_from(names))
        state = draw(st.sampled_from(tuple(x.name for x in charts[names.index(device)].states)))
        text = draw(st.sampled_from(("", "In('{}')", "not In('{}')"))).format(f"{device}.{state}")
        guard = GlobalExpr(text, ((device, state),), HERE) if text else None
        event = draw(st.sampled_from(STIMULI))
        links.append(Link(names[s], trigger, what, names[t], event, guard, HERE))
    return Cell("Random", "random-cell.yaml", refs, tuple(links), completions=False)


@dataclass
class _Taken:
    """One step a host ran: the device, its event, the explorer's states around it, and
    the links (indices) the host sent after it."""

    device: str
    event: str | None
    before: int
    after: int
    g: int
    sent: list[int]


class _Host:
    """A System (or NodeSystem) of the cell as wired by its own code: each step it runs,
    and the links its firing function (``links.due_links``, asked after each step)
    returned."""

    def __init__(self, system: System) -> None:
        self.system = system
        self.steps: list[_Taken] = []
        links = system.links
        assert links is not None
        self.links = links
        self.lids: dict[str, int] = {}
        due = links.due_links

        def sent() -> tuple[int, ...]:
            out = due()
            if self.steps:
                self.steps[-1].sent.extend(out)
            return out

        links.due_links = sent  # type: ignore[method-assign]
        for name, subject in system.subjects.items():
            subject.listen_steps(self._heard(name))

    def _heard(self, name: str) -> Any:
        def heard(step: StepRecord) -> None:
            if step.event is None:
                return
            g = self.links.state()
            after = self.links.model.local(g, self.links.model.position[name])
            self.steps.append(_Taken(name, step.event, self.lids[name], after, g, []))
            self.lids[name] = after

        return heard

    def start(self) -> None:
        """Start the devices; their steps from now on are the ones compared."""
        self.system.start()
        self.system.drain()
        self.steps.clear()
        model, g = self.links.model, self.links.state()
        self.lids = {n: model.local(g, model.position[n]) for n in model.names}

    def run(self, device: str, event: str) -> None:
        self.system.post(device, event)
        self.system.drain()


def _system(cell: Cell) -> System:
    setups = [DeviceSetup(d.name, d.chart) for d in cell.devices]
    return System(setups, SimClock(), cell=cell, enforce=False)


class _NoWire:
    """Every device of the cell runs on this node: nothing ever goes over the wire."""

    def down(self, link: Link) -> bool:
        raise AssertionError(f"{link.label} went to the wire")

    def send(self, device: str, event: str, data: Any) -> None:
        raise AssertionError(f"{device}.{event} went to the wire")

    forward = send


def _node(cell: Cell) -> System:
    one = Node("n", tuple(d.name for d in cell.devices))
    cell = replace(cell, nodes=Nodes((one,), tuple(LinkDelivery() for _ in cell.links)))
    setups = [DeviceSetup(d.name, d.chart) for d in cell.devices]
    system = NodeSystem(setups, SimClock(), None, cell)
    system.attach(_NoWire(), {})
    return system


def _explorer_fires(model: Composed, step: _Taken) -> list[int]:
    """The links the explorer fires for the same step: the outcome it has from the state
    before to the state after, and the link guards in the global state after."""
    d = model.position[step.device]
    assert step.event is not None
    if step.event not in model.spaces[d].events:  # the host says unknown event: no step
        assert step.after == step.before
        return []
    outs = [o for o in model.outcomes(d, step.before, step.event) if o.target == step.after]
    assert outs, f"the explorer never takes {step.device} {step.event} to that state"
    return [i for _, _, i in model.sends(model.fires(d, outs[0]), step.g)]


def _check(cell: Cell, stimuli: list[tuple[int, int]]) -> None:
    model = Composed(cell)
    hosts = {"System": _Host(_system(cell)), "node": _Host(_node(cell))}
    for host in hosts.values():
        host.start()
    names = model.names
    for device, event in stimuli:
        for host in hosts.values():
            host.run(names[device % len(names)], STIMULI[event % len(STIMULI)])
    system, node = (hosts[k].steps for k in ("System", "node"))
    for n, (a, b) in enumerate(zip(system, node, strict=True), 1):
        at = f"step {n}: {a.device} {a.event}"
        assert (a.device, a.event, a.after) == (b.device, b.event, b.after), at
        explorer = _explorer_fires(model, a)
        assert a.sent == explorer, f"{at}: the System sent {a.sent}, verify fires {explorer}"
        assert b.sent == explorer, f"{at}: the node sent {b.sent}, verify fires {explorer}"
    for host in hosts.values():  # every link the host decided on was sent: one step each
        assert len(host.steps) == len(stimuli) + sum(len(t.sent) for t in host.steps)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cells(), st.lists(st.tuples(st.integers(0, 2), st.integers(0, 2)), max_size=16))
def test_explorer_system_and_node_fire_the_same_links(
    cell: Cell, stimuli: list[tuple[int, int]]
) -> None:
    """On random cells and commands, every step the System and a node run sends exactly
    the links the explorer fires for that step (statectl.cell.links)."""
    _check(cell, stimuli)


def _micro(event: str | None, entered: tuple[str, ...], took: bool = True) -> Microstep:
    return Microstep(event, ("t",) if took else (), (), entered, ())  # type: ignore[arg-type]


def _link(trigger: Trigger, what: str, guard: str = "") -> Link:
    expr = GlobalExpr(guard, (), HERE) if guard else None
    return Link("a", trigger, what, "b", "Go", expr, HERE)


@pytest.mark.parametrize(
    ("link", "microsteps", "fires"),
    [
        (_link(Trigger.RAISES, "Finish"), [_micro("Finish", ("Done",))], True),
        # a transition on an event the device raised itself during the step (rule 3)
        (_link(Trigger.RAISES, DONE), [_micro("Finish", ("Done",)), _micro(DONE, ("A",))], True),
        (_link(Trigger.RAISES, DONE), [_micro("Finish", ("Done",))], False),
        (_link(Trigger.RAISES, "Finish"), [_micro("Finish", (), took=False)], False),
        (_link(Trigger.ENTERS, "A"), [_micro("Finish", ("Done",)), _micro(DONE, ("A",))], True),
        (_link(Trigger.ENTERS, "A"), [_micro(None, ("B",))], False),
        (_link(Trigger.ENTERS, "B"), [_micro(None, ("B",))], True),  # an eventless microstep
        (_link(Trigger.RAISES, "Finish"), [], False),  # unhandled: no microstep
    ],
)
def test_a_link_fires_on_any_microstep_of_its_sources_step(
    link: Link, microsteps: list[Microstep], fires: bool
) -> None:
    """``enters S`` fires when any microstep entered S, ``raises E`` when any took a
    transition on E, the device's own raised events included (cell/links.py rules 1-3)."""
    rules = CellLinkRules((link,))
    assert rules.fired("a", microsteps) == ((0,) if fires else ())
    assert rules.fired("b", microsteps) == ()  # only the link's source fires it


def test_a_link_fires_once_per_step_in_file_order_and_sends_its_data() -> None:
    """Two microsteps matching one link fire it once; fired links come in the cell file's
    order, guarded ones only where the guard holds, each with its data (rules 4-6)."""
    links = (
        replace(_link(Trigger.ENTERS, "Done"), data={"n": 1}),
        replace(_link(Trigger.RAISES, "Go", guard="x"), forward_data=True),
        _link(Trigger.ENTERS, "A"),
    )
    steps = [_micro("Go", ("A",)), _micro("Finish", ("Done", "A"))]
    rules = CellLinkRules(links)
    assert triggers(steps).entered == {"A", "Done"}
    asked: list[str] = []

    def state() -> str:
        asked.append("state")
        return "now"

    def no(g: str) -> bool:
        return False

    def yes(g: str) -> bool:
        return g == "now"

    assert rules.fire("a", steps, (None, yes, None), state, "d") == (
        Send(0, "b", "Go", {"n": 1}),
        Send(1, "b", "Go", "d"),
        Send(2, "b", "Go", None),
    )
    assert asked == ["state"]  # asked once, for the one guarded link
    assert [s.link for s in rules.fire("a", steps, (None, no, None), state)] == [0, 2]
    asked.clear()
    assert rules.fire("a", [_micro("Go", ())], (None, None, None), state) == (
        Send(1, "b", "Go", None),
    )
    assert asked == []  # no guard among the fired: the global state is never packed
