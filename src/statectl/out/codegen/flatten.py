"""Chart -> flat tables: every reachable snapshot, and per (snapshot, event) what happens.

Generated code must not re-implement the semantics, so the semantics decides everything
here, at generation time, and the C++ only looks the decision up. Rules:

1. A *configuration* of the generated device is a reachable
   :class:`~statectl.kernel.semantics.Snapshot` (active states, history, previous state).
   They are found breadth-first from :func:`~statectl.kernel.semantics.initial` by
   :func:`~statectl.kernel.semantics.step` for every event the chart knows, and numbered
   in that order (0 is the start).
2. A step is a :class:`FlatStep` (a row of the C++ ``kOutcomes`` table): handled or
   not (and why not, as the Python Subject says it), the target configuration, and its
   *effects* in the order the Python runtime reports them, per microstep: states
   exited, transitions taken, states entered, invoke numbers notified.
3. A guard that reads no context field (``previous == 'Moving'``, ``In('X')``) is
   decided here by the semantics itself, because ``previous`` and the active states
   are part of the configuration. A guard that reads a context field (an ``int``
   data item the user fills at run time) cannot be; such a step becomes a
   :class:`Decision` tree: evaluate runtime guard *g*, go to one subtree or the other.
   The trees are found by re-running :func:`~statectl.kernel.semantics.step` with a
   guard oracle that answers those guards from a list of choices (and leaves
   the rest to the kernel), depth first, every choice tried both ways. One guard
   evaluated twice in one step, in the same configuration, answers the same both
   times (guards are pure), so impossible paths are never generated.
4. A runtime guard is specialised to the configuration it is evaluated in:
   ``previous`` and ``In(...)`` are folded to constants by the Python evaluator,
   what remains must read only integer context fields with ``+ - *``,
   comparisons, ``and/or/not`` and ``a if c else b`` (G702 otherwise). Values are
   64-bit integers in C++, booleans 0 and 1, as in Python.
5. Whatever the generated code cannot do is a diagnostic, never dropped in silence:
   G701 executable content other than ``Notify``/``Raise``, G702 a guard that does
   not translate, G703 a guard reading ``_event``, G704 a context field that is not
   an integer, G705 a non-``safe`` datamodel, G706 too many configurations or
   guard paths, G707 a step that does not settle, G708 a ``Log`` the generated code
   skips (warning), G709 a ``Notify`` of an invoke number the chart does not declare,
   G713 an assignment the generated code cannot perform (:mod:`~statectl.out.codegen.assign`),
   G714 a guard that fails when the semantics evaluates it.

This module explores; the values it produces are in :mod:`statectl.out.codegen.flat`, the
checks before exploring in :mod:`~statectl.out.codegen.checks`, guard translation in
:mod:`~statectl.out.codegen.translate` and C++ names in
:mod:`~statectl.out.codegen.cpp_names`: import each from where it lives.
"""

from __future__ import annotations

import ast
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from statectl.kernel.codes import family
from statectl.kernel.errors import Diagnostic, DiagnosticError, Location, Severity, StatectlError
from statectl.kernel.expr import Expression, compile_expression
from statectl.kernel.model import (
    Assign,
    Chart,
    Notify,
    Transition,
)
from statectl.kernel.semantics import (
    Machine,
    Microstep,
    Run,
    Snapshot,
    Step,
    Unhandled,
    initial,
    step,
)
from statectl.kernel.semantics.offers import Offers
from statectl.out.codegen.assign import AssignTable
from statectl.out.codegen.checks import _check_actions, _context
from statectl.out.codegen.cpp_timers import check_timeouts
from statectl.out.codegen.flat import (
    Configuration,
    ContextField,
    Decision,
    Effect,
    EffectKind,
    FlatChart,
    FlatStep,
    Row,
    RuntimeGuard,
    Tree,
)
from statectl.out.codegen.translate import _Translator, _Untranslatable

