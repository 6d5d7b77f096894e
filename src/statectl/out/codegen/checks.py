"""What :func:`~statectl.out.codegen.flatten.flatten` checks before exploring: executable
content the generated code cannot perform (G701, G708, G709) and the integer context
fields (G704). Split from the explorer because these checks read the chart only.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.expr import compile_expression
from statectl.kernel.model import (
    Action,
    Assign,
    Chart,
    Log,
    Notify,
    Raise,
)
from statectl.out.codegen.cpp_names import identifiers
from statectl.out.codegen.flat import ContextField

# -- checks before exploring -------------------------------------------------------------------


def _walk_actions(actions: Iterable[Action]) -> Iterable[Action]:
    for a in actions:
        yield a
        inner = getattr(a, "actions", None)
        if isinstance(inner, tuple):
            yield from _walk_actions(inner)


def _check_actions(chart: Chart, where: Location, diags: list[Diagnostic]) -> None:
    numbers = {i.number for i in chart.invokes}
    blocks: list[tuple[str, Location, tuple[Action, ...]]] = []
    for s in chart.states:
        at = s.origin
        blocks += [
            (f"onentry of state {s.name!r}", at, s.on_entry),
            (f"onexit of state {s.name!r}", at, s.on_exit),
            (f"initial content of state {s.name!r}", at, s.initial_actions),
            (f"history content of state {s.name!r}", at, s.history_actions),
        ]
        if s.invokes:
            diags.append(
                Diagnostic(
                    "G701",
                    Severity.ERROR,
                    s.invokes[0].origin if s.invokes else at,
                    f"state {s.name!r} has <invoke>, which generated code cannot start",
                    "model the child session as its own device",
                )
            )
    for t in chart.transitions:
        blocks.append((f"transition {t.source} + {t.label}", t.origin, t.actions))
    blocks.append(("top-level <script>", where, chart.script))
    for what, at, actions in blocks:
        for a in actions:
            if isinstance(a, Raise) or (isinstance(a, Assign) and a.expr is not None):
                continue  # an assignment is checked as it is translated (codegen.assign)
            if isinstance(a, Notify):
                if a.invoke not in numbers:
                    diags.append(
                        Diagnostic(
                            "G709",
                            Severity.ERROR,
                            at,
                            f"{what} notifies invoke #{a.invoke} ({a.name}), which the chart "
                            "does not declare",
                            "declare the invoke (an API in the Event Definition table)",
                        )
                    )
                continue
            if isinstance(a, Log):
                diags.append(
                    Diagnostic(
                        "G708",
                        Severity.WARNING,
                        a.origin if a.origin.line else at,
                        f"{what} has a Log action ({a.label!r}); generated code skips it, "
                        "as the Python Subject does",
                        "use a trace hook in C++ to log",
                    )
                )
                continue
            origin = getattr(a, "origin", None)
            diags.append(
                Diagnostic(
                    "G701",
                    Severity.ERROR,
                    origin if isinstance(origin, Location) and origin.line else at,
                    f"{what} has a {type(a).__name__} action, which generated C++ cannot perform",
                    "keep executable content to Notify and Raise for a C++ target",
                )
            )


def _context(chart: Chart, diags: list[Diagnostic]) -> tuple[dict[str, Any], list[ContextField]]:
    """The chart's data items evaluated in order, as the Python Subject does."""
    values: dict[str, Any] = {}
    for item in chart.data:
        value: Any = None
        if item.expr:
            expr, problems = compile_expression(item.expr, item.origin, what="data")
            if expr is None:
                diags.extend(problems)
                continue
            try:
                value = expr.evaluate(values)
            except Exception as exc:  # reported, not raised: bad input never gives a traceback
                diags.append(
                    Diagnostic(
                        "G704",
                        Severity.ERROR,
                        item.origin,
                        f"data item {item.name!r} = {item.expr!r} fails: {exc}",
                        "give it an integer literal",
                    )
                )
                continue
        values[item.name] = value
    fields: list[ContextField] = []
    idents = identifiers([n for n, v in values.items() if _is_int(v)], lower=True)
    for name, value in values.items():
        if _is_int(value):
            fields.append(ContextField(name, idents[name], int(value)))
    return values, fields


def _is_int(value: object) -> bool:
    return isinstance(value, int) and -(2**63) <= int(value) < 2**63
