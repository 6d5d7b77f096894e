"""``statectl run CELL [--replay TRACE]``: a cell live on the runtime, with a readable trace.

Rules:
1. Each device instance is a :class:`~statectl.runtime.Subject` on one shared
   simulated clock; the cell's links are performed here, as the explorer composes
   them: after a device's step, the links its step triggered (in the cell file's
   order) whose guards hold in the new global state queue their events, and queued
   events are delivered first in, first out, each run to completion.
2. With ``--replay`` the stimuli come from a trace file (``statectl verify
   --traces``: JSON, or YAML with the same ``steps``); without it, a seeded random
   walk over the stimuli the explorer says are enabled.
3. After every step the devices' states are compared with what the trace (or the
   explorer) expects; a difference is reported as a divergence (the command,
   :mod:`statectl.cli.replay`, then exits 1). A free
   choice the runtime cannot make the trace's way shows up there.
4. Invariants are checked after every step and reported when they fail, so a
   replayed counterexample shows its failure on the simulated devices.
5. :class:`CellLinks` is rule 1's link part alone, for any host of running
   Subjects: this runner, and ``statectl run CELL --dashboard/--journal``
   (:mod:`statectl.cli.run`).
"""

from __future__ import annotations

import os
import random
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from statectl.cell import Cell, InputKind, Link, Trigger
from statectl.errors import StatectlError
from statectl.explore.compose import Composed, Stimulus
from statectl.runtime import (
    EventIgnored,
    Record,
    SimClock,
    StateEntered,
    Subject,
    TransitionTaken,
    format_record,
)
from statectl.tables import safeyaml

__all__ = ["CellLinks", "CellRun", "ReplayStep", "load_replay", "run_cell"]


@dataclass(frozen=True, slots=True)
class ReplayStep:
    kind: InputKind
    device: str
    event: str
    expect: tuple[tuple[str, str], ...] = ()  # (device, state label) after the step