__all__ = ["CODES", "MAX_CONFIGURATIONS", "MAX_PATHS", "flatten"]

#: Bound on reachable configurations; beyond it the flat tables would not be small.
MAX_CONFIGURATIONS = 4096
#: Bound on guard paths of one step (2**12: twelve independent runtime guards).
MAX_PATHS = 4096

#: Code -> one-line summary of every G7xx code (a view of statectl.kernel.codes.REGISTRY).
CODES: Mapping[str, str] = family("G7")


# -- exploring ---------------------------------------------------------------------------------


class _TooMany(Exception):
    pass


class _Oracle:
    """The kernel's guard oracle: runtime guards from ``choices`` (rule 3), the rest unforced."""

    def __init__(self, flattener: _Flattener, choices: list[bool]) -> None:
        self.flattener = flattener
        self.choices = choices
        self.decisions: list[tuple[int, bool]] = []
        self.memo: dict[int, bool] = {}

    def __call__(self, run: Run, transition: Transition) -> bool | None:
        guard = transition.guard
        assert guard is not None
        gid = self.flattener.runtime_guard(guard, run)
        if gid is None:
            return None  # decided by the kernel, as the Python runtime decides it
        if gid in self.memo:
            return self.memo[gid]
        pos = len(self.decisions)
        value = self.choices[pos] if pos < len(self.choices) else False
        self.decisions.append((gid, value))
        self.memo[gid] = value
        return value


