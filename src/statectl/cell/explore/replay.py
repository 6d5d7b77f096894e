"""``statectl run CELL [--replay TRACE]``: a cell live on the runtime, with a readable trace.

Rules:
1. Each device instance is a :class:`~statectl.run.runtime.Subject` on one shared
   simulated clock; the cell's links are performed here, as the explorer composes
   them: after a device's step, the links its step triggered (in the cell file's
   order) whose guards hold in the new global state queue their events, and queued
   events are delivered first in, first out, each run to completion.
2. With ``--replay`` the stimuli come from a trace file (``statectl verify
   --traces``: JSON, or YAML with the same ``steps``); without it, a seeded random
   walk over the stimuli the explorer says are enabled.
3. After every step the devices' states are compared with what the trace (or the
   explorer) expects; a difference is reported as a divergence (the command,
   :mod:`statectl.channels.cli.replay`, then exits 1). A free
   choice the runtime cannot make the trace's way shows up there.
4. Invariants are checked after every step and reported when they fail, so a
   replayed counterexample shows its failure on the simulated devices.
5. :class:`CellLinks` is rule 1's link part alone, for any host of running
   Subjects: this runner, and ``statectl run CELL --dashboard/--journal``
   (:mod:`statectl.channels.cli.run`).
6. Every device runs on its simulated twin (:class:`~statectl.run.devices.twin.SimTwin`,
   whose clock never runs on by itself here): a completion step is the twin's own
   report of a call it has pending, never an injected event. When the twin would
   not report the completion a step needs (the explorer offered one no device
   makes), the run stops there with a divergence naming the step. A state's
   timeout and a completion its table marks ``unasked`` are posted as they are.
"""

from __future__ import annotations

import os
import random
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from statectl.cell.explore.compose import Composed, Stimulus
from statectl.cell.explore.conditions import bind_cross_guards
from statectl.cell.explore.timeouts import timing_out
from statectl.cell.links import Send, sent_data
from statectl.cell.model import Cell, InputKind, Link
from statectl.front.tables import safeyaml
from statectl.front.tables.inputs import read_input_text
from statectl.kernel.errors import StatectlError
from statectl.kernel.semantics import Snapshot, Unhandled
from statectl.kernel.semantics.calls import Pending
from statectl.run.devices.twin import SimTwin
from statectl.run.runtime import (
    EventIgnored,
    MicrostepTaken,
    Record,
    SimClock,
    StepRecord,
    Subject,
    format_record,
)

__all__ = ["CellLinks", "CellRun", "ReplayStep", "load_replay", "run_cell"]


@dataclass(frozen=True, slots=True)
class ReplayStep:
    kind: InputKind
    device: str
    event: str
    expect: tuple[tuple[str, str], ...] = ()  # (device, state label) after the step
    #: (link label, "lost" | "overtaken"): what distribution did to link deliveries, in order
    fates: tuple[tuple[str, str], ...] = ()


def load_replay(path: str | os.PathLike[str]) -> list[ReplayStep]:
    """The stimuli of a trace file; raises :class:`StatectlError` saying what is wrong."""
    try:
        doc: Any = safeyaml.load_value(read_input_text(path))
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
        deliveries = s.get("deliveries") or []
        if not isinstance(deliveries, list):
            raise StatectlError(f"{path}: step {i}: 'deliveries' must be a list of mappings")
        fates = tuple(
            (str(d.get("via", "")), str(d["fate"]))
            for d in deliveries
            if isinstance(d, dict) and d.get("fate")
        )
        out.append(ReplayStep(kind, str(s["to"]), str(s["event"]), expect, fates))
    return out


@dataclass(frozen=True, slots=True)
class CellRun:
    steps: int
    divergences: tuple[str, ...]
    violations: tuple[str, ...]
    unhandled: tuple[str, ...]


