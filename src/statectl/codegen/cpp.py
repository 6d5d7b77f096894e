"""Flat tables -> plain C++17: one header per device, the shared runtime, a CMake target.

Rules:
1. Everything the semantics decided is data: ``constexpr`` tables with a comment
   per row (event-major cells -> the case of one switch; outcomes -> effects; guard
   decisions). ``dispatch`` is one bound check, one ``kCells`` load and one indexed
   jump; each case is an outcome's effects as straight-line code or a guard-decision
   tree unrolled at compile time. Nothing re-implements the semantics.
2. The paper's observer pattern: enums for states, events and invoke numbers; an
   ``Observer`` with ``update(Invoke)``; the device is a ``Subject`` that notifies
   only the observer attached for an invoke number; a generated ``<Device>Api``
   observer maps each invoke number to one pure virtual API method.
3. No heap, no exceptions, no RTTI; a fixed-capacity lock-free SPSC queue behind
   ``post()``; numbered contract checks (1xx device, 2xx subject, see the runtime),
   always on: the device's state word carries "not started" and "busy" flags that put
   the cell index past the table, so the dispatch checks are the lookup's bound check;
   trace calls exist only when ``STATECTL_TRACE`` is 1.
4. Output is deterministic (no dates, no absolute paths), so regenerating gives
   identical files and a diff shows what a model change did.
5. Any error diagnostic from :func:`~statectl.codegen.flatten.flatten` means no file
   is written.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from importlib.resources import files
from pathlib import Path
from typing import TextIO

from statectl.codegen.flatten import (
    Decision,
    Effect,
    EffectKind,
    FlatChart,
    Outcome,
    Tree,
    Unhandled,
    flatten,
    identifiers,
)
from statectl.errors import Diagnostic, DiagnosticError, Severity, has_errors
from statectl.model import Chart

__all__ = ["RUNTIME_HEADERS", "generate", "render", "run_codegen"]

#: The shared runtime headers, copied to ``<out>/statectl/``.
RUNTIME_HEADERS = ("contract.hpp", "observer.hpp", "runtime.hpp", "spsc_queue.hpp", "trace.hpp")

_REASON_BITS = {
    None: 0,
    Unhandled.DECLARED_IGNORED: 1,
    Unhandled.GUARD_FALSE: 2,
    Unhandled.NO_TRANSITION: 3,
}
_OPS = {
    EffectKind.EXIT: "kExit",
    EffectKind.TAKE: "kTake",
    EffectKind.ENTER: "kEnter",
    EffectKind.INVOKE: "kInvoke",
}


def _c(text: str) -> str:
    """A C++ string literal."""
    out = text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
    return f'"{out}"'


def _comment(text: str) -> str:
    return text.replace("*/", "* /").replace("\n", " ")


class _Tables:
    """Deduplicated outcomes, effect runs and decisions, in first-use order."""

    def __init__(self, flat: FlatChart) -> None:
        self.flat = flat
        self.effects: list[Effect] = []
        self.runs: dict[tuple[Effect, ...], int] = {}
        # target, first, count, flags, comment
        self.outcomes: list[tuple[int, int, int, int, str]] = []
        self.outcome_ids: dict[tuple[int, int, int, int], int] = {}
        self.decisions: list[tuple[int, int, int]] = []
        self.decision_ids: dict[tuple[int, int, int], int] = {}

    def run(self, effects: tuple[Effect, ...]) -> int:
        if not effects:
            return 0
        found = self.runs.get(effects)
        if found is None:
            found = self.runs[effects] = len(self.effects)
            self.effects.extend(effects)
        return found

    def code(self, tree: Tree) -> int:
        """>= 0: an outcome index; < 0: ``~decision index``."""
        if isinstance(tree, Decision):
            key = (tree.guard, self.code(tree.if_true), self.code(tree.if_false))
            found = self.decision_ids.get(key)
            if found is None:
                found = self.decision_ids[key] = len(self.decisions)
                self.decisions.append(key)
            return ~found
        return self._outcome(tree)

    def _outcome(self, o: Outcome) -> int:
        flags = (1 if o.handled else 0) | (2 if o.final else 0) | (_REASON_BITS[o.unhandled] << 2)
        target = o.target if o.handled else 0
        key = (target, self.run(o.effects), len(o.effects), flags)
        found = self.outcome_ids.get(key)
        if found is None:
            found = self.outcome_ids[key] = len(self.outcomes)
            self.outcomes.append((*key, self._describe(o)))
        return found

    def _describe(self, o: Outcome) -> str:
        flat = self.flat
        if not o.handled:
            return f"unhandled: {o.unhandled}"
        parts = [f"-> {o.target} {flat.configurations[o.target].label}"]
        parts += [self.effect_text(e) for e in o.effects]
        if o.final:
            parts.append("final")
        return "; ".join(parts)

    def effect_text(self, e: Effect) -> str:
        flat = self.flat
        if e.kind is EffectKind.TAKE:
            t = flat.transitions[e.index]
            return f"{t.source} + {t.label} = {', '.join(t.targets) or '(targetless)'}"
        if e.kind is EffectKind.INVOKE:
            inv = next(i for i in flat.chart.invokes if i.number == e.index)
            return f"invoke #{inv.number} {inv.name}"
        return f"{e.kind.value} {flat.states[e.index]}"


def _width(values: Sequence[int]) -> int:
    return max((len(str(v)) for v in values), default=1)


def render(flat: FlatChart) -> dict[str, str]:
    """The generated files (relative path -> text) of one flat chart."""
    chart = flat.chart
    cls = identifiers([chart.name])[chart.name]
    ns = identifiers([chart.name], lower=True)[chart.name]
    base = ns
    return {
        f"{base}.hpp": _header(flat, cls, ns),
        f"{base}_check.cpp": _check(flat, cls, ns, base),
        "CMakeLists.txt": _cmake(cls, ns, base),
    }


def _header(flat: FlatChart, cls: str, ns: str) -> str:
    chart = flat.chart
    st = identifiers(flat.states)
    ev = identifiers(flat.events)
    invokes = sorted(chart.invokes, key=lambda i: i.number)
    inv = identifiers([i.name for i in invokes])
    methods = identifiers([i.method for i in invokes])
    tables = _Tables(flat)
    start = tables.code(flat.start)
    dispatch = [[tables.code(t) for t in row] for row in flat.dispatch]
    n_states, n_events, n_configs = len(flat.states), len(flat.events), len(flat.configurations)
    words = max(1, (n_states + 63) // 64)
    n_invokes = max(1, max((i.number for i in invokes), default=0) + 1)
    guard = f"STATECTL_GENERATED_{ns.upper()}_HPP"
    src = os.path.basename(chart.origin.file) if chart.origin.file != "<memory>" else "<memory>"
    w: list[str] = []
    add = w.append
    add(f"// {cls}: generated by statectl codegen from {src}. Do not edit; regenerate.")
    add("//")
    add(
        f"// {n_configs} configurations x {n_events} events, {len(tables.outcomes)} outcomes, "
        f"{len(flat.guards)} runtime guards."
    )
    add("// Every decision below was made by statectl's semantics at generation time; see")
    add("// docs/codegen.md. Contract checks: 101 event out of range, 102 dispatch re-entered,")
    add("// 103 dispatch before start, 104 start twice, 107 corrupt state word.")
    add(f"#ifndef {guard}")
    add(f"#define {guard}")
    add("")
    add("#include <cstddef>")
    add("#include <cstdint>")
    add("#include <utility>")
    add("")
    add('#include "statectl/runtime.hpp"')
    add("")
    add(f"namespace {ns} {{")
    add("")
    add("/// Chart states, document order (compound and parallel states included).")
    add("enum class State : std::uint16_t {")
    for n, name in enumerate(flat.states):
        add(f"  {st[name]} = {n},  // {_comment(name)}")
    add("};")
    add("")
    add("/// External events, in the chart's order.")
    add("enum class Event : std::uint16_t {")
    for n, name in enumerate(flat.events):
        add(f"  {ev[name]} = {n},  // {_comment(name)}")
    add("};")
    add("")
    add("/// Invoke numbers: the value a notification carries (the paper's step 3).")
    add("enum class Invoke : std::uint8_t {")
    for iv in invokes:
        add(f"  {inv[iv.name]} = {iv.number},  // observer method {_comment(iv.method)}()")
    if not invokes:
        add("  None_ = 0,  // the chart notifies no observer")
    add("};")
    add("")
    add("inline constexpr std::size_t kStateCount = " + f"{n_states};")
    add("inline constexpr std::size_t kEventCount = " + f"{n_events};")
    add("inline constexpr std::size_t kConfigurationCount = " + f"{n_configs};")
    add("inline constexpr std::size_t kInvokeCount = " + f"{n_invokes};")
    add("")
    add("/// The data guards read, filled by the user (64-bit integers, booleans as 0/1).")
    add("struct Context {")
    for f in flat.context:
        add(f"  std::int64_t {f.ident} = {f.initial};  // {_comment(f.name)}")
    add("};")
    add("")
    add("/// Entry/exit hooks: Basic<Device><H> calls H::on_exit/on_entry for every state exit")
    add("/// and entry, in the order the semantics decided, after the tracer saw it. Static")
    add("/// dispatch: with NoHooks the calls compile to nothing.")
    add("struct NoHooks {")
    add("  void on_exit(State /*state*/) noexcept {}")
    add("  void on_entry(State /*state*/) noexcept {}")
    add("};")
    add("")
    add("/// The device with its API: one method per invoke number.")
    add(f"class {cls}Api : public statectl::Observer<Invoke> {{")
    add(" public:")
    add("  void update(Invoke invoke) noexcept final {")
    if invokes:
        add("    switch (invoke) {")
        for iv in invokes:
            add(f"      case Invoke::{inv[iv.name]}:")
            add(f"        {methods[iv.method]}();")
            add("        break;")
        add("    }")
    else:
        add("    static_cast<void>(invoke);")
    add("  }")
    for iv in invokes:
        add(f"  virtual void {methods[iv.method]}() noexcept = 0;  // invoke #{iv.number}")
    add("")
    add(" protected:")
    add(f"  {cls}Api() = default;")
    add(f"  {cls}Api(const {cls}Api&) = default;")
    add(f"  {cls}Api& operator=(const {cls}Api&) = default;")
    add(f"  ~{cls}Api() = default;")
    add("};")
    add("")
    add("namespace detail {")
    add("")
    add("using V = std::int64_t;")
    add("")
    add("enum Op : std::uint8_t { kExit, kTake, kEnter, kInvoke };")
    add("")
    add("struct Effect {")
    add("  Op op;")
    add("  std::uint16_t arg;  // state, transition or invoke number")
    add("};")
    add("")
    add("// flags: bit 0 handled, bit 1 reached a top-level final state,")
    add("// bits 2-3 why unhandled (1 declared ignored, 2 guard false, 3 no transition).")
    add("struct Outcome {")
    add("  std::uint16_t target;  // configuration after the step (handled only)")
    add("  std::uint16_t first;   // effects [first, first + count)")
    add("  std::uint16_t count;")
    add("  std::uint8_t flags;")
    add("};")
    add("")
    add("// Evaluate guard; a code >= 0 is an outcome, < 0 is ~decision.")
    add("struct Decision {")
    add("  std::uint16_t guard;")
    add("  std::int16_t if_true;")
    add("  std::int16_t if_false;")
    add("};")
    add("")
    add("struct TransitionText {")
    add("  const char* source;")
    add("  const char* targets;")
    add("  const char* label;")
    add("};")
    add("")
    add("struct InvokeText {")
    add("  const char* name;")
    add("  const char* method;")
    add("};")
    add("")
    add("inline constexpr const char* kDevice = " + _c(chart.name) + ";")
    add("")
    add("inline constexpr const char* kStateNames[kStateCount] = {")
    for name in flat.states:
        add(f"    {_c(name)},")
    add("};")
    add("")
    add(f"inline constexpr const char* kEventNames[{max(1, n_events)}] = {{")
    for name in flat.events:
        add(f"    {_c(name)},")
    if not flat.events:
        add('    "",  // unused: the chart has no events')
    add("};")
    add("")
    add("inline constexpr const char* kReasons[4] = {")
    add('    "", "declared ignored", "guard false", "no transition",')
    add("};")
    add("")
    n_trans = max(1, len(flat.transitions))
    add(f"inline constexpr TransitionText kTransitions[{n_trans}] = {{")
    for i, t in enumerate(flat.transitions):
        add(f"    {{{_c(t.source)}, {_c(', '.join(t.targets))}, {_c(t.label)}}},  // {i}")
    if not flat.transitions:
        add('    {"", "", ""},  // unused: the chart has no transitions')
    add("};")
    add("")
    add("inline constexpr InvokeText kInvokes[kInvokeCount] = {")
    by_number = {i.number: i for i in invokes}
    for n in range(n_invokes):
        found = by_number.get(n)
        if found is None:
            add('    {"", ""},  // no invoke with this number')
        else:
            add(f"    {{{_c(found.name)}, {_c(found.method)}}},  // #{n}")
    add("};")
    add("")
    # guards
    add("// Runtime guards, each specialised to the configuration it is evaluated in.")
    for g in flat.guards:
        prev = g.previous if g.previous is not None else "-"
        add(f"// guard {g.index}: {_comment(g.source)}   (previous {prev})")
        add(f"inline bool guard_{g.index}(const Context& c) noexcept {{")
        add("  static_cast<void>(c);")
        add(f"  return {g.cpp};")
        add("}")
    add("")
    add("using GuardFn = bool (*)(const Context&) noexcept;")
    add("")
    if flat.guards:
        add(f"inline constexpr GuardFn kGuards[{len(flat.guards)}] = {{")
        for g in flat.guards:
            add(f"    &guard_{g.index},")
        add("};")
    else:
        add("inline constexpr GuardFn kGuards[1] = {nullptr};  // unused: no runtime guards")
    add("")
    # effects
    add(f"inline constexpr Effect kEffects[{max(1, len(tables.effects))}] = {{")
    iw = _width(range(len(tables.effects)))
    for n, fx in enumerate(tables.effects):
        text = _comment(tables.effect_text(fx))
        add(f"    {{{_OPS[fx.kind]}, {fx.index}}},  // {n:>{iw}}: {text}")
    if not tables.effects:
        add("    {kTake, 0},  // unused: no step has an effect")
    add("};")
    add("")
    add(f"inline constexpr Outcome kOutcomes[{len(tables.outcomes)}] = {{")
    ow = _width(range(len(tables.outcomes)))
    for i, (target, first, count, flags, text) in enumerate(tables.outcomes):
        add(f"    {{{target}, {first}, {count}, {flags}}},  // {i:>{ow}}: {_comment(text)}")
    add("};")
    add("")
    add(f"inline constexpr Decision kDecisions[{max(1, len(tables.decisions))}] = {{")
    for n, (gid, yes, no) in enumerate(tables.decisions):
        add(f"    {{{gid}, {yes}, {no}}},  // ~{n}: guard_{gid} ? {yes} : {no}")
    if not tables.decisions:
        add("    {0, 0, 0},  // unused: no runtime guards")
    add("};")
    add("")
    depth = _depth(flat)
    add(f"inline constexpr int kMaxDepth = {depth};  // most guards one step evaluates")
    add(f"inline constexpr std::int16_t kStart = {start};  // entering the initial configuration")
    add("")
    cases, cells = _cells(dispatch, n_configs, n_events)
    add("// Dispatch cells, event-major: kCells[event * kConfigurationCount + configuration] is")
    add("// the case of dispatch()'s switch that runs the step (one row per event, columns are")
    add("// the configurations 0.., see kActive). Cells past the table are contract faults.")
    add(f"inline constexpr std::size_t kCellCount = {len(cells)};")
    add(f"inline constexpr std::size_t kCaseCount = {len(cases)};")
    ctype = "std::uint8_t" if len(cases) <= 256 else "std::uint16_t"
    add(f"inline constexpr {ctype} kCells[{max(1, len(cells))}] = {{")
    cw = _width(cells)
    for e, name in enumerate(flat.events):
        row = cells[e * n_configs : (e + 1) * n_configs]
        for k in range(0, len(row), 24):
            body = ", ".join(f"{x:>{cw}}" for x in row[k : k + 24])
            note = f"  // {e}: {_comment(name)}" if k == 0 else ""
            add(f"    {body},{note}")
    if not cells:
        add("    0,  // unused: the chart has no events")
    add("};")
    add("")
    add("constexpr bool cells_name_cases() noexcept {")
    add("  for (std::size_t i = 0; i < sizeof kCells / sizeof kCells[0]; ++i) {")
    add("    if (kCellCount != 0 && kCells[i] >= kCaseCount) {")
    add("      return false;")
    add("    }")
    add("  }")
    add("  return true;")
    add("}")
    add('static_assert(cells_name_cases(), "every cell names a case of dispatch()");')
    add("")
    add(f"inline constexpr std::uint64_t kActive[kConfigurationCount][{words}] = {{")
    order = {s: i for i, s in enumerate(flat.states)}
    for c in flat.configurations:
        bits = [0] * words
        for s in c.active:
            bits[order[s] // 64] |= 1 << (order[s] % 64)
        add("    {" + ", ".join(f"0x{b:x}u" for b in bits) + f"}},  // {c.index}")
    add("};")
    add("")
    add("}  // namespace detail")
    add("")
    add(_device_class(cls, start, _cases(tables, cases), bool(cells)))
    add("")
    add(f"}}  // namespace {ns}")
    add("")
    add(f"#endif  // {guard}")
    return "\n".join(w) + "\n"


def _depth(flat: FlatChart) -> int:
    def depth(t: Tree) -> int:
        if isinstance(t, Decision):
            return 1 + max(depth(t.if_true), depth(t.if_false))
        return 0

    trees = [flat.start, *(t for row in flat.dispatch for t in row)]
    return max(depth(t) for t in trees)


_DEVICE = """\
/// The device: run-to-completion dispatch over the flat tables.
template <typename H = NoHooks>
class Basic@CLS@ : public statectl::Subject<Invoke, kInvokeCount> {
  // The state word (see below), first so that it packs with the empty Context and hooks.
  std::uint32_t state_ = kNew;