class _Flattener:
    def __init__(self, chart: Chart, fields: list[ContextField], values: dict[str, Any]) -> None:
        self.chart = chart
        self.m = Machine(chart)
        self.fields = {f.name: f.ident for f in fields}
        self.values = values  # every data item, integer or not
        self.order = {s.name: i for i, s in enumerate(chart.states)}
        self.transition_index = {id(t): i for i, t in enumerate(chart.transitions)}
        self.exprs: dict[str, Expression] = {}
        self.trees: dict[str, ast.expr] = {}
        self.guards: dict[tuple[str, str | None, frozenset[str]], RuntimeGuard] = {}
        self.diags: list[Diagnostic] = []
        self.reported: set[tuple[str, str]] = set()
        self.snapshots: dict[Snapshot, int] = {}
        self.queue: deque[Snapshot] = deque()
        self.assigns = AssignTable(self.fields, self.diags)
        self.offers = Offers(self.m, chart.event_names)  # rows step only offered events

    # guards

    def _expr(self, guard: str) -> Expression:
        expr = self.exprs.get(guard)
        if expr is None:
            compiled, problems = compile_expression(guard, Location())
            if compiled is None:  # Machine() refuses such charts first; kept for safety
                raise DiagnosticError(problems)
            expr = self.exprs[guard] = compiled
            self.trees[guard] = ast.parse(guard.strip(), mode="eval").body
        return expr

    def _env(self, run: Run) -> dict[str, Any]:
        return {"previous": run.previous, "In": run.active.__contains__}

    def runtime_guard(self, guard: str, run: Run) -> int | None:
        """The runtime guard id of ``guard`` in this configuration, ``None`` if static."""
        expr = self._expr(guard)
        if "_event" in expr.names:
            self._report(
                "G703",
                guard,
                f"guard {guard!r} reads _event",
                "event data does not exist in generated code; use a context field",
            )
            return None
        if not (expr.names & self.values.keys()):
            return None
        uses_in = any(
            isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "In"
            for n in ast.walk(self.trees[guard])
        )
        previous = run.previous if "previous" in expr.names else None
        active = frozenset(run.active) if uses_in else frozenset()
        key = (guard, previous, active)
        found = self.guards.get(key)
        if found is None:
            found = RuntimeGuard(len(self.guards), guard, previous, self._translate(guard, run))
            self.guards[key] = found
        return found.index

    def _translate(self, guard: str, run: Run) -> str:
        expr = self.exprs[guard]
        strange = sorted(n for n in expr.names & self.values.keys() if n not in self.fields)
        if strange:
            self._report(
                "G704",
                guard,
                f"guard {guard!r} reads {', '.join(strange)}, which is not an integer "
                "(C++ context fields are 64-bit integers)",
                "give the data item an integer or boolean value",
            )
            return "false"
        try:
            return f"({_Translator(self.fields, self._env(run)).cpp(self.trees[guard])}) != 0"
        except _Untranslatable as exc:
            self._report(
                "G702",
                guard,
                f"guard {guard!r} does not translate to C++: {exc}",
                "over context fields use integers, + - *, comparisons, and/or/not, a if c else b",
            )
            return "false"

    def _report(self, code: str, guard: str, message: str, hint: str) -> None:
        if (code, guard) in self.reported:
            return
        self.reported.add((code, guard))
        where = next((t.origin for t in self.chart.transitions if t.guard == guard), Location())
        self.diags.append(Diagnostic(code, Severity.ERROR, where, message, hint))

    # snapshots and steps

    def index(self, snap: Snapshot) -> int:
        found = self.snapshots.get(snap)
        if found is None:
            if len(self.snapshots) >= MAX_CONFIGURATIONS:
                raise _TooMany(f"more than {MAX_CONFIGURATIONS} reachable configurations")
            found = self.snapshots[snap] = len(self.snapshots)
            self.queue.append(snap)
        return found

    def effects(self, microsteps: Iterable[Microstep]) -> tuple[Effect, ...]:
        out: list[Effect] = []
        for micro in microsteps:
            assigns = [a for a in micro.actions if isinstance(a, Assign)]
            if assigns:  # first: the data changes before the step is performed (codegen.assign)
                out.append(Effect(EffectKind.ASSIGN, self.assigns.group(assigns)))
            out += [Effect(EffectKind.EXIT, self.order[s]) for s in micro.exited]
            out += [
                Effect(EffectKind.TAKE, self.transition_index[id(t)]) for t in micro.transitions
            ]
            out += [Effect(EffectKind.ENTER, self.order[s]) for s in micro.entered]
            out += [
                Effect(EffectKind.INVOKE, a.invoke) for a in micro.actions if isinstance(a, Notify)
            ]
        return tuple(out)

    def outcome_of(self, source: Snapshot | None, result: Step) -> FlatStep:
        failure = result.failure
        if failure is not None:  # a guard that raises: the runtime refuses the event
            self._report(
                "G714",
                failure.guard,
                f"guard {failure.guard!r} fails when it is evaluated ({failure.reason})",
                "the runtime refuses such an event (guard error); make the guard total",
            )
            assert source is not None
            return FlatStep(False, self.snapshots[source], (), Unhandled.GUARD_FALSE)
        if source is not None and not result.handled:
            return FlatStep(False, self.snapshots[source], (), result.unhandled)
        target = self.index(result.target)
        return FlatStep(True, target, self.effects(result.microsteps), final=result.final)

    def oracle_step(
        self, source: Snapshot | None, event: str | None, choices: list[bool]
    ) -> tuple[list[tuple[int, bool]], FlatStep]:
        """One step of the kernel with runtime guards answered from ``choices``."""
        oracle = _Oracle(self, choices)
        if source is None:
            result = initial(self.m, self.values, oracle=oracle)
        else:
            assert event is not None
            result = step(self.m, source, event, self.values, oracle=oracle)
        return oracle.decisions, self.outcome_of(source, result)

    def tree(self, source: Snapshot | None, event: str | None) -> Tree:
        """Every guard path of one step, depth first (rule 3)."""
        leaves: list[tuple[list[tuple[int, bool]], FlatStep]] = []

        def visit(prefix: list[bool]) -> None:
            if len(leaves) >= MAX_PATHS:
                raise _TooMany(f"more than {MAX_PATHS} guard paths in one step")
            decisions, outcome = self.oracle_step(source, event, prefix)
            leaves.append((decisions, outcome))
            for i in range(len(prefix), len(decisions)):
                visit([d for _, d in decisions[:i]] + [True])

        visit([])
        return _build_tree(leaves, 0)

    def row(self, snap: Snapshot, events: tuple[str, ...]) -> Row:
        """One configuration's row: the kernel's step for each event an active state
        could take (rule 1), in event order so configurations are numbered as before;
        every other event is unhandled and needs no step (:class:`~.flat.Row`)."""
        offered = sorted(self.offers.offered(snap.active))
        explicit = {e: self.decide(snap, events[e]) for e in offered}
        ignored = self.offers.ignored(snap.active) - explicit.keys()
        return Row(self.snapshots[snap], len(events), explicit, ignored)

    def decide(self, source: Snapshot | None, event: str | None) -> Tree:
        """The semantics' own step where no guard was consulted, the oracle otherwise."""
        result = (
            initial(self.m, self.values)
            if source is None
            else step(self.m, source, event or "", self.values)
        )
        if not result.guarded:
            return self.outcome_of(source, result)
        return self.tree(source, event)