class CellLinks:
    """A cell's links over running Subjects: which links a step fired, and whether they hold.

    Listen with :meth:`watch_step` (or :meth:`watch`) on every device; after a
    device's step, :meth:`due` gives the links that step fired whose guards hold in
    the global state now, in the cell file's order, and forgets them. Both
    questions are :mod:`statectl.cell.links`'s, asked as the explorer asks them.
    """

    def __init__(
        self, cell: Cell, subjects: Mapping[str, Subject], model: Composed | None = None
    ) -> None:
        self.cell = cell
        self.model = model if model is not None else Composed(cell)
        self.rules = self.model.rules
        self.subjects = subjects
        self.fired: list[int] = []

    def watch(self, r: Record) -> None:
        """Note the links a microstep's record fires (records a failing observer cut short)."""
        if type(r) is MicrostepTaken and r.device in self.rules.sources:
            self.fired.extend(self.rules.fired(r.device, (r,)))

    def watch_step(self, step: StepRecord) -> None:
        """:meth:`watch` as a step listener: the kernel's step is read as it is (a failed
        step's own records are read: they end where the step did)."""
        decided = step.step
        if decided is None or step.failed:
            if decided is not None or step.event is None:  # else nothing entered or taken
                for record in step.records:
                    self.watch(record)
            return
        if step.device in self.rules.sources:
            self.fired.extend(self.rules.fired(step.device, decided.microsteps))

    def state(self) -> int:
        """The explorer's packed global state for the subjects' snapshots."""
        return self.packed(None)

    def packed(self, calls: Mapping[str, Pending] | None) -> int:
        """:meth:`state`, with the calls pending on each device when they are known."""
        g = 0
        for d, space in enumerate(self.model.spaces):
            name = self.model.names[d]
            subject = self.subjects[name]
            snap = subject.snapshot
            pending = calls.get(name) if calls is not None else None
            lid = space.lookup(snap, subject.data, pending) if snap is not None else None
            if lid is None:
                raise StatectlError(f"{self.model.names[d]} is in a state the explorer never saw")
            g = self.model.replace(g, d, lid)
        return g

    def due_links(self) -> tuple[int, ...]:
        """The links (indices) fired since the last call whose guards hold now (rule 1),
        forgotten; the global state is packed only when one of them has a guard."""
        if not self.fired:
            return ()
        fired = sorted(set(self.fired))
        self.fired.clear()
        return self.rules.holding(fired, self.model.link_guard, self.state)

    def due(self) -> list[Link]:
        """:meth:`due_links` as the links themselves."""
        links = self.cell.links
        return [links[i] for i in self.due_links()]

    def sends(self, data: Any) -> list[Send]:
        """:meth:`due_links` as what each sends after a step whose event had ``data``."""
        return [self.rules.send(i, data) for i in self.due_links()]


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
        self.harmless = False  # the link being delivered says its event may land unhandled
        self.fates: list[tuple[str, str]] = []  # what the replayed trace says happened to links
        self.twins: dict[str, SimTwin] = {}
        for d in cell.devices:
            s = Subject(d.chart, clock=self.clock, name=d.name)
            twin = self.twins[d.name] = SimTwin(d.chart)
            twin.bind(s.post, self.clock)
            s.attach(twin)
            s.listen(self._trace)
            s.listen(self.links.watch)
            s.listen(self._watch)
            self.subjects[d.name] = s
        bind_cross_guards(self.subjects)
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
            and r.reason in (Unhandled.NO_TRANSITION, Unhandled.UNKNOWN_EVENT)
            and not self.harmless
        ):
            self.unhandled.append(f"{r.device} gets {r.event} ({r.reason})")

    def calls(self) -> dict[str, Pending]:
        """The calls each twin has pending that the explorer tracks (its model's rule)."""
        out: dict[str, Pending] = {}
        for d, space in enumerate(self.model.spaces):
            name = self.model.names[d]
            model = space.calls
            pending = self.twins[name].pending_calls
            if model is not None:
                pending = tuple(k for k in pending if model.tracked(model.call(*k)))
            out[name] = pending
        return out

    def state(self) -> int:
        return self.links.packed(self.calls())

    def refusal(self, device: str, event: str) -> str:
        """Why the twin of ``device`` would not report ``event`` now ("" if it would)."""
        d = self.model.position[device]
        space = self.model.spaces[d]
        subject = self.subjects[device]
        lid = space.lookup(subject.snapshot or Snapshot(frozenset()), subject.data)
        if lid is not None and timing_out(space, lid, event):
            return ""
        if space.unasked(event) or self.twins[device].would_report(event):
            return ""
        calls = self.twins[device].pending_calls
        doing = ", ".join(f"{m}() for {e}" for m, e in calls) or "none"
        return (
            f"{device}'s twin would not report {event}: no call it completes is pending "
            f"(pending calls: {doing})"
        )

    def _step(self, device: str, event: str, data: Any = None, report: bool = False) -> None:
        self.links.fired.clear()
        if not (report and self.twins[device].complete_now(event)):
            self.subjects[device].post(event, data)
        self.subjects[device].run_until_idle()

    def _fate(self, link: Link) -> str:
        """The trace's fate for this delivery ("" when it arrives in order)."""
        if self.fates and self.fates[0][0] == link.label:
            return self.fates.pop(0)[1]
        return ""

    def perform(
        self,
        device: str,
        event: str,
        fates: Sequence[tuple[str, str]] = (),
        report: bool = False,
    ) -> None:
        """Rule 1: one stimulus and its cascade of link deliveries (lost or overtaken as
        ``fates`` says: a replayed trace of a cell with lossy or delayed links); a
        completion (``report``) is the twin's own (rule 6)."""
        self.fates = list(fates)
        queue: deque[tuple[Link, Any, bool]] = deque()
        self._step(device, event, report=report)
        queue.extend((k, d, False) for k, d in self._links(event, None))
        count = 0
        while queue and count < 256:
            link, data, late = queue.popleft()
            fate = "" if late else self._fate(link)
            if fate == "overtaken":
                self.out(f"          link overtaken: {link.label}\n")
                queue.append((link, data, True))
                continue
            if fate == "lost":
                self.out(f"          link lost: {link.label}\n")
                count += 1
                notify = self.model.dropped.get(self.cell.links.index(link))
                if notify is not None:  # nodes: the link's `dropped` event to its source
                    self.out(f"          dropped: {link.source} gets {notify[1]}\n")
                    self._step(link.source, notify[1])
                    queue.extend((k, d, False) for k, d in self._links(notify[1], None))
                continue
            self.delivering = (link.target, link.event)
            self.harmless = link.ignore_if_unhandled
            self._step(link.target, link.event, data)
            self.delivering = None
            queue.extend((k, d, False) for k, d in self._links(link.event, data))
            count += 1

    def _links(self, event: str, data: Any) -> list[tuple[Link, Any]]:
        out = []
        for k in self.links.due():
            self.out(f"          link: {k.label}\n")
            out.append((k, sent_data(k, data)))
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
        report = stim.kind is InputKind.COMPLETION
        refused = r.refusal(m.names[stim.device], stim.event) if report else ""
        if refused:  # rule 6: never inject what no device would do
            divergences.append(f"step {i + 1}: {refused}")
            write(f"--- step {i + 1}: {stim.label(m.names)}: {refused}\n")
            break
        write(f"--- step {i + 1}: {stim.label(m.names)}\n")
        expected = {h for h, _, _ in m.successors(g, stim)}
        fates = plan[i].fates if plan is not None else ()
        r.perform(m.names[stim.device], stim.event, fates, report)
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
