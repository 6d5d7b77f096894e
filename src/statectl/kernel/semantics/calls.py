"""Which completion follows which API call: the one model of a device's answers.

The simulated twin (:mod:`statectl.run.devices.twin`) runs it, the explorer
(:mod:`statectl.cell.explore.local`) assumes it and testgen expects it, so what
``verify`` proves and what ``run`` on the twins does cannot drift apart. Pure:
it decides, it performs nothing (no clock, no timer).

Rules:
1. A notification of method ``M`` for event ``E`` (a command or fault step drove
   the device) is a *call* ``(M, E)``. It enters the kernel's entry set of the
   transitions on ``E`` that notify ``M`` (every transition on ``E`` when none
   does; a targetless one stays in its source) and leaves the descendants of
   their sources.
2. The call is *completed* by the ``completion``-kind events of ``M``'s observer
   (the Event Definition rows with API ``M``) that have a transition leaving an
   entered state or one of its superstates. None: the device reports nothing.
3. A later call *supersedes* a pending one whose entered states it leaves, or
   whose entered states the device cannot be in beside the new call's sources
   (they were left by an event the device did not see): a real device stops
   what it was doing.
4. A completion the device reports settles one pending call it completes; a
   completion-kind event the device did not report (a link, the environment)
   settles nothing. An event row marked ``unasked`` may be reported with no call
   pending (the device raises it by itself).
Which faults a monitored state raises is :func:`statectl.front.observers.extract`'s
answer (its monitors), which the runtime's monitors and the explorer both read.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from statectl.kernel.model import Api, Chart, EventKind, Notify, StateKind, Transition
from statectl.kernel.semantics.algorithm import entry_set
from statectl.kernel.semantics.machine import Machine, structural

__all__ = ["Call", "CallKey", "DeviceCalls", "Pending"]

#: A call as the explorer keeps it: (method, the event whose step notified it).
CallKey = tuple[str, str]
#: The calls a device has not completed: sorted, without repeats (hashable, compact).
Pending = tuple[CallKey, ...]


@dataclass(frozen=True, slots=True)
class Call:
    """What a notification of ``method`` for ``event`` means for the device (rules 1-2)."""

    method: str
    event: str
    entered: frozenset[str]
    left: frozenset[str]
    sources: frozenset[str]
    completions: tuple[str, ...]  # table order; empty: the device reports nothing
    reason: str  # why nothing is reported, when ``completions`` is empty

    @property
    def key(self) -> CallKey:
        return (self.method, self.event)


def _entered(m: Machine, t: Transition) -> set[str]:
    """What taking ``t`` enters, by the kernel; a targetless transition stays in its source."""
    if not t.targets:
        return {t.source} if t.source in m.order else set()
    if not all(x in m.order for x in t.targets):
        return set()
    return set(entry_set(m, [t]))


def _descendants(chart: Chart, name: str) -> set[str]:
    found = {name}
    for child in chart.children(name):
        found |= _descendants(chart, child.name)
    return found


class DeviceCalls:
    """Rules 1-5 for one chart, derived once and cached per question."""

    def __init__(self, chart: Chart, machine: Machine | None = None) -> None:
        self.chart = chart
        self.machine = machine if machine is not None else structural(chart)
        self._calls: dict[CallKey, Call] = {}
        # indexed once, so a call's derivation reads only the transitions on its events
        # (a scan of every transition per call made check quadratic in the rows)
        self._on: dict[str, list[Transition]] = {}
        for t in chart.transitions:
            for e in t.events:
                self._on.setdefault(e, []).append(t)
        self._apis: dict[str, Api] = {}
        for a in chart.apis:
            self._apis.setdefault(a.method, a)
        self._candidates: dict[str, tuple[tuple[str, ...], dict[str, int]]] = {}
        self.unasked: frozenset[str] = frozenset(
            e.name for e in chart.events if e.kind is EventKind.COMPLETION and e.unasked
        )

    def around(self, states: Iterable[str]) -> set[str]:
        """``states`` and their superstates: whose transitions leave them."""
        out = set(states)
        for s in list(out):
            out.update(self.machine.ancestors.get(s, ()))
        return out

    def call(self, method: str, event: str) -> Call:
        """Rules 1-2 for a notification of ``method`` for ``event``."""
        key = (method, event)
        found = self._calls.get(key)
        if found is None:
            found = self._calls[key] = self._derive(method, event)
        return found

    def _completions_of(self, method: str) -> tuple[tuple[str, ...], dict[str, int]]:
        """The completion events of ``method``'s observer in table order, and their ranks."""
        found = self._candidates.get(method)
        if found is None:
            api = self._apis.get(method)
            events = api.events if api is not None else ()
            chart = self.chart
            names = tuple(
                e
                for e in events
                if (d := chart.event(e)) is not None and d.kind is EventKind.COMPLETION
            )
            found = self._candidates[method] = (names, {e: i for i, e in enumerate(names)})
        return found

    def _derive(self, method: str, event: str) -> Call:
        chart = self.chart
        on_event = tuple(self._on.get(event, ()))
        notifying = tuple(
            t
            for t in on_event
            if any(isinstance(a, Notify) and a.method == method for a in t.actions)
        )
        taken = notifying or on_event
        entered: set[str] = set()
        left: set[str] = set()
        for t in taken:
            left |= _descendants(chart, t.source) if chart.has_state(t.source) else {t.source}
            entered |= _entered(self.machine, t)
        leaves = self.around(entered)
        candidates, rank = self._completions_of(method)
        found = {
            e for s in leaves for t in chart.transitions_from(s) for e in t.events if e in rank
        }
        completions = tuple(sorted(found, key=rank.__getitem__))  # in table order
        where = ", ".join(sorted(entered)) or "no known state"
        reason = ""
        if not candidates:
            reason = f"{method}() has no completion event in {chart.name}'s Event Definition table"
        elif not completions:
            reason = (
                f"{event} entered {where}, and no completion of {method}() "
                f"({', '.join(candidates)}) leaves it"
            )
        sources = frozenset(t.source for t in taken)
        return Call(
            method, event, frozenset(entered), frozenset(left), sources, completions, reason
        )

    def completion_entered(self, entered: frozenset[str], completion: str) -> set[str]:
        """What ``completion`` of a call that entered ``entered`` enters when reported."""
        leaves = self.around(entered)
        out: set[str] = set()
        for t in self._on.get(completion, ()):
            if t.source in leaves and t.targets:
                out |= _entered(self.machine, t)
        return out

    # -- rule 3 ---------------------------------------------------------------------------

    def together(self, a: str, b: str) -> bool:
        """Whether the device can be in states ``a`` and ``b`` at once."""
        chart = self.chart
        if not (chart.has_state(a) and chart.has_state(b)):
            return True  # not a state of the chart: assume nothing
        above_a = [a, *self.machine.ancestors.get(a, ())]
        above_b = [b, *self.machine.ancestors.get(b, ())]
        if a in above_b or b in above_a:
            return True
        common = next((x for x in above_a if x in above_b), None)
        return common is not None and chart.state(common).kind is StateKind.PARALLEL

    def left_by(self, entered: frozenset[str], new: Call) -> bool:
        """Rule 3, first half: ``new`` leaves a state a pending call entered."""
        return bool(entered & new.left)

    def unseen(self, entered: frozenset[str], new: Call) -> bool:
        """Rule 3, second half: the device cannot be in ``entered`` beside ``new``'s sources."""
        return bool(new.sources) and not any(
            self.together(s, e) for s in new.sources for e in entered
        )

    def supersedes(self, pending: CallKey, new: Call) -> bool:
        """Rule 3: whether ``new`` cancels the pending call ``pending``."""
        entered = self.call(*pending).entered
        return self.left_by(entered, new) or self.unseen(entered, new)

    # -- rules 1-4 on a set of pending calls ------------------------------------------------

    def tracked(self, call: Call) -> bool:
        """Whether a pending ``call`` matters: some completion of it must be asked for."""
        return any(c not in self.unasked for c in call.completions)

    def after_calls(self, pending: Pending, calls: Sequence[CallKey]) -> Pending:
        """``pending`` after the device was called for ``calls`` in order (rules 1-3)."""
        out = list(pending)
        for method, event in calls:
            new = self.call(method, event)
            out = [p for p in out if not self.supersedes(p, new)]
            if self.tracked(new) and new.key not in out:
                out.append(new.key)
        return tuple(sorted(out))

    def settled_by(self, pending: Pending, completion: str) -> tuple[Pending, ...]:
        """Rule 4: each way ``completion``, reported by the device, settles ``pending``
        (empty: no pending call is completed by it)."""
        return tuple(
            tuple(p for p in pending if p != key)
            for key in pending
            if completion in self.call(*key).completions
        )

    def completes(self, pending: Pending, completion: str) -> bool:
        """Whether the device may report ``completion`` now (rule 4)."""
        return completion in self.unasked or any(
            completion in self.call(*key).completions for key in pending
        )