def _build_tree(leaves: list[tuple[list[tuple[int, bool]], FlatStep]], depth: int) -> Tree:
    if len(leaves) == 1 and len(leaves[0][0]) == depth:
        return leaves[0][1]
    gid = leaves[0][0][depth][0]
    yes = [leaf for leaf in leaves if leaf[0][depth][1]]
    no = [leaf for leaf in leaves if not leaf[0][depth][1]]
    return Decision(gid, _build_tree(yes, depth + 1), _build_tree(no, depth + 1))


def flatten(
    chart: Chart, progress: Callable[[int, int], None] | None = None
) -> tuple[FlatChart | None, list[Diagnostic]]:
    """Explore ``chart`` into flat tables, or say why it cannot be (G7xx).

    ``progress`` is called after each configuration's row with the rows done and the
    configurations found so far (the CLI shows it on a long run)."""
    where = chart.origin
    diags: list[Diagnostic] = []
    if chart.datamodel != "safe":
        diags.append(
            Diagnostic(
                "G705",
                Severity.ERROR,
                where,
                f"datamodel {chart.datamodel!r}: its scripts and conditions cannot run in C++",
                "use the safe expression language (datamodel 'safe') for a C++ target",
            )
        )
        return None, diags
    _check_actions(chart, where, diags)
    check_timeouts(chart, where, diags)  # G710-G712 (cpp_timers)
    values, fields = _context(chart, diags)
    if any(d.severity is Severity.ERROR for d in diags):
        return None, diags
    try:
        f = _Flattener(chart, fields, values)
    except DiagnosticError as exc:
        return None, [*diags, *exc.diagnostics]
    events = chart.event_names
    try:
        start = f.decide(None, None)
        rows: list[Row] = []
        while f.queue:
            rows.append(f.row(f.queue.popleft(), events))
            if progress is not None:
                progress(len(rows), len(f.snapshots))
    except _TooMany as exc:
        diags.append(
            Diagnostic(
                "G706",
                Severity.ERROR,
                where,
                f"chart {chart.name!r}: {exc}",
                "split the device into several charts or drop history/parallel regions",
            )
        )
        return None, diags
    except StatectlError as exc:
        diags.append(
            Diagnostic(
                "G707",
                Severity.ERROR,
                where,
                f"chart {chart.name!r} does not settle: {exc}",
                "look for eventless or raised transitions that loop",
            )
        )
        return None, diags
    diags += f.diags
    configs = tuple(
        Configuration(i, snap, tuple(sorted(snap.active, key=f.order.__getitem__)))
        for snap, i in f.snapshots.items()
    )
    flat = FlatChart(
        chart,
        tuple(s.name for s in chart.states),
        events,
        chart.transitions,
        configs,
        start,
        tuple(rows),
        tuple(sorted(f.guards.values(), key=lambda g: g.index)),
        tuple(fields),
        tuple(f.assigns.groups),
    )
    return flat, diags
