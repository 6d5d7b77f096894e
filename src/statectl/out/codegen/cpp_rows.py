"""Dispatch cells as C++ data: the dense ``kCells`` table, or compact rows for big charts.

Rules:
1. A chart with at most :data:`DENSE_CELLS` cells (configurations x events) gets the
   dense event-major ``kCells`` table: one load per dispatch, the fast path the docs
   and ``bench/cpp_dispatch`` describe. Its size grows with the product, so a big
   chart (generated ones reach thousands of states) gets the compact form instead.
2. Compact rows: per event a default case (the commonest in the event's row) and the
   exceptions as ``(configuration, case)`` pairs sorted by configuration, found by
   binary search. Their size is events + exceptions, and a sparse chart's exceptions
   are about its transitions and declared ignores, so it grows linearly.
3. Both are built from :class:`~statectl.out.codegen.flat.Row`, never by stepping the
   kernel per cell; the dense form enumerates every cell in the order it always did,
   so small charts' output is unchanged byte for byte.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from statectl.kernel.semantics import Unhandled
from statectl.out.codegen.cpp_tables import _Tables, _width
from statectl.out.codegen.flat import FlatChart, FlatStep
from statectl.out.escape.cpp import comment as _comment

#: Cells (configurations x events) up to which the dense ``kCells`` table is written:
#: 64 Ki cells is 64 KiB of flash at one byte a cell (128 KiB at two).
DENSE_CELLS = 65536

#: Compact rows up to this many exceptions are also checked by a ``static_assert``;
#: beyond it compilers' constexpr step limits (clang: 2**20 steps) could be reached,
#: and the generator's own construction is the check.
_CHECKED_EXCEPTIONS = 65536


@dataclass(frozen=True, slots=True)
class Cells:
    """The switch's cases and the table that names one per (event, configuration)."""

    dense: bool
    cases: tuple[int, ...]  # distinct outcome/decision codes, first use
    cells: tuple[int, ...] = ()  # dense: event-major case numbers
    defaults: tuple[int, ...] = ()  # compact: each event's default case
    first: tuple[int, ...] = ()  # compact: event e's exceptions are [first[e], first[e+1])
    exceptions: tuple[tuple[int, int], ...] = ()  # compact: (configuration, case)


def build(tables: _Tables, flat: FlatChart, dense_limit: int = DENSE_CELLS) -> Cells:
    """The cells of ``flat``: dense when there are at most ``dense_limit`` (rule 1)."""
    n_configs, n_events = len(flat.configurations), len(flat.events)
    if n_configs * n_events <= dense_limit:
        return _dense(tables, flat)
    return _compact(tables, flat)


class _Cases:
    """The switch's cases: each distinct outcome/decision code numbered at first use."""

    def __init__(self) -> None:
        self.codes: list[int] = []
        self.index: dict[int, int] = {}

    def __call__(self, code: int) -> int:
        found = self.index.get(code)
        if found is None:
            found = self.index[code] = len(self.codes)
            self.codes.append(code)
        return found


def _dense(tables: _Tables, flat: FlatChart) -> Cells:
    dispatch = [[tables.code(t) for t in row] for row in flat.dispatch]
    case = _Cases()
    cells = [case(row[e]) for e in range(len(flat.events)) for row in dispatch]
    return Cells(True, tuple(case.codes), tuple(cells))


def _compact(tables: _Tables, flat: FlatChart) -> Cells:
    n_configs, n_events = len(flat.configurations), len(flat.events)
    coded: dict[Unhandled, int] = {}

    def unhandled(reason: Unhandled) -> int:  # coded at first use, as the dense form does
        if reason not in coded:
            coded[reason] = tables.code(FlatStep(False, 0, (), reason))
        return coded[reason]

    by_event: list[dict[int, int]] = [{} for _ in range(n_events)]  # configuration -> code
    for row in flat.dispatch:  # configuration-major, as the dense form numbers outcomes
        for e, tree in row.explicit.items():
            by_event[e][row.source] = tables.code(tree)
        for e in sorted(row.ignored):
            by_event[e][row.source] = unhandled(Unhandled.DECLARED_IGNORED)
    case = _Cases()
    defaults: list[int] = []
    first: list[int] = [0]
    exceptions: list[tuple[int, int]] = []
    for listed in by_event:
        counts = Counter(listed.values())
        missing = n_configs - len(listed)  # configurations with no transition for the event
        cells = listed
        if missing and (not counts or missing >= max(counts.values())):
            default = unhandled(Unhandled.NO_TRANSITION)
        else:
            default = max(counts, key=counts.__getitem__)
            if missing:  # rare: each unlisted configuration is an exception
                none = unhandled(Unhandled.NO_TRANSITION)
                cells = {c: listed.get(c, none) for c in range(n_configs)}
        defaults.append(case(default))
        exceptions += [(c, case(code)) for c, code in sorted(cells.items()) if code != default]
        first.append(len(exceptions))
    return Cells(False, tuple(case.codes), (), tuple(defaults), tuple(first), tuple(exceptions))