 public:
#ifndef @QUEUE_MACRO@
  static constexpr std::size_t kQueueCapacity = 16;
#else
  static constexpr std::size_t kQueueCapacity = @QUEUE_MACRO@;
#endif

  Context context{};  // what guards read; fill it before start() and between events
  H hooks{};          // entry/exit hooks (see NoHooks)

  /// Enter the initial configuration.
  void start() noexcept {
    STATECTL_REQUIRE(104, state_ == kNew, "start: the device was started already");
    STATECTL_TRACE_CALL(tracer_, started(detail::kDevice));
    state_ = kBusy;  // the initial configuration sets it; hooks that dispatch fault (102)
    @START@;
  }

  /// Process one event to completion; the owner thread only.
  ///
  /// One bound check, one load from kCells, one indexed jump. The bound check is every
  /// contract of the hot path at once: an event out of range (101), a busy device (102,
  /// bit 31 of the state word) or one not started (103, bit 30) gives a cell past the
  /// table, and the cold fault() names the contract.
  void dispatch(Event event) noexcept {
@DISPATCH@
  }

  /// Queue an event from one producer thread (a monitor); false when the queue is full.
  bool post(Event event) noexcept { return queue_.push(event); }

  /// Dispatch queued events, at most kQueueCapacity of them; returns how many ran.
  std::size_t run_until_idle() noexcept {
    std::size_t count = 0;
    Event event{};
    while (count < kQueueCapacity && queue_.pop(event)) {
      dispatch(event);
      ++count;
    }
    return count;
  }

