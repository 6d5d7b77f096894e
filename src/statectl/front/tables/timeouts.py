"""The ``timeout``, ``defer`` and ``ignore: all others`` cells of the State Definition table.

Rules:
1. A ``timeout`` cell reads ``DURATION -> EVENT``: a positive number with a unit
   (``ms``, ``s`` or ``min``; ``5s``, ``2.5 s``, ``250ms``, ``1 min``), an arrow
   (``->`` or ``→``) and the event the state raises when it has been active that
   long. Durations are whole milliseconds from 1 ms to :data:`MAX_TIMEOUT_MS`, so
   every host (Python, generated C++ with a ``uint32_t`` millisecond tick) counts
   the same; anything else is T118 at the cell.
2. ``defer`` is a list cell like ``ignore`` (event names, commas between them).
3. An ``ignore`` item spelled ``all others`` (any case; also ``*``) stands for every
   declared event the state does not handle itself: the build expands it.
"""

from __future__ import annotations

import math
import re

from statectl.front.tables.rows import Bad, DeviceTables, RawRow, diag
from statectl.kernel.errors import Diagnostic, Location
from statectl.kernel.model import Timeout

__all__ = [
    "ALL_OTHERS",
    "MAX_TIMEOUT_MS",
    "format_timeout",
    "is_all_others",
    "parse_timeout",
    "timeout_cell",
]

#: Longest timeout: what a ``uint32_t`` millisecond count holds with room to add (~24.8 days).
MAX_TIMEOUT_MS = 2**31 - 1
#: How writers spell the ``ignore`` item that stands for every other event.
ALL_OTHERS = "all others"

_UNITS = {"ms": 0.001, "s": 1.0, "sec": 1.0, "min": 60.0}
_FORM = re.compile(
    r"^\s*(?P<n>[0-9]+(?:\.[0-9]+)?)\s*(?P<unit>[a-z]+)\s*(?:->|→)\s*(?P<event>\S.*?)\s*$",
    re.IGNORECASE,
)
_HINT = "write DURATION -> EVENT, e.g. '5s -> Move timeout' (units: ms, s, min)"


def parse_timeout(text: str) -> tuple[float, str] | str:
    """``(seconds, event)`` of a ``timeout`` cell, or what is wrong with it."""
    m = _FORM.match(text)
    if m is None:
        return f"timeout {text!r} is not DURATION -> EVENT"
    scale = _UNITS.get(m["unit"].lower())
    if scale is None:
        return f"timeout {text!r}: unknown unit {m['unit']!r}"
    event = m["event"]
    if "," in event:
        return f"timeout {text!r}: the event name {event!r} contains a comma"
    ms = float(m["n"]) * scale * 1000.0
    if not math.isfinite(ms) or ms < 1 or ms > MAX_TIMEOUT_MS:
        return f"timeout {text!r}: the duration must be from 1 ms to {MAX_TIMEOUT_MS} ms"
    if abs(ms - round(ms)) > 1e-6:
        return f"timeout {text!r}: the duration must be a whole number of milliseconds"
    return round(ms) / 1000.0, event


def format_timeout(seconds: float, event: str) -> str:
    """The cell text that :func:`parse_timeout` reads back as ``(seconds, event)``."""
    return f"{Timeout(seconds, event).duration} -> {event}"


def is_all_others(item: str) -> bool:
    """Whether an ``ignore`` item is the ``all others`` form (rule 3)."""
    return item == "*" or " ".join(item.lower().split()) == ALL_OTHERS


def timeout_cell(row: RawRow, diags: list[Diagnostic]) -> str:
    """The row's ``timeout`` text, checked (T118 at the cell; T108 for a list or non-text)."""
    got = row.cells.get("timeout")
    if got is None:
        return ""
    value, where = got
    if isinstance(value, Bad | tuple):
        found = value.found if isinstance(value, Bad) else "a list"
        diags.append(diag("T108", where, f"'timeout' must be text (got {found})", _HINT))
        return ""
    text = value.strip()
    if text:
        problem = parse_timeout(text)
        if isinstance(problem, str):
            diags.append(diag("T118", where, problem, _HINT))
            return ""
    return text


def where_of(row: RawRow, column: str) -> Location:
    """The cell's location, else the row's."""
    got = row.cells.get(column)
    return got[1] if got is not None else row.where


def optional_state_columns(tables: DeviceTables) -> tuple[str, ...]:
    """``timeout`` and ``defer`` for writers, each only when some row uses it."""
    out: tuple[str, ...] = ()
    if any(s.timeout for s in tables.states):
        out += ("timeout",)
    if any(s.defer for s in tables.states):
        out += ("defer",)
    return out