def dense_lines(flat: FlatChart, cells: Cells) -> list[str]:
    """``kCells`` with its comment and bound check (the dense form)."""
    n_configs = len(flat.configurations)
    ctype = "std::uint8_t" if len(cells.cases) <= 256 else "std::uint16_t"
    w = [
        "// Dispatch cells, event-major: kCells[event * kConfigurationCount + configuration] is",
        "// the case of dispatch()'s switch that runs the step (one row per event, columns are",
        "// the configurations 0.., see kActive). Cells past the table are contract faults.",
        f"inline constexpr std::size_t kCellCount = {len(cells.cells)};",
        f"inline constexpr std::size_t kCaseCount = {len(cells.cases)};",
        f"inline constexpr {ctype} kCells[{max(1, len(cells.cells))}] = {{",
    ]
    cw = _width(cells.cells)
    for e, name in enumerate(flat.events):
        row = cells.cells[e * n_configs : (e + 1) * n_configs]
        for k in range(0, len(row), 24):
            body = ", ".join(f"{x:>{cw}}" for x in row[k : k + 24])
            note = f"  // {e}: {_comment(name)}" if k == 0 else ""
            w.append(f"    {body},{note}")
    if not cells.cells:
        w.append("    0,  // unused: the chart has no events")
    w += [
        "};",
        "",
        "constexpr bool cells_name_cases() noexcept {",
        "  for (std::size_t i = 0; i < sizeof kCells / sizeof kCells[0]; ++i) {",
        "    if (kCellCount != 0 && kCells[i] >= kCaseCount) {",
        "      return false;",
        "    }",
        "  }",
        "  return true;",
        "}",
        'static_assert(cells_name_cases(), "every cell names a case of dispatch()");',
    ]
    return w


def compact_lines(flat: FlatChart, cells: Cells) -> list[str]:
    """The compact rows, their binary search and checks (rule 2)."""
    n_configs, n_events = len(flat.configurations), len(flat.events)
    w = [
        f"// Dispatch rows, compact: {n_configs} configurations x {n_events} events is more",
        f"// than the {DENSE_CELLS} cells of a dense table (docs/codegen.md). Event e runs",
        "// case kRowDefault[e] unless kRowCells[kRowFirst[e] .. kRowFirst[e + 1]) lists the",
        "// configuration (sorted by configuration, found by binary search) with its own case.",
        "struct RowCell {",
        "  std::uint16_t configuration;",
        "  std::uint16_t case_;",
        "};",
        "",
        f"inline constexpr std::size_t kCaseCount = {len(cells.cases)};",
        f"inline constexpr std::size_t kRowCellCount = {len(cells.exceptions)};",
        "inline constexpr std::uint16_t kRowDefault[kEventCount] = {",
    ]
    dw = _width(cells.defaults)
    w += [
        f"    {d:>{dw}},  // {e}: {_comment(name)}"
        for e, (d, name) in enumerate(zip(cells.defaults, flat.events, strict=True))
    ]
    w += ["};", "", "inline constexpr std::uint32_t kRowFirst[kEventCount + 1] = {"]
    fw = _width(cells.first)
    for k in range(0, len(cells.first), 16):
        w.append("    " + ", ".join(f"{x:>{fw}}" for x in cells.first[k : k + 16]) + ",")
    w += ["};", "", f"inline constexpr RowCell kRowCells[{max(1, len(cells.exceptions))}] = {{"]
    for e, name in enumerate(flat.events):
        row = cells.exceptions[cells.first[e] : cells.first[e + 1]]
        for k in range(0, len(row), 8):
            body = " ".join(f"{{{c}, {x}}}," for c, x in row[k : k + 8])
            note = f"  // {e}: {_comment(name)}" if k == 0 else ""
            w.append(f"    {body}{note}")
    if not cells.exceptions:
        w.append("    {0, 0},  // unused: no event has an exception")
    w += [
        "};",
        "",
        "/// The case of dispatch()'s switch for `event` in `configuration` (both in range).",
        "constexpr std::uint16_t cell_case(std::size_t event,",
        "                                  std::size_t configuration) noexcept {",
        "  std::size_t lo = kRowFirst[event];",
        "  std::size_t hi = kRowFirst[event + 1];",
        "  while (lo < hi) {",
        "    const std::size_t mid = lo + (hi - lo) / 2;",
        "    if (kRowCells[mid].configuration < configuration) {",
        "      lo = mid + 1;",
        "    } else if (kRowCells[mid].configuration > configuration) {",
        "      hi = mid;",
        "    } else {",
        "      return kRowCells[mid].case_;",
        "    }",
        "  }",
        "  return kRowDefault[event];",
        "}",
    ]
    if len(cells.exceptions) <= _CHECKED_EXCEPTIONS:
        w += [
            "",
            "constexpr bool rows_name_cases() noexcept {",
            "  for (std::size_t e = 0; e < kEventCount; ++e) {",
            "    if (kRowDefault[e] >= kCaseCount || kRowFirst[e] > kRowFirst[e + 1]) {",
            "      return false;",
            "    }",
            "    for (std::size_t i = kRowFirst[e]; i < kRowFirst[e + 1]; ++i) {",
            "      if (kRowCells[i].case_ >= kCaseCount || kRowCells[i].configuration >=",
            "          kConfigurationCount || (i > kRowFirst[e] &&",
            "          kRowCells[i - 1].configuration >= kRowCells[i].configuration)) {",
            "        return false;",
            "      }",
            "    }",
            "  }",
            "  return kRowFirst[kEventCount] == kRowCellCount;",
            "}",
            'static_assert(rows_name_cases(), "rows are sorted and name cases of dispatch()");',
        ]
    return w
