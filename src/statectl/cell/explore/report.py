"""What verification found: findings with shortest traces, as values, text and JSON.

Rules:
1. A finding is a failure (deadlock, invariant, recovery, unhandled link event,
   link livelock, guard error) or a warning (a device state never reached); only failures
   decide the verdict.
2. The verdict is ``holds`` only when the search was complete and nothing
   failed; a bounded search that found nothing is ``incomplete``.
3. Every trace starts in the initial global state and is as short as any trace
   to its state (breadth-first order), unless the report says it is not
   (``shortest`` false: found by a reduced search, explore/search.py rule 7).
4. Where verify over-approximates (free choices over data it does not track, kept
   events released beyond what a device keeps), a trace that takes such a way is
   marked "may not be reproducible" with what it assumes, and so is a failing
   verdict all of whose counterexamples do; a deadlock or recovery verdict that
   holds on a model with such ways is marked "over-approximated" (an assumed way
   on may hide a real dead end). Other verdicts that hold are sound as they are.
5. A reduced search (symmetry) says so: the states it stored, the states the full
   search stores, and the reductions it used; its verdicts are the full search's.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

from statectl.cell.explore.compose import Delivery
from statectl.cell.explore.local import FreeGuard
from statectl.cell.model import InputKind

__all__ = ["FAILURES", "Finding", "Kind", "Report", "Trace", "TraceStep", "Unanticipated"]


class Kind(enum.Enum):
    DEADLOCK = "deadlock"
    INVARIANT = "invariant"
    RECOVERY = "recovery"
    UNHANDLED = "unhandled link event"
    LIVELOCK = "link livelock"
    GUARD_ERROR = "guard error"
    UNREACHED = "unreached state"


FAILURES = frozenset(
    {Kind.DEADLOCK, Kind.INVARIANT, Kind.RECOVERY, Kind.UNHANDLED, Kind.LIVELOCK, Kind.GUARD_ERROR}
)


@dataclass(frozen=True, slots=True)
class TraceStep:
    """One stimulus and everything it caused, with every device's state afterwards."""

    kind: InputKind
    device: str
    event: str
    deliveries: tuple[Delivery, ...]
    state: tuple[str, ...]

    @property
    def choices(self) -> tuple[tuple[str, bool], ...]:
        return tuple(c for d in self.deliveries for c in d.choices)

    @property
    def assumed(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(a for d in self.deliveries for a in d.assumed))

    def to_json(self) -> dict[str, Any]:
        return {
            "source": self.kind.value,
            "to": self.device,
            "event": self.event,
            "choices": [{"part": p, "value": v} for p, v in self.choices],
            "deliveries": [
                {
                    "from": d.sender,
                    "to": d.receiver,
                    "event": d.event,
                    "via": d.via,
                    "before": d.before,
                    "after": d.after,
                    "reaction": str(d.unhandled) if d.unhandled is not None else "handled",
                    "calls": list(d.notifies),
                    **({"fate": d.fate} if d.fate else {}),
                }
                for d in self.deliveries
            ],
        }


@dataclass(frozen=True, slots=True)
class Trace:
    devices: tuple[str, ...]
    start: tuple[str, ...]
    steps: tuple[TraceStep, ...]

    def __len__(self) -> int:
        return len(self.steps)

    @property
    def end(self) -> tuple[str, ...]:
        return self.steps[-1].state if self.steps else self.start

    @property
    def assumed(self) -> tuple[str, ...]:
        """What the trace assumes beyond the model: non-empty, it may not be reproducible."""
        return tuple(dict.fromkeys(a for s in self.steps for a in s.assumed))

    def to_json(self) -> dict[str, Any]:
        """The replay file format too: ``statectl run CELL --replay`` reads ``steps``."""
        return {
            "devices": list(self.devices),
            "start": dict(zip(self.devices, self.start, strict=True)),
            "steps": [
                {**s.to_json(), "state": dict(zip(self.devices, s.state, strict=True))}
                for s in self.steps
            ],
            "end": dict(zip(self.devices, self.end, strict=True)),
        }

    def lines(self, indent: str = "    ") -> list[str]:
        start = ", ".join(f"{n}={s}" for n, s in zip(self.devices, self.start, strict=True))
        out = [f"{indent}start: {start}"]
        for i, s in enumerate(self.steps, 1):
            for j, d in enumerate(s.deliveries):
                head = f"{i}." if j == 0 else "  "
                change = f"{d.before} -> {d.after}" if d.before != d.after else d.before
                what = f"{d.sender} -> {d.receiver}: {d.event}"
                via = "" if d.via in ("environment", "completion", "fault") else " (link)"
                via += " (overtaken)" if d.fate == "overtaken" else ""
                tail = "" if d.unhandled is None else f" [{d.unhandled}]"
                if d.via in ("fault", "peer lost"):
                    via = f" ({d.via})"
                elif d.via == "completion":
                    via = " (completion)"
                choice = "".join(f" [free: {p} = {v}]" for p, v in d.choices)
                if d.fate == "lost":
                    via, change, choice = " (link LOST on the way)", d.before, ""
                out.append(f"{indent}{head:<3} {what}{via}: {d.receiver} {change}{tail}{choice}")
        return out


@dataclass(frozen=True, slots=True)
class Finding:
    kind: Kind
    name: str
    message: str
    trace: Trace | None = None
    count: int = 1  # how many global states show it

    @property
    def failure(self) -> bool:
        return self.kind in FAILURES

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": self.kind.value,
            "name": self.name,
            "message": self.message,
            "failure": self.failure,
            "states": self.count,
            "trace": self.trace.to_json() if self.trace is not None else None,
            **({"reproducible": False, "assumes": list(self.assumed)} if self.assumed else {}),
        }

    @property
    def assumed(self) -> tuple[str, ...]:
        """What the counterexample assumes beyond the model (empty: a run the devices make)."""
        return self.trace.assumed if self.trace is not None else ()


