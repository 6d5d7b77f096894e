"""Per-state timeouts and deferred events in the generated C++.

Timeouts are counted on a millisecond tick the controller supplies; deferred events are
kept in a small fixed array.

Rules:
1. Generated code reads no clock. ``tick(now_ms)`` takes a monotonic millisecond count
   from the controller (any ``uint32_t`` that wraps; call it at least every 2^31 ms);
   a step that enters a state with a timeout arms it at the last tick's time plus its
   duration, a step that leaves it (or the end of the run) disarms it.
2. ``tick`` first runs the queued events, then fires every armed timeout that is due,
   earliest deadline first (ties: the one armed first), each as ``dispatch`` of its
   event at its deadline (an entry it causes is armed from there) followed by
   ``run_until_idle``: exactly what the Python runtime does when a SimClock advances,
   so the traces are equal (tests/test_codegen_timers.py).
3. A chart without timeouts gets none of this: no member, no table, not a byte.
4. Deferred events (the ``defer`` cell): the flat tables answer "declared ignored" for
   them, as the kernel does; ``kDeferred[configuration]`` says which events the
   configuration defers. An event ignored so is kept in an array of
   :data:`~statectl.run.runtime.defer.MAX_DEFERRED` events (one more is dropped), and after
   every handled step the kept events no longer deferred are dispatched again, in the
   order they arrived, before anything queued: statectl.run.runtime.defer's rules.
5. G710 a timeout whose event the chart does not know, G711 a duration that is not a
   whole number of milliseconds from 1 to 2^31-1, G712 a timeout on a state the flat
   tables cannot index (more than 32767 states).
"""

from __future__ import annotations

from collections.abc import Mapping

from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.model import MAX_DEFERRED, Chart
from statectl.out.codegen.flat import FlatChart
from statectl.out.escape.cpp import comment

__all__ = ["check_timeouts", "defer_tables", "device_parts", "timer_tables"]

_MAX_MS = 2**31 - 1


def check_timeouts(chart: Chart, where: Location, diags: list[Diagnostic]) -> None:
    """G710-G712 for the chart's timeouts, before anything is flattened."""
    events = set(chart.event_names)
    for index, s in enumerate(chart.states):
        t = s.timeout
        if t is None:
            continue
        at = t.origin if t.origin.file is not None else where
        if t.event not in events:
            diags.append(
                Diagnostic(
                    "G710",
                    Severity.ERROR,
                    at,
                    f"state {s.name!r} times out with {t.event!r}, which the chart does not know",
                    "declare the event (an event row) so the C++ has an Event for it",
                )
            )
        ms = t.seconds * 1000
        if not (1 <= ms <= _MAX_MS) or abs(ms - round(ms)) > 1e-6:
            diags.append(
                Diagnostic(
                    "G711",
                    Severity.ERROR,
                    at,
                    f"state {s.name!r}: timeout {t.seconds!r} s is not a whole number of "
                    f"milliseconds from 1 to {_MAX_MS}",
                    "the C++ counts milliseconds in a uint32_t: round the duration",
                )
            )
        if index > 32767:
            diags.append(
                Diagnostic(
                    "G712",
                    Severity.ERROR,
                    at,
                    f"state {s.name!r} (number {index}) is past the timeout table's int16 index",
                    "a chart with timeouts may have at most 32768 states",
                )
            )


def _timeouts(flat: FlatChart) -> list[tuple[str, int, int]]:
    """(state, milliseconds, event index) per state with a timeout, in state order."""
    out = []
    for name in flat.states:
        t = flat.chart.state(name).timeout
        if t is not None:
            out.append((name, round(t.seconds * 1000), flat.events.index(t.event)))
    return out