  /// Is chart state `state` active? (Nothing is before start().)
  bool in(State state) const noexcept {
    if ((state_ & kNew) != 0) {
      return false;
    }
    const auto s = static_cast<std::size_t>(state);
    return ((detail::kActive[state_ & kConfigurationMask][s / 64] >> (s % 64)) & 1u) != 0;
  }

  std::uint16_t configuration() const noexcept {
    return static_cast<std::uint16_t>(state_ & kConfigurationMask);
  }
  bool started() const noexcept { return (state_ & kNew) == 0; }
  bool finished() const noexcept { return finished_; }
#if STATECTL_TRACE
  void set_tracer(statectl::Tracer* tracer) noexcept { tracer_ = tracer; }
#endif

 private:
  // The state word: the configuration in the low 16 bits, plus two flags that put every
  // cell index past the table (kConfigurationCount * 65536 events < kNew).
  static constexpr std::uint32_t kConfigurationMask = 0xFFFFu;
  static constexpr std::uint32_t kNew = 1u << 30;   // start() not called yet
  static constexpr std::uint32_t kBusy = 1u << 31;  // observers or hooks running
  static_assert(kConfigurationCount <= kConfigurationMask + 1 &&
                    kConfigurationCount * 65536u <= kNew,
                "the state word's flags must lie past every cell");

