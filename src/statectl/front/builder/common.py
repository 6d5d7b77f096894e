"""What the forward build and its inverse share: the B2xx codes, limits, diagnostics,
did-you-mean hints and guard compilation. Its own module so the state, event, chart and
inverse modules of :mod:`statectl.front.builder` import one place, not one another.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence

from statectl.kernel.codes import family
from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.expr import Expression, compile_expression

#: Names a guard may read besides the device's data.
GUARD_NAMES = frozenset({"previous", "_event"})

#: Deepest state hierarchy a device file may build (B218; docs/limits.md).
MAX_STATE_DEPTH = 100

#: Code -> one-line summary of every B2xx code (a view of statectl.kernel.codes.REGISTRY).
CODES: Mapping[str, str] = family("B2")


def _compile(guard: str, where: Location) -> tuple[Expression | None, list[Diagnostic]]:
    """``compile_expression``, with a guard nested too deeply to compile as X301."""
    try:
        return compile_expression(guard, where)
    except (RecursionError, MemoryError):
        shown = guard if len(guard) <= 40 else guard[:37] + "..."
        return None, [
            _d(
                "X301",
                Severity.ERROR,
                where,
                f"guard {shown!r} is nested too deeply to analyse",
                "write it with fewer nested parts; see docs/limits.md",
            )
        ]


def _d(code: str, severity: Severity, where: Location, message: str, hint: str = "") -> Diagnostic:
    return Diagnostic(code, severity, where, message, hint)


def _rows_text(places: Sequence[Location]) -> str:
    return ", ".join(str(p) for p in places)


#: Names a hint lists at most, and candidates a did-you-mean compares at most: a file
#: with thousands of wrong names gets thousands of short hints, found in linear time.
_HINT_LISTED = 20
_HINT_SEARCHED = 200


def _listed(names: Sequence[str]) -> str:
    shown = ", ".join(names[:_HINT_LISTED])
    return shown + (f" and {len(names) - _HINT_LISTED} more" if len(names) > _HINT_LISTED else "")


def _hint(word: str, choices: Sequence[str]) -> str:
    names = list(choices)
    if len(names) > _HINT_SEARCHED:  # the likeliest: same first letter, similar length
        near = [n for n in names if n[:1] == word[:1] and abs(len(n) - len(word)) <= 2]
        names_searched = near[:_HINT_SEARCHED]
    else:
        names_searched = names
    close = difflib.get_close_matches(word, names_searched, n=1, cutoff=0.6)
    known = "known: " + _listed(names)
    return f"did you mean {close[0]!r}? {known}" if close else known


def _unique(items: Sequence[str]) -> list[str]:
    return list(dict.fromkeys(i for i in items if i))


def _literal(value: object) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return f"float({str(value)!r})"
    return repr(value)
