"""``statectl testgen CELL``: each device's module, plus the cell's links tested on one System.

Rules:
1. Each device of the cell gets the module ``statectl testgen`` writes for its file
   alone (once per file, however many instances use it).
2. The links module has one test per (link, row) pair: a row of the link's source
   device whose step fires the link. Its path is the shortest sequence of events,
   each sent to one device and handled there, from the cell's start to a state
   where the row is taken, found breadth-first over the kernel's cell
   (:func:`~statectl.out.testgen.cellharness.reference_step`: every link the steps fire
   delivered). The test sends the path, then the row's event, and checks every
   device's state after the links have run and that the link's event reached its
   target (when the link's guard held).
3. ``--hypothesis`` for a cell writes a state machine that draws what the cell's
   environment may do now (inputs whose ``when`` holds, faults in monitored
   states, completions of calls its twin has pending), checks every device against the
   kernel's cell after each step, and the cell's invariants after every step.
"""

from __future__ import annotations

import os
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from statectl.cell.links import CellLinkRules
from statectl.cell.model import Cell, Trigger, load_cell_or_raise
from statectl.kernel.model import Chart
from statectl.kernel.semantics import compiled
from statectl.kernel.semantics import step as kernel_step
from statectl.out.escape.python import NAME_LIMIT, docstring, identifier
from statectl.out.testgen.cases import describe, where
from statectl.out.testgen.cellharness import CellState, reference_step
from statectl.out.testgen.generator import Generated, generate, write_atomic
from statectl.out.testgen.paths import leaves, sendable_events
from statectl.out.testgen.writer import _doc, _lit
from statectl.run.runtime import EventReceived, MicrostepTaken, Record

__all__ = ["CellCase", "CellGenerated", "cell_cases", "generate_cell", "generate_cell_hypothesis"]

#: Bound on the cell states the search visits.
MAX_CELL_NODES = 5_000


@dataclass(frozen=True, slots=True)
class CellCase:
    name: str
    doc: str
    given: tuple[tuple[str, str], ...]  # (device, event) sent first, each handled
    device: str
    event: str
    states: tuple[tuple[str, tuple[str, ...]], ...]  # every device's state afterwards
    delivered: tuple[tuple[str, str], ...]  # (target, link event) that must arrive


@dataclass(frozen=True, slots=True)
class CellGenerated:
    links: Path
    cases: tuple[CellCase, ...]
    notes: tuple[str, ...]
    devices: tuple[Generated, ...]


def _slug(text: str) -> str:
    return identifier(text)


def _key(state: CellState) -> tuple[Any, ...]:
    return tuple((snap, repr(data)) for snap, data in state)


def _first_step(records: list[Record]) -> list[Record]:
    """The records of the event sent (before the first link event is received)."""
    out: list[Record] = []
    seen = 0
    for r in records:
        if isinstance(r, EventReceived):
            seen += 1
            if seen == 2:
                break
        out.append(r)
    return out


def _fired(cell: Cell, device: str, first: list[Record]) -> list[int]:
    """The links the step recorded in ``first`` fires (statectl.cell.links)."""
    steps = [r for r in first if type(r) is MicrostepTaken and r.device == device]
    return list(CellLinkRules(cell.links).fired(device, steps))


def _within(chart: Chart, state: str, outer: str) -> bool:
    while True:
        if state == outer:
            return True
        parent = chart.state(state).parent
        if parent is None:
            return False
        state = parent


def _wanted(cell: Cell) -> set[tuple[int, int, bool]]:
    """(link, row, delivered) the search looks for: rows that may fire each link.

    Over-approximated (a row into a compound state may or may not enter the link's
    state): the search stops early only when every one is found.
    """
    out: set[tuple[int, int, bool]] = set()
    for i, k in enumerate(cell.links):
        chart = next(d.chart for d in cell.devices if d.name == k.source)
        for row, t in enumerate(chart.transitions, 1):
            if k.trigger is Trigger.RAISES:
                hit = k.what in t.events
            else:
                hit = any(_within(chart, x, k.what) or _within(chart, k.what, x) for x in t.targets)
            if hit:
                out |= {(i, row, True), (i, row, False)} if k.guard else {(i, row, True)}
    return out