  [[noreturn]] STATECTL_COLD void fault(std::size_t event) const noexcept {
    STATECTL_REQUIRE(101, event < kEventCount, "dispatch: event out of range");
    STATECTL_REQUIRE(102, (state_ & kBusy) == 0,
                     "dispatch: re-entered from an observer or hook; post() instead");
    STATECTL_REQUIRE(103, (state_ & kNew) == 0, "dispatch: call start() first");
    statectl::contract_failed(107, "dispatch: configuration out of range (corrupt state)");
  }

  /// One table cell: trace the event, then its outcome or guard-decision tree.
  template <int Code>
  void step([[maybe_unused]] std::size_t event) noexcept {
    STATECTL_TRACE_CALL(tracer_, event(detail::kDevice, detail::kEventNames[event]));
    run<Code>(event);
  }

  /// Code >= 0: apply outcome Code; < 0: decision ~Code, unrolled at compile time, so the
  /// guards run in the order the semantics consulted them with no loop and no bound.
  template <int Code>
  void run([[maybe_unused]] std::size_t event) noexcept {
    if constexpr (Code >= 0) {
      apply<static_cast<std::size_t>(Code)>(event);
    } else {
      constexpr detail::Decision d = detail::kDecisions[~Code];
      if (detail::kGuards[d.guard](context)) {
        run<d.if_true>(event);
      } else {
        run<d.if_false>(event);
      }
    }
  }