def timer_tables(flat: FlatChart) -> list[str]:
    """The ``detail`` tables of the timeouts (nothing for a chart without any)."""
    timeouts = _timeouts(flat)
    if not timeouts:
        return []
    slot = {name: k for k, (name, _, _) in enumerate(timeouts)}
    lines = [
        "// Per-state timeouts (the state table's timeout cells), counted by tick(now_ms).",
        f"inline constexpr std::size_t kTimeoutCount = {len(timeouts)};",
        "inline constexpr std::uint32_t kTimeoutMs[kTimeoutCount] = {",
        *(f"    {ms}u,  // {comment(name)}" for name, ms, _ in timeouts),
        "};",
        "inline constexpr Event kTimeoutEvent[kTimeoutCount] = {",
        *(f"    Event({e}),  // {comment(flat.events[e])}" for _, _, e in timeouts),
        "};",
        "// The timeout slot of each state, -1 for none.",
        "inline constexpr std::int16_t kTimeoutOf[kStateCount] = {",
        "    " + ", ".join(str(slot.get(s, -1)) for s in flat.states) + ",",
        "};",
        "",
    ]
    return lines


_PUBLIC = """

  /// Per-state timeouts: tell the device the time, a monotonic millisecond count from the
  /// controller (wrapping at 2^32 is fine; call at least every 2^31 ms). Runs the queued
  /// events, then every timeout due by now_ms, earliest first, each at its deadline.
  void tick(std::uint32_t now_ms) noexcept {
    run_until_idle();
    for (;;) {
      std::size_t due = detail::kTimeoutCount;
      for (std::size_t k = 0; k < detail::kTimeoutCount; ++k) {
        if (!timeout_armed_[k] ||
            static_cast<std::int32_t>(now_ms - timeout_deadline_[k]) < 0) {
          continue;
        }
        if (due != detail::kTimeoutCount) {
          const auto d = static_cast<std::int32_t>(timeout_deadline_[k] - timeout_deadline_[due]);
          const auto s = static_cast<std::int32_t>(timeout_seq_[k] - timeout_seq_[due]);
          if (d > 0 || (d == 0 && s > 0)) {
            continue;
          }
        }
        due = k;
      }
      if (due == detail::kTimeoutCount) {
        break;
      }
      now_ms_ = timeout_deadline_[due];
      timeout_armed_[due] = false;
      dispatch(detail::kTimeoutEvent[due]);
      run_until_idle();
    }
    now_ms_ = now_ms;
  }

  /// The time of the last tick (what an entry arms its timeout from).
  std::uint32_t now_ms() const noexcept { return now_ms_; }

  /// Is the timeout of chart state `state` running?
  bool timing(State state) const noexcept {
    const int slot = detail::kTimeoutOf[static_cast<std::size_t>(state)];
    return slot >= 0 && timeout_armed_[static_cast<std::size_t>(slot)];
  }"""

_ENTER = """
      if constexpr (detail::kTimeoutOf[fx.arg] >= 0) {
        constexpr auto k = static_cast<std::size_t>(detail::kTimeoutOf[fx.arg]);
        timeout_armed_[k] = true;
        timeout_deadline_[k] = now_ms_ + detail::kTimeoutMs[k];
        timeout_seq_[k] = timeout_next_seq_++;
      }"""

_EXIT = """
      if constexpr (detail::kTimeoutOf[fx.arg] >= 0) {
        timeout_armed_[static_cast<std::size_t>(detail::kTimeoutOf[fx.arg])] = false;
      }"""

_FINISH = """
      for (bool& armed : timeout_armed_) {
        armed = false;
      }"""

_FIELDS = """
  std::uint32_t now_ms_ = 0;
  std::uint32_t timeout_next_seq_ = 0;
  bool timeout_armed_[detail::kTimeoutCount] = {};
  std::uint32_t timeout_deadline_[detail::kTimeoutCount] = {};
  std::uint32_t timeout_seq_[detail::kTimeoutCount] = {};"""


