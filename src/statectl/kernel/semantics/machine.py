"""A chart compiled for stepping: the static tables computed once at load.

Ancestors, descendants, candidate transitions per (state, event), static
transition domains and compiled guards; plus the memo of unguarded steps and
the interned snapshots with their plan tables that make a repeated dispatch a
dictionary lookup.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable

from statectl.kernel.errors import DiagnosticError
from statectl.kernel.expr import CALLABLE_NAMES, Expression, compile_expression
from statectl.kernel.model import Chart, Notify, StateKind, Transition
from statectl.kernel.semantics.records import MEMO_LIMIT, Consult, Plan, PlanTable, Snapshot, Step

__all__ = ["Machine", "compiled", "name_match", "structural"]


def name_match(descriptors: Iterable[str], event: str) -> bool:
    """SCXML event matching: ``error`` matches ``error`` and ``error.execution``; ``*`` all."""
    for d in descriptors:
        if d == "*" or d == event:
            return True
        d = d.removesuffix(".*")
        if event.startswith(d) and event[len(d) : len(d) + 1] == ".":
            return True
    return False


class Machine:
    """A chart compiled for stepping: static tables computed once at load."""

    def __init__(self, chart: Chart, *, guards: bool = True) -> None:
        self.chart = chart
        self.order: dict[str, int] = {s.name: i for i, s in enumerate(chart.states)}
        self.kind: dict[str, StateKind] = {s.name: s.kind for s in chart.states}
        self.parent: dict[str, str | None] = {s.name: s.parent for s in chart.states}
        self.initial_of: dict[str, tuple[str, ...]] = {}
        self.history_default: dict[str, tuple[str, ...]] = {}
        self._index_hierarchy(chart)
        for s in chart.states:
            if s.kind is StateKind.COMPOUND:
                kids = [c for c in self.children.get(s.name, ()) if not self.kind[c].is_history]
                self.initial_of[s.name] = s.initial or (kids[:1] and (kids[0],)) or ()
        for s in chart.states:
            if s.kind.is_history:
                self.history_default[s.name] = s.history_default or self._parent_default(s.name)
        self.top_initial: tuple[str, ...] = chart.initial or self.children.get(None, ())[:1]
        by_source: dict[str, list[Transition]] = {name: [] for name in self.order}
        for t in chart.transitions:  # one pass, document order kept within each source
            by_source[t.source].append(t)
        self.transitions_of: dict[str, tuple[Transition, ...]] = {
            name: tuple(ts) for name, ts in by_source.items()
        }
        self.histories_of: dict[str, tuple[str, ...]] = {
            name: tuple(c for c in self.children.get(name, ()) if self.kind[c].is_history)
            for name in self.order
        }
        self._compile_guards(chart, guards)
        self.ignored = chart.ignored | chart.deferred  # a deferred event is kept, not taken
        self._static_domains: dict[int, str | None] | None = None  # see static_domains()
        self._candidates: dict[tuple[str, str | None], tuple[Transition, ...]] = {}
        self._memo: dict[tuple[Snapshot, str], Step] = {}
        # data-guarded steps: per (snapshot, event), the guard outcomes seen and their step
        self._guarded: dict[tuple[Snapshot, str], list[tuple[tuple[Consult, ...], Step]]] = {}
        self._initial: Step | None = None
        self.event_names: frozenset[str] = frozenset(chart.event_names)
        # interned snapshots with their plan tables, by value and by identity
        self._tables: dict[Snapshot, tuple[Snapshot, PlanTable]] = {}
        self._by_id: dict[int, tuple[Snapshot, PlanTable]] = {}
        self._slots: dict[int, int] = {}  # id(Notify) -> slot; the chart keeps them alive
        # one shared machine serves subjects on several threads: slot numbers must be unique
        self._installing = threading.Lock()
        #: the memoised initial step's (target, plan table) when :meth:`quiet` found it so
        self.quiet_start: tuple[Snapshot, PlanTable] | None = None

    def _index_hierarchy(self, chart: Chart) -> None:
        """Children, ancestors and descendants of every state, so no step walks the tree."""
        children: dict[str | None, list[str]] = {}
        for s in chart.states:
            children.setdefault(s.parent, []).append(s.name)
        self.children: dict[str | None, tuple[str, ...]] = {
            k: tuple(v) for k, v in children.items()
        }
        self.ancestors: dict[str, tuple[str, ...]] = {}
        for s in chart.states:
            chain: list[str] = []
            p = s.parent
            while p is not None:
                chain.append(p)
                p = self.parent[p]
            self.ancestors[s.name] = tuple(chain)
        # linear in the sum of depths: each state is added to its ancestors' sets
        below: dict[str, list[str]] = {s.name: [] for s in chart.states}
        for s in chart.states:
            for a in self.ancestors[s.name]:
                below[a].append(s.name)
        self.descendants: dict[str | None, frozenset[str]] = {None: frozenset(self.order)}
        for name, names in below.items():
            self.descendants[name] = frozenset(names)

    def _compile_guards(self, chart: Chart, guards: bool) -> None:
        """Compile each safe guard once, failing at load (not mid-run) on a bad one."""
        self.guards: dict[str, Expression] = {}
        problems = []
        # other datamodels' conditions are the executor's to evaluate
        for t in chart.transitions if chart.datamodel == "safe" and guards else ():
            if t.guard and t.guard not in self.guards:
                expr, diags = compile_expression(t.guard, t.origin)
                problems.extend(diags)
                if expr is not None:
                    self.guards[t.guard] = expr
        if problems:
            raise DiagnosticError(problems)
        # guards whose value follows from the snapshot alone: a step they decide is
        # memoisable (unless a data item shadows a function name the guard may call)
        shadowed = any(d.name in CALLABLE_NAMES for d in chart.data)
        self.snapshot_guards: frozenset[str] = frozenset(
            g for g, e in self.guards.items() if e.names <= {"previous"} and not shadowed
        )

    def _parent_default(self, history: str) -> tuple[str, ...]:
        """A history state without a default transition (W3C requires one) enters what its
        parent enters by default: a compound's initial state, a parallel's regions. Without
        this, entering it before anything was recorded would enter no child at all.
        """
        parent = self.parent[history]
        if parent is None:
            return ()
        if self.kind[parent] is StateKind.COMPOUND:
            return self.initial_of.get(parent, ())
        return tuple(c for c in self.children.get(parent, ()) if not self.kind[c].is_history)

    def quiet(self, result: Step) -> tuple[Snapshot, PlanTable] | None:
        """``result``'s interned target and plan table if performing it unheard only moves there.

        That is when it issues no notification and reaches no final state, so a host
        with nobody listening commits the target and is done (a new instance's start).
        The memoised initial step's answer is kept in :attr:`quiet_start`.
        """
        if result.final or any(isinstance(a, Notify) for a in result.actions):
            return None
        entry = self._entry(result.target)
        if result is self._initial:
            self.quiet_start = entry
        return entry

    # -- plans ---------------------------------------------------------------------------

    def _entry(self, snapshot: Snapshot) -> tuple[Snapshot, PlanTable]:
        hit = self._by_id.get(id(snapshot))
        if hit is not None and hit[0] is snapshot:
            return hit
        entry = self._tables.get(snapshot)
        if entry is None:
            if len(self._tables) >= MEMO_LIMIT:
                return snapshot, {}  # not interned: its plans are not kept
            entry = self._tables.setdefault(snapshot, (snapshot, {}))
            self._by_id.setdefault(id(entry[0]), entry)
        return entry

    def intern(self, snapshot: Snapshot) -> Snapshot:
        """The one kept instance equal to ``snapshot``, so hosts compare and look up by identity."""
        return self._entry(snapshot)[0]

    def plans(self, snapshot: Snapshot) -> dict[str, Plan]:
        """The plan table of ``snapshot``: event -> :class:`Plan`, for the steps memoised so far.

        Read it, never write it; :func:`step` fills it.
        """
        return self._entry(snapshot)[1]

    def _install(self, snapshot: Snapshot, event: str, result: Step) -> None:
        table = self._entry(snapshot)[1]
        target, next_table = self._entry(result.target)
        slots = self._slots
        with self._installing:
            notifies = tuple(
                (slots.setdefault(id(a), len(slots)), a)
                for a in result.actions
                if isinstance(a, Notify)
            )
        table[event] = Plan(
            result,
            target,
            next_table,
            notifies,
            result.handled,
            result.final,
            result.entered,
            result.exited,
            result.unhandled,
        )

    # -- structure -------------------------------------------------------------------------

    def is_descendant(self, state: str, ancestor: str | None) -> bool:
        return ancestor is None or ancestor in self.ancestors[state]

    def is_atomic(self, state: str) -> bool:
        return self.kind[state] in (StateKind.ATOMIC, StateKind.FINAL)

    def candidates(self, atomic: str, event: str | None) -> tuple[Transition, ...]:
        """Transitions an atomic state offers for ``event``: its own first, then ancestors'."""
        key = (atomic, event)
        found = self._candidates.get(key)
        if found is None:
            out: list[Transition] = []
            for s in (atomic, *self.ancestors[atomic]):
                for t in self.transitions_of[s]:
                    eventless = event is None and not t.events
                    if eventless or (event is not None and name_match(t.events, event)):
                        out.append(t)
            found = self._candidates[key] = tuple(out)
        return found

    def _find_lcca(self, states: list[str]) -> str | None:
        head, tail = states[0], states[1:]
        for anc in self.ancestors[head]:
            if self.kind[anc] is StateKind.COMPOUND and all(
                self.is_descendant(s, anc) for s in tail
            ):
                return anc
        return None

    def static_domains(self) -> dict[int, str | None]:
        """The domain of each transition whose targets fix it (none is a history), by id.

        Worked out for every transition on the first step that asks: a host that only
        asks structural questions (``statectl check``: a fifth of its rules' time on a
        100,000-row chart) never pays for it. The table is published whole, so a thread
        that races another to make it reads a complete one either way.
        """
        domains = self._static_domains
        if domains is None:
            domains = {}
            for t in self.chart.transitions:
                if t.targets and not any(self.kind[x].is_history for x in t.targets):
                    domains[id(t)] = self._domain(t, t.targets)
            self._static_domains = domains
        return domains

    def _domain(self, t: Transition, targets: Iterable[str]) -> str | None:
        tstates = list(targets)
        if (
            t.internal
            and self.kind[t.source] is StateKind.COMPOUND
            and all(self.is_descendant(s, t.source) for s in tstates)
        ):
            return t.source
        return self._find_lcca([t.source, *tstates])


_COMPILED: dict[int, tuple[Chart, Machine]] = {}
_COMPILED_LIMIT = 256
_compiling = threading.Lock()


def compiled(chart: Chart) -> Machine:
    """The :class:`Machine` of ``chart`` shared by every host that only steps it.

    Compiling is the expensive part of a new instance; a chart is a value, so one
    compilation (and one memo) serves every instance of it in the process. A host
    that changes its machine (an explorer swapping guards) builds its own.
    """
    hit = _COMPILED.get(id(chart))
    if hit is not None and hit[0] is chart:
        return hit[1]
    with _compiling:
        hit = _COMPILED.get(id(chart))
        if hit is not None and hit[0] is chart:
            return hit[1]
        m = Machine(chart)
        if len(_COMPILED) >= _COMPILED_LIMIT:
            del _COMPILED[next(iter(_COMPILED))]
        _COMPILED[id(chart)] = (chart, m)
        return m


def release(chart: Chart) -> None:
    """Drop ``chart``'s shared machine: a host that asked only structural questions of a
    chart it then discards (``statectl check``) frees both at once, rather than keeping a
    100,000-row chart for the life of the process (and the collector walking it)."""
    with _compiling:
        hit = _COMPILED.get(id(chart))
        if hit is not None and hit[0] is chart:
            del _COMPILED[id(chart)]


def structural(chart: Chart) -> Machine:
    """A Machine to ask structural questions (entry sets, ancestors) of any built chart.

    The shared :func:`compiled` machine, or, when a guard does not compile (a chart
    that is being checked may still have such errors), one without guards: what a
    transition enters does not depend on them.
    """
    try:
        return compiled(chart)
    except DiagnosticError:
        return Machine(chart, guards=False)