@dataclass(frozen=True, slots=True)
class Unanticipated:
    """Global states where an outside event reaches a device whose table has no word for it."""

    device: str
    state: str
    event: str
    source: InputKind
    count: int
    trace: Trace | None

    def to_json(self) -> dict[str, Any]:
        return {
            "device": self.device,
            "state": self.state,
            "event": self.event,
            "source": self.source.value,
            "states": self.count,
            "trace": self.trace.to_json() if self.trace is not None else None,
        }


@dataclass(frozen=True, slots=True)
class Report:
    cell: str
    path: str
    devices: tuple[tuple[str, int], ...]  # instance name, local states
    states: int
    transitions: int
    depth: int
    complete: bool
    seconds: float
    peak_bytes: int
    findings: tuple[Finding, ...] = ()
    unanticipated: tuple[Unanticipated, ...] = ()
    unanticipated_states: int = 0
    free_guards: tuple[FreeGuard, ...] = ()
    properties: tuple[tuple[str, str], ...] = field(default=())  # (property, verdict)
    #: (property, what its verdict relies on beyond the model): rule 4
    relies: tuple[tuple[str, tuple[str, ...]], ...] = ()
    #: the reductions the search used, one line each (empty: the full search; rule 5)
    reductions: tuple[str, ...] = ()
    #: whether every trace is as short as any (rule 3)
    shortest: bool = True
    #: the states the full search stores (symmetry: the stored orbits counted out; with
    #: an incomplete search, at least this many), when the reduction can tell
    full_states: int | None = None

    @property
    def failures(self) -> tuple[Finding, ...]:
        return tuple(f for f in self.findings if f.failure)

    @property
    def verdict(self) -> str:
        if self.failures:
            return "fails"
        return "holds" if self.complete else "incomplete"

    @property
    def rate(self) -> float:
        return self.states / self.seconds if self.seconds > 0 else float(self.states)

    def to_json(self) -> dict[str, Any]:
        relies = {p: () for p, _ in self.properties} | dict(self.relies)
        return {
            "cell": self.cell,
            "path": self.path,
            "verdict": self.verdict,
            "complete": self.complete,
            "devices": [{"name": n, "local_states": k} for n, k in self.devices],
            "global_states": self.states,
            "transitions": self.transitions,
            "depth": self.depth,
            "seconds": round(self.seconds, 3),
            "states_per_second": round(self.rate),
            "peak_bytes": self.peak_bytes,
            "reductions": list(self.reductions),
            "shortest_traces": self.shortest,
            **({"full_states": self.full_states} if self.full_states is not None else {}),
            "properties": [
                {"property": p, "verdict": v, **({"assumes": list(r)} if (r := relies[p]) else {})}
                for p, v in self.properties
            ],
            "findings": [f.to_json() for f in self.findings],
            "unanticipated_states": self.unanticipated_states,
            "unanticipated": [u.to_json() for u in self.unanticipated],
            "free_choices": [
                {
                    "device": g.device,
                    "guard": g.guard,
                    "parts": list(g.parts),
                    "file": g.where.file,
                    "line": g.where.line,
                }
                for g in self.free_guards
            ],
        }

    def to_text(self) -> str:
        devs = ", ".join(f"{n} ({k})" for n, k in self.devices)
        out = [
            f"cell {self.cell}: {len(self.devices)} devices (local states): {devs}",
            f"explored {self.states:,} global states, {self.transitions:,} transitions, "
            f"depth {self.depth}, in {self.seconds:.2f} s ({self.rate:,.0f} states/s, "
            f"peak {self.peak_bytes / 2**20:.0f} MiB)",
        ]
        out.extend(self.reductions)
        if not self.complete:
            out.append(
                f"incomplete: the search stopped at its bound of {self.states:,} states "
                "(--max-states); properties not violated so far are not proven: give a "
                "larger --max-states, or 0 for no bound"
            )
        for g in self.free_guards:
            parts = "; ".join(g.parts)
            out.append(
                f"free choice: {g.device} guard {g.guard!r} ({g.where}) reads data the "
                f"model does not track ({parts}); both outcomes explored"
            )
        relies = dict(self.relies)
        for p, v in self.properties:
            why = relies.get(p, ())
            note = f" [{'over-approximated' if v == 'holds' else 'may not be reproducible'}: "
            out.append(f"  {v.upper():<10} {p}" + (note + "; ".join(why) + "]" if why else ""))
        for f in self.findings:
            head = "FAIL" if f.failure else "warning"
            more = f" ({f.count:,} states)" if f.count > 1 else ""
            out.append(f"{head} {f.kind.value} {f.name}: {f.message}{more}")
            if f.trace is not None:
                maybe = f"; may not be reproducible: assumes {'; '.join(f.assumed)}"
                how = "shortest trace" if self.shortest else "trace"
                short = "" if self.shortest else "; not shortest: partial-order reduction"
                out.append(f"  {how} ({len(f.trace)} steps{short}{maybe if f.assumed else ''}):")
                out.extend(f.trace.lines())
        if self.unanticipated:
            out.append(
                f"{self.unanticipated_states:,} global states receive an outside event that no "
                "device table anticipated (neither handled nor declared ignored):"
            )
            for u in self.unanticipated:
                out.append(
                    f"  {u.device} in {u.state} gets {u.event} ({u.source.value}): "
                    f"{u.count:,} states"
                )
        out.append(f"verdict: {self.verdict}")
        return "\n".join(out) + "\n"
