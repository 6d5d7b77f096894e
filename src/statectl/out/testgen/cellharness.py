"""A cell under test: its devices on one System with its links, checked against the kernel.

Rules:
1. The cell under test is a :class:`~statectl.run.system.System` of the cell's devices,
   each wired to its driver (the tables' simulated twin unless the test gives
   one), with the cell's links, on a :class:`~statectl.run.runtime.SimClock` that only
   :meth:`CellUnderTest.advance` moves.
2. The oracle is the kernel with the cell's links and no drivers
   (:func:`reference_step`): plain Subjects restored to the devices' snapshots
   and data, the event posted, every link the steps fire delivered, in the
   System's order (rule 3 of :mod:`statectl.run.system`), until nothing is queued.
3. A cell's invariants are global expressions (``In('device.State')``, ``and``,
   ``or``, ``not``, ``True``, ``False``) read over the devices' active states.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from statectl.cell.explore import Composed
from statectl.cell.explore.conditions import bind_cross_guards
from statectl.cell.explore.replay import CellLinks
from statectl.cell.model import Cell
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import ControlKind, EventKind, StateKind
from statectl.kernel.semantics import Snapshot, Unhandled
from statectl.kernel.semantics import step as kernel_step
from statectl.out.testgen.adapters.runtime import Recorder
from statectl.out.testgen.harness import api_function
from statectl.run.devices import SimTwin
from statectl.run.runtime import (
    EventIgnored,
    EventReceived,
    EventRejected,
    ObserverCalled,
    Record,
    SimClock,
    Subject,
)
from statectl.run.system import DeviceSetup, System

__all__ = ["CellState", "CellUnderTest", "reference_step"]

#: Per device of the cell (in its order): the snapshot and the datamodel.
CellState = tuple[tuple[Snapshot, tuple[tuple[str, Any], ...]], ...]


def _leaves(s: Subject) -> tuple[str, ...]:
    m = s.machine
    return tuple(
        x
        for x in sorted(s.configuration, key=m.order.__getitem__)
        if m.kind[x] in (StateKind.ATOMIC, StateKind.FINAL)
    )


_MODELS: dict[int, tuple[Cell, Composed]] = {}


def _composed(cell: Cell) -> Composed:
    """The explorer's model of ``cell`` (what link guards are read over), built once."""
    hit = _MODELS.get(id(cell))
    if hit is None or hit[0] is not cell:
        if len(_MODELS) > 16:
            _MODELS.clear()
        hit = _MODELS[id(cell)] = (cell, Composed(cell))
    return hit[1]


def _settle(subjects: Mapping[str, Subject], links: CellLinks, ready: deque[Subject]) -> None:
    """Run the devices with work until none has; deliver the links each step fires."""

    def deliver(_event: str, data: Any, _outcome: str) -> None:
        for send in links.sends(data):
            subjects[send.target].post(send.event, send.data)

    offs = [s.on_step(deliver) for s in subjects.values()]
    while ready:
        s = ready.popleft()
        if s.queued:
            s.run_until_idle()
    for off in offs:
        off()


def reference_step(
    cell: Cell, state: CellState | None, device: str | None, event: str, data: Any = None
) -> tuple[CellState, list[Record]]:
    """The kernel's answer (rule 2): the cell's state after ``event`` reaches ``device``.

    ``state`` ``None`` starts every device; ``device`` ``None`` only starts them.
    """
    clock = SimClock()
    subjects: dict[str, Subject] = {}
    ready: deque[Subject] = deque()
    for i, d in enumerate(cell.devices):
        values = dict(state[i][1]) if state is not None else None
        s = Subject(d.chart, clock=clock, name=d.name, data=values)
        s.on_queued(ready.append)
        subjects[d.name] = s
    bind_cross_guards(subjects)  # guards reading another device, as the System does
    links = CellLinks(cell, subjects, _composed(cell))
    records: list[Record] = []
    for s in subjects.values():
        s.listen(links.watch)
        s.listen(records.append)
    for i, s in enumerate(subjects.values()):
        if state is None:
            s.start()
        else:
            s.restore(state[i][0])
    links.fired.clear()  # entering the initial or restored states fires nothing
    ready.extend(subjects.values())
    _settle(subjects, links, ready)
    records.clear()
    if device is not None:
        subjects[device].post(event, data)
        _settle(subjects, links, ready)
    after = tuple(
        (s.snapshot or Snapshot(frozenset()), tuple(s.data.items())) for s in subjects.values()
    )
    return after, records


