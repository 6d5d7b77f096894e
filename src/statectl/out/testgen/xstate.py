"""Export a chart as an XState (v5) machine config, for ``@xstate/graph`` users.

Rules:
1. Every state keeps its name as its key and as its ``id``; targets are
   ``#name``, so they resolve wherever the state sits in the hierarchy.
2. Kinds map one to one: compound (``initial``), ``parallel``, ``final``,
   ``history`` (``shallow``/``deep``, with its default as ``target``).
3. A row is an entry of ``on`` (``always`` when eventless; ``onDone`` for
   ``done.state.<its own state>``), in table order; its guard is a named guard
   whose name is the expression text (XState calls the implementation the user
   gives under that name); its notifications are named actions, the observer
   methods, so a path lists the device API it drives.
4. What XState has no place for is kept in ``meta``: the row's file:line and
   prose condition, the events a state declares ignored, the invoke numbers.
5. A row whose targets are its own source or inside it re-enters the source
   (SCXML exits and enters it again, its entry notifications included) where
   XState v5 would not: it is marked ``reenter: true``; an internal row
   ``reenter: false``.
"""

from __future__ import annotations

import json
from typing import Any

from statectl.kernel.model import Chart, Notify, State, StateKind, Transition
from statectl.out.testgen.cases import where

__all__ = ["xstate_config"]


def _within(chart: Chart, state: str, source: str) -> bool:
    """Whether ``state`` is ``source`` or one of its descendants (rule 5)."""
    at: str | None = state
    while at is not None:
        if at == source:
            return True
        at = chart.state(at).parent if chart.has_state(at) else None
    return False


def _transition(chart: Chart, t: Transition) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if t.targets:
        out["target"] = [f"#{x}" for x in t.targets] if len(t.targets) > 1 else f"#{t.targets[0]}"
    if t.guard:
        out["guard"] = t.guard
    methods = [a.method for a in t.actions if isinstance(a, Notify)]
    if methods:
        out["actions"] = methods
    if t.internal:
        out["reenter"] = False
    elif t.targets and all(_within(chart, x, t.source) for x in t.targets):
        out["reenter"] = True  # SCXML leaves and enters the source again
    meta: dict[str, Any] = {"row": where(t)}
    if t.condition:
        meta["condition"] = t.condition
    invokes = [a.invoke for a in t.actions if isinstance(a, Notify)]
    if invokes:
        meta["invokes"] = invokes
    out["meta"] = meta
    return out


def _state(chart: Chart, s: State, ignored: dict[str, list[str]]) -> dict[str, Any]:
    node: dict[str, Any] = {"id": s.name}
    if s.kind is StateKind.PARALLEL:
        node["type"] = "parallel"
    elif s.kind is StateKind.FINAL:
        node["type"] = "final"
    elif s.kind.is_history:
        node["type"] = "history"
        node["history"] = "deep" if s.kind is StateKind.HISTORY_DEEP else "shallow"
        if s.history_default:
            node["target"] = f"#{s.history_default[0]}"
        return node
    children = list(chart.children(s.name))
    if children:
        if s.kind is StateKind.COMPOUND:
            first = [c.name for c in children if not c.kind.is_history][:1]
            node["initial"] = s.initial[0] if s.initial else first[0]
        node["states"] = {c.name: _state(chart, c, ignored) for c in children}
    on: dict[str, list[dict[str, Any]]] = {}
    for t in chart.transitions_from(s.name):
        if not t.events:
            node.setdefault("always", []).append(_transition(chart, t))
            continue
        for e in t.events:
            if e == f"done.state.{s.name}":
                node.setdefault("onDone", []).append(_transition(chart, t))
            else:
                on.setdefault(e, []).append(_transition(chart, t))
    if on:
        node["on"] = on
    meta: dict[str, Any] = {}
    if s.description:
        meta["description"] = s.description
    if ignored.get(s.name):
        meta["ignores"] = ignored[s.name]
    if meta:
        node["meta"] = meta
    return node


def xstate_config(chart: Chart) -> str:
    """The machine config as JSON (rules 1-4)."""
    ignored: dict[str, list[str]] = {}
    for state, event in sorted(chart.ignored):
        ignored.setdefault(state, []).append(event)
    top = list(chart.children(None))
    first = [s.name for s in top if not s.kind.is_history][:1]
    config: dict[str, Any] = {
        "id": chart.name,
        "initial": chart.initial[0] if chart.initial else first[0],
        "states": {s.name: _state(chart, s, ignored) for s in top},
    }
    return json.dumps(config, indent=2, ensure_ascii=False) + "\n"