  /// Outcome K as straight-line code: its effects are constant table rows.
  template <std::size_t K>
  void apply([[maybe_unused]] std::size_t event) noexcept {
    constexpr detail::Outcome o = detail::kOutcomes[K];
    if constexpr ((o.flags & 1u) == 0) {
      STATECTL_TRACE_CALL(tracer_, ignored(detail::kDevice, detail::kEventNames[event],
                                           detail::kReasons[o.flags >> 2]));
    } else {
      // Observers and hooks see the new configuration and the busy bit; with no call
      // between the two stores the compiler drops the first.
      state_ = o.target | kBusy;
      effects<o.first>(std::make_index_sequence<o.count>{});
      if constexpr ((o.flags & 2u) != 0) {
        finish();
      }
      state_ = o.target;
    }
  }

  template <std::size_t First, std::size_t... I>
  void effects(std::index_sequence<I...>) noexcept {
    (effect<First + I>(), ...);
  }

  template <std::size_t F>
  void effect() noexcept {
    constexpr detail::Effect fx = detail::kEffects[F];
    if constexpr (fx.op == detail::kExit) {
      STATECTL_TRACE_CALL(tracer_, exited(detail::kDevice, detail::kStateNames[fx.arg]));
      hooks.on_exit(static_cast<State>(fx.arg));
    } else if constexpr (fx.op == detail::kTake) {
      STATECTL_TRACE_CALL(tracer_, taken(detail::kDevice, detail::kTransitions[fx.arg].source,
                                         detail::kTransitions[fx.arg].targets,
                                         detail::kTransitions[fx.arg].label));
    } else if constexpr (fx.op == detail::kEnter) {
      STATECTL_TRACE_CALL(tracer_, entered(detail::kDevice, detail::kStateNames[fx.arg]));
      hooks.on_entry(static_cast<State>(fx.arg));
    } else {
      STATECTL_TRACE_CALL(tracer_, invoked(detail::kDevice, fx.arg, detail::kInvokes[fx.arg].name,
                                           detail::kInvokes[fx.arg].method));
      notify(static_cast<Invoke>(fx.arg));
    }
  }