def defer_tables(flat: FlatChart) -> list[str]:
    """``kDeferred``: per configuration, the events it defers (nothing without defer cells)."""
    if not flat.chart.deferred:
        return []
    words = max(1, (len(flat.events) + 63) // 64)
    index = {e: i for i, e in enumerate(flat.events)}
    lines = [
        "// Deferred events (the state table's defer cells): bit e of a configuration's row is",
        "// set when an active state defers event e.",
        f"inline constexpr std::size_t kDeferCapacity = {MAX_DEFERRED};",
        f"inline constexpr std::uint64_t kDeferred[kConfigurationCount][{words}] = {{",
    ]
    for c in flat.configurations:
        bits = [0] * words
        for state in c.active:
            for e in flat.chart.state(state).defer:
                if e in index:
                    bits[index[e] // 64] |= 1 << (index[e] % 64)
        lines.append("    {" + ", ".join(f"0x{b:x}u" for b in bits) + f"}},  // {c.index}")
    lines += [
        "};",
        "inline constexpr bool deferred(std::size_t configuration, std::size_t event) noexcept {",
        "  return ((kDeferred[configuration][event / 64] >> (event % 64)) & 1u) != 0;",
        "}",
        "",
    ]
    return lines


_DEFER_PUBLIC = """

  /// How many deferred events the device keeps now (at most detail::kDeferCapacity).
  std::size_t deferred_count() const noexcept { return defer_count_; }"""

_DEFER_KEEP = """
      if constexpr ((o.flags >> 2) == 1u) {  // declared ignored: kept if deferred here
        defer_keep(event);
      }"""

_DEFER_RELEASE = """
      defer_release();"""

_DEFER_PRIVATE = """
  Event defer_[detail::kDeferCapacity] = {};
  std::size_t defer_count_ = 0;
  bool defer_releasing_ = false;

  void defer_keep(std::size_t event) noexcept {
    if (detail::deferred(state_ & kConfigurationMask, event) &&
        defer_count_ < detail::kDeferCapacity) {
      defer_[defer_count_++] = static_cast<Event>(event);
    }
  }

  /// After a handled step: dispatch, in arrival order, each kept event the configuration
  /// does not defer any more (a nested call leaves it to this loop).
  void defer_release() noexcept {
    if (defer_count_ == 0 || defer_releasing_) {
      return;
    }
    defer_releasing_ = true;
    for (;;) {
      std::size_t i = 0;
      const std::size_t configuration = state_ & kConfigurationMask;
      while (i < defer_count_ &&
             detail::deferred(configuration, static_cast<std::size_t>(defer_[i]))) {
        ++i;
      }
      if (i == defer_count_) {
        break;
      }
      const Event event = defer_[i];
      for (std::size_t j = i + 1; j < defer_count_; ++j) {
        defer_[j - 1] = defer_[j];
      }
      --defer_count_;
      dispatch(event);
    }
    defer_releasing_ = false;
  }"""

#: The placeholders of the device class template (cpp_tables._DEVICE).
PLACES = (
    "@TIMER_PUBLIC@",
    "@TIMER_ENTER@",
    "@TIMER_EXIT@",
    "@TIMER_FINISH@",
    "@TIMER_FIELDS@",
    "@DEFER_KEEP@",
    "@DEFER_RELEASE@",
)


def device_parts(flat: FlatChart) -> Mapping[str, str]:
    """The device class's timeout and deferral code per placeholder; empty without them."""
    parts = dict.fromkeys(PLACES, "")
    if _timeouts(flat):
        parts.update(zip(PLACES[:5], (_PUBLIC, _ENTER, _EXIT, _FINISH, _FIELDS), strict=True))
    if flat.chart.deferred:
        parts["@TIMER_PUBLIC@"] += _DEFER_PUBLIC
        parts["@TIMER_FIELDS@"] += _DEFER_PRIVATE
        parts["@DEFER_KEEP@"] = _DEFER_KEEP
        parts["@DEFER_RELEASE@"] = _DEFER_RELEASE
    return parts