class CellUnderTest:
    """A started cell (rule 1) whose events can be checked against the kernel (rule 2)."""

    def __init__(
        self,
        cell: Cell,
        drivers: Mapping[str, Any] | None = None,
        *,
        event_data: Mapping[str, Mapping[str, Any]] | None = None,
        strict: bool = False,
    ) -> None:
        self.cell = cell
        self.strict = strict
        self.clock = SimClock()
        given = dict(drivers or {})
        unknown = sorted(set(given) - {d.name for d in cell.devices})
        if unknown:
            raise StatectlError(
                f"drivers for {unknown}: not devices of cell {cell.name!r} "
                f"({', '.join(d.name for d in cell.devices)})"
            )
        self.drivers = {
            d.name: given.get(d.name) if given.get(d.name) is not None else SimTwin(d.chart)
            for d in cell.devices
        }
        setups = [
            DeviceSetup(d.name, d.chart, source=d.path, driver=self.drivers[d.name])
            for d in cell.devices
        ]
        # the links under test are driven from any state: the environment's `when` and
        # the invariants' reactions are the cell's run-time rules, not the links'
        self.system = System(setups, self.clock, cell=cell, enforce=False)
        self.event_data = {k: dict(v) for k, v in (event_data or {}).items()}
        self.recorder = Recorder()
        self.system.listen(self.recorder)
        self.sent: list[str] = []
        self.system.start()
        # whether an invariant or an input's `when` holds: the compiled model's answer, as
        # the System's enforcement and the explorer ask it (cell/explore/compose.py)
        links = self.system.links
        assert links is not None  # a System given a cell has its links
        self._links = links
        self._invariants = [(inv.name, links.model.predicate(inv.expr)) for inv in cell.invariants]

    # -- reading -------------------------------------------------------------------------------

    @property
    def devices(self) -> tuple[str, ...]:
        return tuple(d.name for d in self.cell.devices)

    def subject(self, device: str) -> Subject:
        return self.system.subjects[self.system.device(device)]

    def states(self, device: str) -> tuple[str, ...]:
        """The device's active atomic states in document order."""
        return _leaves(self.subject(device))

    def state(self) -> CellState:
        """Every device's snapshot and data (what :func:`reference_step` starts from)."""
        out = []
        for name in self.devices:
            s = self.system.subjects[name]
            out.append((s.snapshot or Snapshot(frozenset()), tuple(s.data.items())))
        return tuple(out)

    def broken_invariants(self) -> list[str]:
        """The names of the cell's invariants that do not hold now."""
        g = self._links.state()
        return [name for name, holds in self._invariants if not holds(g)]

    def allowed(self) -> list[tuple[str, str]]:
        """What the outside world may do now: the cell's environment and the completions.

        A ``send`` input when its ``when`` holds; a ``fault`` while its device is in a
        state that requires monitoring; a device's completion event while its state
        handles it (unless the cell says ``completions: off``) and, on a simulated twin,
        only while a call it completes is pending (or its row says ``unasked``): the
        twin's model, :mod:`statectl.kernel.semantics.calls`, which verify assumes too.
        """
        g = self._links.state()
        out: list[tuple[str, str]] = []
        for inp, when in zip(self.cell.environment, self._links.model.when, strict=True):
            s = self.system.subjects[inp.device]
            if inp.kind.value == "fault":
                monitored = any(
                    ControlKind.MONITORING in s.chart.state(x).controls for x in s.configuration
                )
                if monitored:
                    out.append((inp.device, inp.event))
            elif when is None or when(g):
                out.append((inp.device, inp.event))
        if self.cell.completions:
            for name in self.devices:
                s = self.system.subjects[name]
                snap = s.snapshot
                if snap is None:
                    continue
                for event in s.chart.event_names:
                    d = s.chart.event(event)
                    if d is None or d.kind is not EventKind.COMPLETION:
                        continue
                    twin = self.drivers.get(name)
                    if isinstance(twin, SimTwin) and not twin.calls.completes(
                        twin.pending_calls, event
                    ):
                        continue
                    if kernel_step(s.machine, snap, event, s.data).handled:
                        out.append((name, event))
        return out

    # -- driving -------------------------------------------------------------------------------

    def _path(self) -> str:
        return "after " + (" -> ".join(self.sent) if self.sent else "the start")

    def send(self, device: str, event: str, data: Any = None) -> None:
        """Post ``event`` to ``device`` and run the cell until nothing is queued (links too)."""
        __tracebackhide__ = True
        self.recorder.mark = len(self.recorder.records)
        self.sent.append(f"{device}: {event}")
        if data is None:
            data = self.event_data.get(device, {}).get(event)
        twin = self.drivers.get(device)
        # a completion the twin has a call pending for is the twin's own report: it
        # settles the call (statectl.kernel.semantics.calls), as verify assumes
        reported = isinstance(twin, SimTwin) and twin.complete_now(event)
        if not reported:
            self.system.post(device, event, data)
        self.system.drain()
        if self.strict:
            missed = [
                f"{r.device} gets {r.event}"
                for r in self.recorder.since_mark()
                if isinstance(r, EventIgnored | EventRejected)
                and r.reason is Unhandled.NO_TRANSITION
            ]
            if missed:
                raise AssertionError(
                    f"{self._path()}: {', '.join(missed)}: a pair the tables neither handle "
                    "nor ignore (statectl_strict); add a row or an ignore entry"
                )

    def given(self, *steps: Sequence[str]) -> None:
        """Send each ``[device, event]`` in turn; each must be handled by its device."""
        __tracebackhide__ = True
        for device, event in steps:
            self.send(device, event)
            first = self._outcome(device, event)
            if first is not None:
                raise AssertionError(
                    f"{self._path()}: {event!r} was not handled by {device} in the path to "
                    f"the case ({first})"
                )

    def _outcome(self, device: str, event: str) -> str | None:
        """Why the last sent event was not handled by its device (``None``: it was)."""
        for r in self.recorder.since_mark():
            if r.device != device:
                continue
            if isinstance(r, EventIgnored | EventRejected) and r.event == event:
                return r.reason.value
            if isinstance(r, EventReceived) and r.event != event:
                break
        return None

    def advance(self, seconds: float) -> None:
        """Move the simulated clock on: the drivers' completions arrive, links follow."""
        self.system.advance(seconds)

    def step(self, device: str, event: str) -> None:
        """Send ``event`` and check every device against the kernel's cell (rule 2)."""
        __tracebackhide__ = True
        want, _ = reference_step(self.cell, self.state(), device, event)
        self.send(device, event)
        problems = []
        for i, name in enumerate(self.devices):
            s = self.system.subjects[name]
            m = s.machine
            expected = [
                x
                for x in sorted(want[i][0].active, key=m.order.__getitem__)
                if m.kind[x] in (StateKind.ATOMIC, StateKind.FINAL)
            ]
            if tuple(expected) != _leaves(s):
                problems.append(f"{name}: expected {expected}, it is in {list(_leaves(s))}")
        if problems:
            raise AssertionError(f"{self._path()}: " + "; ".join(problems))

    # -- checking ------------------------------------------------------------------------------

    def expect(
        self,
        *,
        states: Mapping[str, Sequence[str]],
        delivered: Iterable[Sequence[str]] = (),
    ) -> None:
        """After the last event: each device named is in its states; each link event arrived."""
        __tracebackhide__ = True
        problems = []
        for name, want in states.items():
            if tuple(want) != self.states(name):
                problems.append(
                    f"{name}: expected {list(want)}, it is in {list(self.states(name))}"
                )
        got = [
            (r.device, r.event) for r in self.recorder.since_mark() if isinstance(r, EventReceived)
        ]
        for device, event in delivered:
            if (device, event) not in got:
                problems.append(f"the link's {event!r} never reached {device} (received: {got})")
        if problems:
            raise AssertionError(f"{self._path()}: " + "; ".join(problems))

    def assert_state(self, device: str, *states: str) -> None:
        """``device`` is in exactly ``states``."""
        __tracebackhide__ = True
        if tuple(states) != self.states(device):
            raise AssertionError(
                f"{self._path()}: {device}: expected the state {list(states)}, "
                f"it is in {list(self.states(device))}"
            )

    def assert_called(self, device: str, name: str) -> None:
        """The last event made ``device``'s driver call ``name`` (API function or method)."""
        __tracebackhide__ = True
        called = [
            (r.method, r.api)
            for r in self.recorder.since_mark()
            if isinstance(r, ObserverCalled) and r.device == device
        ]
        if not any(name in (m, api_function(api)) for m, api in called):
            raise AssertionError(
                f"{self._path()}: expected {device}'s driver to call {name}(), it called "
                f"{[api for _, api in called] or 'nothing'}"
            )

    def assert_invariants(self) -> None:
        """Every invariant of the cell holds now."""
        __tracebackhide__ = True
        broken = self.broken_invariants()
        if broken:
            shown = {n: list(self.states(n)) for n in self.devices}
            raise AssertionError(f"{self._path()}: invariant {', '.join(broken)} broken: {shown}")
