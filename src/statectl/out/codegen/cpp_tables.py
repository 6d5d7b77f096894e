"""The data side of the C++ generator: tables as ``constexpr`` arrays and the dispatch switch.

Rule 1 of :mod:`statectl.out.codegen.cpp`: everything the semantics decided is
data. This module turns a flat chart's cells, outcomes and guard trees into
C++ text; the header around it is :mod:`statectl.out.codegen.cpp_header`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from statectl.kernel.semantics import Unhandled
from statectl.out.codegen.flat import Decision, Effect, EffectKind, FlatChart, FlatStep, Tree
from statectl.out.escape.cpp import comment as _comment

#: The reasons a flattened outcome can give, by their number in the outcome's flags
#: (``None``: handled); the C++ ``kReasons`` table is written from this tuple.
REASONS: tuple[Unhandled | None, ...] = (
    None,
    Unhandled.DECLARED_IGNORED,
    Unhandled.GUARD_FALSE,
    Unhandled.NO_TRANSITION,
)
_REASON_BITS = {reason: i for i, reason in enumerate(REASONS)}


_OPS = {
    EffectKind.EXIT: "kExit",
    EffectKind.TAKE: "kTake",
    EffectKind.ENTER: "kEnter",
    EffectKind.INVOKE: "kInvoke",
    EffectKind.ASSIGN: "kAssign",
}


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

    def _outcome(self, o: FlatStep) -> int:
        flags = (1 if o.handled else 0) | (2 if o.final else 0) | (_REASON_BITS[o.unhandled] << 2)
        target = o.target if o.handled else 0
        key = (target, self.run(o.effects), len(o.effects), flags)
        found = self.outcome_ids.get(key)
        if found is None:
            found = self.outcome_ids[key] = len(self.outcomes)
            self.outcomes.append((*key, self._describe(o)))
        return found

    def _describe(self, o: FlatStep) -> str:
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
        if e.kind is EffectKind.ASSIGN:
            return f"assign {flat.assignments[e.index].source}"
        if e.kind is EffectKind.INVOKE:
            inv = next(i for i in flat.chart.invokes if i.number == e.index)
            return f"invoke #{inv.number} {inv.name}"
        return f"{e.kind.value} {flat.states[e.index]}"


def _width(values: Sequence[int]) -> int:
    return max((len(str(v)) for v in values), default=1)


def _depth(flat: FlatChart) -> int:
    def depth(t: Tree) -> int:
        if isinstance(t, Decision):
            return 1 + max(depth(t.if_true), depth(t.if_false))
        return 0

    trees = [flat.start, *(t for row in flat.dispatch for t in row.explicit.values())]
    return max(depth(t) for t in trees)  # an unhandled cell (not explicit) has depth 0


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
  }@TIMER_PUBLIC@

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
                                           detail::kReasons[o.flags >> 2]));@DEFER_KEEP@
    } else {
      // Observers and hooks see the new configuration and the busy bit; with no call
      // between the two stores the compiler drops the first.
      state_ = o.target | kBusy;
      effects<o.first>(std::make_index_sequence<o.count>{});
      if constexpr ((o.flags & 2u) != 0) {
        finish();
      }
      state_ = o.target;@DEFER_RELEASE@
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
      hooks.on_exit(static_cast<State>(fx.arg));@TIMER_EXIT@
    } else if constexpr (fx.op == detail::kTake) {
      STATECTL_TRACE_CALL(tracer_, taken(detail::kDevice, detail::kTransitions[fx.arg].source,
                                         detail::kTransitions[fx.arg].targets,
                                         detail::kTransitions[fx.arg].label));
    } else if constexpr (fx.op == detail::kEnter) {
      STATECTL_TRACE_CALL(tracer_, entered(detail::kDevice, detail::kStateNames[fx.arg]));
      hooks.on_entry(static_cast<State>(fx.arg));@TIMER_ENTER@
    } else if constexpr (fx.op == detail::kAssign) {
      detail::kAssigns[fx.arg](context);  // the row's assign: all values, then all stores
    } else {
      STATECTL_TRACE_CALL(tracer_, invoked(detail::kDevice, fx.arg, detail::kInvokes[fx.arg].name,
                                           detail::kInvokes[fx.arg].method));
      notify(static_cast<Invoke>(fx.arg));
    }
  }

  void finish() noexcept {
    if (!finished_) {
      finished_ = true;@TIMER_FINISH@
      STATECTL_TRACE_CALL(tracer_, finished(detail::kDevice));
    }
  }

  bool finished_ = false;@TIMER_FIELDS@
#if STATECTL_TRACE
  statectl::Tracer* tracer_ = nullptr;
#endif
  statectl::SpscQueue<Event, kQueueCapacity> queue_;
};

/// The device without hooks.
using @CLS@ = Basic@CLS@<>;"""


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


#: dispatch() over compact rows: the range checks, then the row's binary search.
_COMPACT_DISPATCH = """\
    const auto e = static_cast<std::size_t>(event);
    if (STATECTL_UNLIKELY(e >= kEventCount || state_ >= kConfigurationCount)) {
      fault(e);
    }
    switch (detail::cell_case(e, state_)) {
@CASES@
      default:
        STATECTL_UNREACHABLE();  // every row names a case (static_assert on kRowCells)
    }"""


_DENSE_NOTE = """\
  /// One bound check, one load from kCells, one indexed jump. The bound check is every
  /// contract of the hot path at once: an event out of range (101), a busy device (102,
  /// bit 31 of the state word) or one not started (103, bit 30) gives a cell past the
  /// table, and the cold fault() names the contract."""

_COMPACT_NOTE = """\
  /// Two range checks, a binary search of the event's row in kRowCells, one indexed
  /// jump. The range checks are every contract of the hot path at once: an event out
  /// of range (101), a busy device (102, bit 31 of the state word) or one not started
  /// (103, bit 30) fails them, and the cold fault() names the contract."""


_NO_EVENTS = """\
    fault(static_cast<std::size_t>(event));  // the chart has no events: always 101"""


def _device_class(
    cls: str,
    start: int,
    cases: str,
    has_cells: bool,
    parts: Mapping[str, str],
    *,
    compact: bool = False,
) -> str:
    macro = f"STATECTL_{cls.upper()}_QUEUE_CAPACITY"
    dispatch = _COMPACT_DISPATCH if compact else _DISPATCH  # codegen.cpp_rows rules 1, 2
    body = dispatch.replace("@CASES@", cases) if has_cells else _NO_EVENTS
    device = _DEVICE
    if compact:  # the dense form's comment describes kCells (codegen.cpp_rows rule 2)
        device = device.replace(_DENSE_NOTE, _COMPACT_NOTE)
    for place, text in parts.items():  # per-state timeouts (cpp_timers), empty without
        device = device.replace(place, text)
    return (
        device.replace("@CLS@", cls)
        .replace("@QUEUE_MACRO@", macro)
        .replace("@START@", f"run<{start}>(0)")
        .replace("@DISPATCH@", body)
    )