def cell_cases(cell: Cell, *, max_nodes: int = MAX_CELL_NODES) -> tuple[list[CellCase], list[str]]:
    """One case per (link, row, guard outcome) the search finds (rule 2), and what it could not."""
    wanted = _wanted(cell)
    start, _ = reference_step(cell, None, None, "")
    index = {d.name: i for i, d in enumerate(cell.devices)}
    seen = {_key(start)}
    queue: deque[tuple[CellState, tuple[tuple[str, str], ...]]] = deque([(start, ())])
    found: dict[tuple[int, int, bool], CellCase] = {}
    complete = True
    while queue and not wanted <= found.keys():
        state, path = queue.popleft()
        for d in cell.devices:
            m = compiled(d.chart)
            snap, data = state[index[d.name]]
            for event in sendable_events(d.chart):
                decided = kernel_step(m, snap, event, dict(data))
                if not decided.handled:
                    continue
                after, records = reference_step(cell, state, d.name, event)
                for i in _fired(cell, d.name, _first_step(records)):
                    for t in decided.transitions:
                        row = next(n for n, x in enumerate(d.chart.transitions, 1) if x is t)
                        case = _case(cell, i, d.name, row, path, event, after, records)
                        found.setdefault((i, row, bool(case.delivered)), case)
                key = _key(after)
                if key in seen:
                    continue
                if len(seen) >= max_nodes:
                    complete = False
                    continue
                seen.add(key)
                queue.append((after, (*path, (d.name, event))))
    notes = []
    for i, k in enumerate(cell.links):
        if not any(j == i for j, _, _ in found):
            notes.append(
                f"link {i + 1} ({Path(k.where.file).name}:{k.where.line}) never fires "
                "from the cell's start"
            )
    if not complete:
        notes.append("the search stopped at its bound on cell states: some paths are missing")
    cases = [found[k] for k in sorted(found, key=lambda x: (x[0], x[1], not x[2]))]
    return cases, notes


def _case(
    cell: Cell,
    i: int,
    device: str,
    row: int,
    path: tuple[tuple[str, str], ...],
    event: str,
    after: CellState,
    records: list[Record],
) -> CellCase:
    k = cell.links[i]
    chart = next(d.chart for d in cell.devices if d.name == device)
    t = chart.transitions[row - 1]
    verb = "enters" if k.trigger is Trigger.ENTERS else "raises"
    got = {(r.device, r.event) for r in records if isinstance(r, EventReceived)}
    delivered = ((k.target, k.event),) if (k.target, k.event) in got else ()
    doc = (
        f"Link {i + 1}, {Path(k.where.file).name}:{k.where.line}: when {k.source} {verb} "
        f"{k.what}, send {k.event} to {k.target}; fired by {device} row {row}, "
        f"{where(t)}: {describe(t)}."
    )
    if not delivered:
        doc += " Its guard is false here, so nothing is sent."
    states = tuple((d.name, leaves(d.chart, after[n][0])) for n, d in enumerate(cell.devices))
    name = f"test_link_{i + 1:02d}_{_slug(k.source)}_{_slug(k.what)}_row_{row:02d}"
    name += "" if delivered else "_guard_false"
    return CellCase(name[:90], doc, path, device, event, states, delivered)


def _call(fn: str, args: list[str]) -> str:
    line = f"    c.{fn}({', '.join(args)})\n"
    if len(line) <= 101:
        return line
    return f"    c.{fn}(\n" + "".join(f"        {a},\n" for a in args) + "    )\n"


def _cell_case(c: CellCase) -> str:
    out = f"def {c.name}(statectl_cell):\n" + _doc(c.doc) + "    c = statectl_cell\n"
    if c.given:
        out += _call("given", [_lit([d, e]) for d, e in c.given])
    out += f"    c.send({_lit(c.device)}, {_lit(c.event)})\n"
    out += "    c.expect(\n        states={\n"
    out += "".join(f"            {_lit(d)}: {_lit(list(s))},\n" for d, s in c.states)
    out += "        },\n"
    out += f"        delivered={_lit([list(x) for x in c.delivered])},\n    )\n\n\n"
    return out