  void finish() noexcept {
    if (!finished_) {
      finished_ = true;
      STATECTL_TRACE_CALL(tracer_, finished(detail::kDevice));
    }
  }

  bool finished_ = false;
#if STATECTL_TRACE
  statectl::Tracer* tracer_ = nullptr;
#endif
  statectl::SpscQueue<Event, kQueueCapacity> queue_;
};

/// The device without hooks.
using @CLS@ = Basic@CLS@<>;"""


def _cells(dispatch: list[list[int]], n_configs: int, n_events: int) -> tuple[list[int], list[int]]:
    """The switch's cases (distinct codes, first use) and the event-major cells naming them."""
    cases: list[int] = []
    index: dict[int, int] = {}
    cells: list[int] = []
    for e in range(n_events):
        for c in range(n_configs):
            code = dispatch[c][e]
            if code not in index:
                index[code] = len(cases)
                cases.append(code)
            cells.append(index[code])
    return cases, cells


def _cases(tables: _Tables, cases: list[int]) -> str:
    """One case per distinct cell code: an outcome's effects or a guard-decision tree."""
    out: list[str] = []
    for k, code in enumerate(cases):
        if code >= 0:
            what = f"outcome {code}: {tables.outcomes[code][4]}"
        else:
            gid, yes, no = tables.decisions[~code]
            what = f"decision ~{~code}: guard_{gid} ? {yes} : {no}"
        out.append(f"      case {k}:  // {_comment(what)}")
        out.append(f"        step<{code}>(e);")
        out.append("        break;")
    return "\n".join(out)


