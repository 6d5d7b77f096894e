"""C420, C421: a guard names only states and events its device has.

A guard that reads ``In('Clsed')`` or ``previous == 'Clsed'`` is simply false at run
time, so the device ignores the event as "guard false" and nobody is told; the same
for ``_event.name == 'Strat'``. These rules name the row instead.

Rules:
1. C420 (error): a guard's ``In('NAME')`` names no state of the device. A dotted
   name (``In('arm.Moving')``) reads another device of a cell and is the cell's to
   check (V831).
2. C420 (error): ``previous`` compared (``==``, ``!=``, ``in``, ``not in``) with a
   text, or texts, that name no state of the device.
3. C421 (error): ``_event.name`` compared the same way with a name the device has
   no event for (SCXML's ``done.*`` and ``error.*`` events are the kernel's own).
4. Each message says "did you mean" with the closest name, when one is close.
Kept in its own module, apart from the structural rules, so each can change alone.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Iterator

from statectl.kernel.errors import Diagnostic, Severity, did_you_mean
from statectl.kernel.model import Chart, Transition

__all__ = ["check_guard_names"]


def _texts(node: ast.expr) -> list[str]:
    """The text constants ``node`` is, or holds (a tuple, list or set of them)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, ast.Tuple | ast.List | ast.Set):
        return [t for e in node.elts for t in _texts(e)]
    return []


def _is_previous(node: ast.expr) -> bool:
    return isinstance(node, ast.Name) and node.id == "previous"


def _is_event_name(node: ast.expr) -> bool:
    if isinstance(node, ast.Attribute):
        return (
            node.attr == "name" and isinstance(node.value, ast.Name) and node.value.id == "_event"
        )
    if isinstance(node, ast.Subscript):
        key = node.slice
        return (
            isinstance(node.value, ast.Name)
            and node.value.id == "_event"
            and isinstance(key, ast.Constant)
            and key.value == "name"
        )
    return False


def _named(tree: ast.AST) -> Iterator[tuple[str, str]]:
    """("state" | "event", name) for each name the guard compares or tests with In()."""
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id == "In"
            and len(node.args) == 1
        ):
            for name in _texts(node.args[0]):
                yield ("in", name)
        elif isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            for kind, test in (("state", _is_previous), ("event", _is_event_name)):
                if any(test(o) for o in operands):
                    for o in operands:
                        if not test(o):
                            yield from ((kind, name) for name in _texts(o))


@functools.lru_cache(maxsize=4096)
def _names_in(guard: str) -> tuple[tuple[str, str], ...]:
    """:func:`_named` of a guard's text, parsed once however many rows repeat it."""
    try:
        tree = ast.parse(guard.strip(), mode="eval")
    except SyntaxError:
        return ()  # the builder reports a guard that does not parse (X3xx)
    return tuple(dict.fromkeys(_named(tree)))


def _problem(chart: Chart, t: Transition, kind: str, name: str) -> Diagnostic | None:
    # the lists for the message are made only for a problem: a check per name stays O(1)
    if kind == "in":
        if chart.has_state(name) or "." in name:
            return None
        states = [s.name for s in chart.states]
        return Diagnostic(
            "C420",
            Severity.ERROR,
            t.origin,
            f"guard [{t.guard}] tests In({name!r}), but {chart.name} has no state {name!r} "
            "(the test is always false)",
            did_you_mean(name, states) + "states: " + ", ".join(states),
        )
    if kind == "state":
        if chart.has_state(name):
            return None
        states = [s.name for s in chart.states]
        return Diagnostic(
            "C420",
            Severity.ERROR,
            t.origin,
            f"guard [{t.guard}] compares previous with {name!r}, but {chart.name} has no "
            f"state {name!r}",
            did_you_mean(name, states) + "states: " + ", ".join(states),
        )
    if chart.event(name) is not None or name.startswith(("done.", "error.")):
        return None
    events = list(chart.event_names)
    return Diagnostic(
        "C421",
        Severity.ERROR,
        t.origin,
        f"guard [{t.guard}] compares _event.name with {name!r}, but {chart.name} has no "
        f"event {name!r}",
        did_you_mean(name, events) + "events: " + ", ".join(events),
    )


def check_guard_names(chart: Chart) -> Iterator[Diagnostic]:
    """Rules 1-4 over every guard of ``chart``, once per row and name."""
    for t in chart.transitions:
        if not t.guard:
            continue
        for kind, name in _names_in(t.guard):
            found = _problem(chart, t, kind, name)
            if found is not None:
                yield found