_HEADER = '''"""The links of cell {cell}, tested on one System: generated by statectl testgen.

Cell: {source}
Regenerate: statectl testgen {source} --out {out}
Each test brings the cell to where a row of a link's source device fires the link,
takes that row, and checks every device's state once the links have run. The
devices run on their simulated twins; override ``statectl_cell_new_drivers`` in a
conftest.py to test your drivers; see docs/testing.md.{notes}
"""

from __future__ import annotations

STATECTL_CELL = {tables}
'''


def _rel(source: Path, out: Path) -> str:
    return Path(os.path.relpath(source.resolve(), out.resolve())).as_posix()


def generate_cell(file: str | Path, criterion: str, out_dir: str | Path) -> CellGenerated:
    """Write each device's ``criterion`` module and the cell's links module (rules 1-2)."""
    source = Path(file)
    cell = load_cell_or_raise(source)
    out = Path(out_dir)
    devices: list[Generated] = []
    done: set[Path] = set()
    for d in cell.devices:
        path = Path(d.path).resolve()
        if path not in done:
            done.add(path)
            devices.append(generate(path, criterion, out))
    cases, notes = cell_cases(cell)
    text = _HEADER.format(
        cell=docstring(cell.name),
        source=docstring(str(file)),
        out=docstring(out.as_posix()),
        notes="".join(f"\n\nNote: {docstring(n)}." for n in notes),  # lines of their own
        tables=_lit(_rel(source, out)),
    )
    body = "".join(_cell_case(c) for c in cases)
    if not cases:
        body = (
            "def test_no_link_fires(statectl_cell):\n"
            '    """No row of this cell fires a link: the cell starts."""\n'
            "    assert statectl_cell.devices\n"
        )
    path = out / f"test_{identifier(cell.name, 'cell', NAME_LIMIT)}_links.py"
    write_atomic(path, text + "\n\n" + body.rstrip("\n") + "\n")
    return CellGenerated(path, tuple(cases), tuple(notes), tuple(devices))


_HYPOTHESIS = '''"""Cell {cell} under random environment sequences (statectl testgen --hypothesis).

Cell: {source}
Regenerate: statectl testgen {source} --hypothesis --out {out}
Hypothesis draws what the cell's environment may do now (its inputs whose `when`
holds, faults in monitored states, completions of calls its twin has pending); after every step
each device must be where the kernel's cell puts it, and every invariant of the
cell must hold. A failure shrinks to a short sequence. The devices run on their
simulated twins unless a conftest.py overrides ``statectl_cell_new_drivers``; see
docs/testing.md.
"""

from __future__ import annotations

from hypothesis import HealthCheck, assume, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule, run_state_machine_as_test

STATECTL_CELL = {tables}


def test_{slug}_follows_the_kernel_and_keeps_its_invariants(statectl_cell_factory):
    """After any sequence the environment may make, the cell did what the kernel decides."""

    class CellMachine(RuleBasedStateMachine):
        def __init__(self):
            super().__init__()
            self.cell = statectl_cell_factory()

        @rule(data=st.data())
        def send(self, data):
            allowed = self.cell.allowed()
            assume(allowed)
            device, event = data.draw(st.sampled_from(allowed))
            self.cell.step(device, event)

        @invariant()
        def invariants_hold(self):
            self.cell.assert_invariants()

    run_state_machine_as_test(
        CellMachine,
        settings=settings(
            max_examples=100,
            stateful_step_count=30,
            deadline=None,
            suppress_health_check=[HealthCheck.function_scoped_fixture],
        ),
    )
'''


def generate_cell_hypothesis(file: str | Path, out_dir: str | Path) -> Path:
    """Write ``test_CELL_hypothesis.py`` (rule 3)."""
    source = Path(file)
    cell = load_cell_or_raise(source)
    out = Path(out_dir)
    path = out / f"test_{identifier(cell.name, 'cell', NAME_LIMIT)}_hypothesis.py"
    text = _HYPOTHESIS.format(
        cell=docstring(cell.name),
        source=docstring(str(file)),
        out=docstring(out.as_posix()),
        tables=_lit(_rel(source, out)),
        slug=identifier(cell.name, "cell", NAME_LIMIT),
    )
    write_atomic(path, text)
    return path