def load_replay(path: str | os.PathLike[str]) -> list[ReplayStep]:
    """The stimuli of a trace file; raises :class:`StatectlError` saying what is wrong."""
    try:
        doc: Any = safeyaml.load_value(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise StatectlError(f"{path}: cannot read the trace: {exc}") from exc
    except safeyaml.YamlRefused as exc:
        where = f"{path}:{exc.line}" if exc.line else str(path)
        raise StatectlError(f"{where}: {exc.code}: {exc.message}") from None
    steps = doc.get("steps") if isinstance(doc, dict) else doc
    if not isinstance(steps, list):
        raise StatectlError(f"{path}: a trace is a mapping with 'steps:' (a list)")
    out: list[ReplayStep] = []
    kinds = {k.value: k for k in InputKind}
    for i, s in enumerate(steps, 1):
        if not isinstance(s, dict) or not {"to", "event"} <= set(s):
            raise StatectlError(f"{path}: step {i} needs 'to' and 'event'")
        kind = kinds.get(str(s.get("source", "environment")))
        if kind is None:
            raise StatectlError(f"{path}: step {i}: source must be one of {', '.join(kinds)}")
        state = s.get("state") or {}
        pairs = state.items() if isinstance(state, dict) else ()
        expect = tuple((str(k), str(v)) for k, v in pairs)
        out.append(ReplayStep(kind, str(s["to"]), str(s["event"]), expect))
    return out


@dataclass(frozen=True, slots=True)
class CellRun:
    steps: int
    divergences: tuple[str, ...]
    violations: tuple[str, ...]
    unhandled: tuple[str, ...]


class CellLinks:
    """A cell's links over running Subjects: which links a step fired, and whether they hold.

    Listen with :meth:`watch` on every device; after a device's step, :meth:`due`
    gives the links that step fired whose guards hold in the global state now, in
    the cell file's order, and forgets them.
    """

    def __init__(
        self, cell: Cell, subjects: Mapping[str, Subject], model: Composed | None = None
    ) -> None:
        self.cell = cell
        self.model = model if model is not None else Composed(cell)
        self.subjects = subjects
        self.fired: list[int] = []

    def watch(self, r: Record) -> None:
        for i, k in enumerate(self.cell.links):
            if k.source != r.device:
                continue
            entered = isinstance(r, StateEntered) and r.state == k.what
            took = isinstance(r, TransitionTaken) and r.event == k.what
            if (k.trigger is Trigger.ENTERS and entered) or (k.trigger is Trigger.RAISES and took):
                self.fired.append(i)

    def state(self) -> int:
        """The explorer's packed global state for the subjects' snapshots."""
        g = 0
        for d, space in enumerate(self.model.spaces):
            subject = self.subjects[self.model.names[d]]
            snap = subject.snapshot
            lid = space.lookup(snap, subject.data) if snap is not None else None
            if lid is None:
                raise StatectlError(f"{self.model.names[d]} is in a state the explorer never saw")
            g = self.model.replace(g, d, lid)
        return g

    def due(self) -> list[Link]:
        """The links fired since the last call whose guards hold now (rule 1)."""
        if not self.fired:
            return []
        fired = sorted(set(self.fired))
        self.fired.clear()
        g = self.state()
        out = []
        for i in fired:
            guard = self.model.link_guard[i]
            if guard is None or guard(g):
                out.append(self.cell.links[i])
        return out


class _Runner:
    def __init__(self, cell: Cell, write: Callable[[str], object]) -> None:
        self.cell = cell
        self.model = Composed(cell)
        self.clock = SimClock()
        width = max(len(d.name) for d in cell.devices)
        self.out = write
        self.width = width
        self.subjects: dict[str, Subject] = {}
        self.links = CellLinks(cell, self.subjects, self.model)
        self.unhandled: list[str] = []
        self.delivering: tuple[str, str] | None = None
        for d in cell.devices:
            s = Subject(d.chart, clock=self.clock, name=d.name)
            s.listen(self._trace)
            s.listen(self.links.watch)
            s.listen(self._watch)
            self.subjects[d.name] = s
        for s in self.subjects.values():
            s.start()
            s.run_until_idle()
        self.links.fired.clear()

    def _trace(self, r: Record) -> None:
        self.out(format_record(r, device_width=self.width) + "\n")

    def _watch(self, r: Record) -> None:
        if (
            isinstance(r, EventIgnored)
            and self.delivering == (r.device, r.event)
            and r.reason in ("no transition", "unknown event")
        ):
            self.unhandled.append(f"{r.device} gets {r.event} ({r.reason})")

    def state(self) -> int:
        return self.links.state()

    def _step(self, device: str, event: str) -> None:
        self.links.fired.clear()
        self.subjects[device].post(event)
        self.subjects[device].run_until_idle()

    def perform(self, device: str, event: str) -> None:
        """Rule 1: one stimulus and its cascade of link deliveries."""
        queue: deque[tuple[str, str]] = deque()
        self._step(device, event)
        queue.extend(self._links())
        count = 0
        while queue and count < 256:
            target, ev = queue.popleft()
            self.delivering = (target, ev)
            self._step(target, ev)
            self.delivering = None
            queue.extend(self._links())
            count += 1

    def _links(self) -> list[tuple[str, str]]:
        out = []
        for k in self.links.due():
            self.out(f"          link: {k.label}\n")
            out.append((k.target, k.event))
        return out


def run_cell(
    cell: Cell,
    write: Callable[[str], object] = lambda text: None,
    *,
    replay: Sequence[ReplayStep] | None = None,
    walk: int = 20,
    seed: int = 0,
) -> CellRun:
    """Run ``cell`` on the runtime (rules 1-4); each piece of the trace goes to ``write``."""
    r = _Runner(cell, write)
    m = r.model
    invariants = [(inv.name, m.predicate(inv.expr)) for inv in cell.invariants]
    rng = random.Random(seed)
    divergences: list[str] = []
    violations: list[str] = []
    plan = list(replay) if replay is not None else None
    n = len(plan) if plan is not None else walk
    done = 0
    for i in range(n):
        g = r.state()
        if plan is not None:
            step = plan[i]
            if step.device not in r.subjects:
                divergences.append(f"step {i + 1}: the cell has no device {step.device!r}")
                break
            stim = Stimulus(step.kind, m.position[step.device], step.event)
            offered = {(s.kind, s.device, s.event) for s in m.enabled(g)}
            if (stim.kind, stim.device, stim.event) not in offered:
                divergences.append(
                    f"step {i + 1}: {stim.label(m.names)} is not offered in {m.describe(g)}"
                )
        else:
            choices = [s for s in m.enabled(g) if m.successors(g, s)]
            if not choices:
                write("--- no stimulus can change the cell: deadlock\n")
                break
            stim = rng.choice(choices)
        write(f"--- step {i + 1}: {stim.label(m.names)}\n")
        expected = {h for h, _, _ in m.successors(g, stim)}
        r.perform(m.names[stim.device], stim.event)
        done += 1
        h = r.state()
        if plan is not None and plan[i].expect:
            got = dict(zip(m.names, m.labels(h), strict=True))
            diff = [
                f"{d} is {got.get(d)} (trace: {s})" for d, s in plan[i].expect if got.get(d) != s
            ]
            if diff:
                divergences.append(f"step {i + 1}: " + "; ".join(diff))
        elif expected and h not in expected:
            divergences.append(
                f"step {i + 1}: runtime reached {m.describe(h)}, which the explorer does not"
            )
        for name, fn in invariants:
            if not fn(h):
                violations.append(f"step {i + 1}: invariant {name} fails in {m.describe(h)}")
                write(f"--- invariant {name} fails\n")
    result = CellRun(done, tuple(divergences), tuple(violations), tuple(r.unhandled))
    for text in result.unhandled:
        write(f"unhandled link event: {text}\n")
    for text in result.divergences:
        write(f"diverged: {text}\n")
    write(f"{done} step(s); final: {m.describe(r.state())}\n")
    return result