_DISPATCH = """\
    const auto e = static_cast<std::size_t>(event);
    const std::size_t cell = e * kConfigurationCount + state_;
    if (STATECTL_UNLIKELY(cell >= detail::kCellCount)) {
      fault(e);
    }
    switch (detail::kCells[cell]) {
@CASES@
      default:
        STATECTL_UNREACHABLE();  // every cell names a case (static_assert on kCells)
    }"""

_NO_EVENTS = """\
    fault(static_cast<std::size_t>(event));  // the chart has no events: always 101"""


def _device_class(cls: str, start: int, cases: str, has_cells: bool) -> str:
    macro = f"STATECTL_{cls.upper()}_QUEUE_CAPACITY"
    body = _DISPATCH.replace("@CASES@", cases) if has_cells else _NO_EVENTS
    return (
        _DEVICE.replace("@CLS@", cls)
        .replace("@QUEUE_MACRO@", macro)
        .replace("@START@", f"run<{start}>(0)")
        .replace("@DISPATCH@", body)
    )


def _check(flat: FlatChart, cls: str, ns: str, base: str) -> str:
    """A small program the CMake target builds: every event once, every API attached."""
    invokes = sorted(flat.chart.invokes, key=lambda i: i.number)
    methods = identifiers([i.method for i in invokes])
    lines = [
        f"// {cls}: build check generated by statectl codegen. Dispatches every event once.",
        f'#include "{base}.hpp"',
        "",
        "#include <cstdio>",
        "",
        "namespace {",
        "",
        f"class CountingApi final : public {ns}::{cls}Api {{",
        " public:",
    ]
    lines += [f"  void {methods[i.method]}() noexcept override {{ ++calls; }}" for i in invokes]
    lines += [
        "  int calls = 0;",
        "};",
        "",
        "}  // namespace",
        "",
        "int main() {",
        f"  {ns}::{cls} device;",
        "  CountingApi api;",
    ]
    lines += [f"  device.attach(api, {ns}::Invoke({i.number}));" for i in invokes]
    lines += [
        "  device.start();",
        f"  for (std::size_t e = 0; e < {ns}::kEventCount; ++e) {{",
        f"    static_cast<void>(device.post(static_cast<{ns}::Event>(e)));",
        "    device.run_until_idle();",
        "  }",
        f'  std::printf("{cls}: configuration %u, %d API calls\\n",',
        "              static_cast<unsigned>(device.configuration()), api.calls);",
        "  return 0;",
        "}",
    ]
    return "\n".join(lines) + "\n"


def _cmake(cls: str, ns: str, base: str) -> str:
    return f"""\
# {cls}: generated by statectl codegen. Header-only: link the target, include "{base}.hpp".
#   add_subdirectory(<this dir>) then target_link_libraries(app PRIVATE statectl::{ns})
#   or install it and find_package({ns}) in another project.
cmake_minimum_required(VERSION 3.16)
project({ns}_statectl LANGUAGES CXX)

add_library({ns} INTERFACE)
add_library(statectl::{ns} ALIAS {ns})
target_include_directories({ns} INTERFACE
  $<BUILD_INTERFACE:${{CMAKE_CURRENT_SOURCE_DIR}}>
  $<INSTALL_INTERFACE:include>)
target_compile_features({ns} INTERFACE cxx_std_17)

option(STATECTL_{ns.upper()}_CHECK "Build the {base}_check program" ON)
if(STATECTL_{ns.upper()}_CHECK)
  add_executable({ns}_check {base}_check.cpp)
  target_link_libraries({ns}_check PRIVATE {ns})
  set_target_properties({ns}_check PROPERTIES CXX_EXTENSIONS OFF)
  if(CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
    target_compile_options({ns}_check PRIVATE
      -Wall -Wextra -Wpedantic -Werror -fno-exceptions -fno-rtti)
  endif()
endif()

include(GNUInstallDirs)
install(TARGETS {ns} EXPORT {ns}Targets)
install(FILES {base}.hpp DESTINATION ${{CMAKE_INSTALL_INCLUDEDIR}})
install(DIRECTORY statectl DESTINATION ${{CMAKE_INSTALL_INCLUDEDIR}})
install(EXPORT {ns}Targets NAMESPACE statectl:: FILE {ns}Config.cmake
  DESTINATION ${{CMAKE_INSTALL_LIBDIR}}/cmake/{ns})
"""


def runtime_files() -> dict[str, str]:
    """The shared header-only runtime, as packaged."""
    root = files("statectl.codegen") / "runtime"
    return {
        f"statectl/{name}": (root / name).read_text(encoding="utf-8") for name in RUNTIME_HEADERS
    }


def generate(chart: Chart, out_dir: str | os.PathLike[str]) -> tuple[list[Path], list[Diagnostic]]:
    """Write the device header, the runtime and a CMake target to ``out_dir``.

    Returns the written paths and every diagnostic; with an error nothing is written.
    """
    flat, diags = flatten(chart)
    if flat is None or has_errors(diags):
        return [], diags
    texts = {**render(flat), **runtime_files()}
    out = Path(out_dir)
    written: list[Path] = []
    for rel, text in sorted(texts.items()):
        path = out / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
        written.append(path)
    return written, diags


def run_codegen(path: str, out_dir: str, target: str, out: TextIO, err: TextIO) -> int:
    """``statectl codegen FILE --target cpp --out DIR``: 0 written, 1 diagnostics, 2 usage."""
    if target != "cpp":
        err.write(f"statectl codegen: unknown target {target!r} (available: cpp)\n")
        return 2
    from statectl.build import load_and_build  # outer ring: codegen reads tables via build

    try:
        chart, diags = load_and_build(path)
    except DiagnosticError as exc:
        chart, diags = None, list(exc.diagnostics)
    except OSError as exc:
        err.write(f"statectl codegen: cannot read {path}: {exc.strerror or exc}\n")
        return 2
    if chart is None:
        for d in diags:
            err.write(f"{d}\n")
        return 1
    written, gen_diags = generate(chart, out_dir)
    for d in (*diags, *gen_diags):
        if d.severity is not Severity.INFO:
            err.write(f"{d}\n")
    if not written:
        return 1
    for p in written:
        out.write(f"{p}\n")
    return 0
