"""The composed cell as a Promela model, for an independent check with SPIN.

Rules:
1. The export is the explorer's own composed model: each device is a variable
   over its numbered local states (the kernel decided every row of the table),
   so SPIN checks the same transition system, not a second reading of the charts.
2. One ``do`` option per stimulus, one ``d_step`` (``atomic`` when the model
   has free choices, which ``d_step`` would resolve deterministically): its guard is the set of
   local states where it happens (and its ``when``); its body is the device's
   outcome table, then the link queue drained first in, first out, then every
   invariant asserted. Free choices are nondeterministic ``if`` options.
3. A link event delivered to a state that neither handles nor ignores it fails
   an assertion, as does one whose guard raises there (a guard error; one on an
   environment stimulus or a completion is not exported); a global state with no
   enabled option is an invalid end state (SPIN's deadlock), matching rule 3 of
   :mod:`statectl.cell.explore.search`.
4. Each option prints ``statectl-step`` so the length of a SPIN trail counts
   stimuli, comparable with statectl's traces. Recovery (a branching-time
   property) and link livelock are not exported.
"""

from __future__ import annotations

import ast

from statectl.cell.explore.compose import Composed
from statectl.cell.explore.conditions import foreign_leaf
from statectl.cell.explore.local import Reaction
from statectl.cell.model import GlobalExpr
from statectl.kernel.semantics import Unhandled

__all__ = ["STEP_MARK", "export_promela"]

STEP_MARK = "statectl-step"


def _ident(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name)


class _Writer:
    def __init__(self, model: Composed) -> None:
        self.m = model
        self.var = tuple(f"l_{_ident(n)}" for n in model.names)
        # one code per target, event and the data the link sends (which may decide guards)
        pairs: dict[tuple[int, str, str | None, bool], int] = {}
        self.via: dict[int, int] = {}  # code -> a link sending it (its data filters outcomes)
        self.link_code: list[int] = []
        for i, k in enumerate(model.links):
            data = None if k.forward_data else repr(k.data)
            key = (model.position[k.target], k.event, data, k.ignore_if_unhandled)
            code = pairs.setdefault(key, len(pairs))
            self.via.setdefault(code, i)
            self.link_code.append(code)
        self.code = pairs

    def expr(self, e: GlobalExpr) -> str:
        return self._node(ast.parse(e.source, mode="eval").body)

    def _node(self, node: ast.expr) -> str:
        if isinstance(node, ast.BoolOp):
            op = " && " if isinstance(node.op, ast.And) else " || "
            return "(" + op.join(self._node(v) for v in node.values) + ")"
        if isinstance(node, ast.UnaryOp):
            return "!" + self._node(node.operand)
        if isinstance(node, ast.Constant):
            return "true" if node.value else "false"
        assert isinstance(node, ast.Call) and isinstance(node.args[0], ast.Constant)
        device, _, state = str(node.args[0].value).partition(".")
        d = self.m.position[device]
        table = self.m.spaces[d].states_in(state)
        return self._in(d, [i for i, v in enumerate(table) if v])

    def happens(self, d: int, event: str, lids: list[int], link: int = -1) -> str:
        """Where ``event`` happens: the local states, each with the other devices' states
        its handled outcomes need (explore/conditions.py rule 1)."""
        free: list[int] = []
        parts: list[str] = []
        for lid in lids:
            conds = [self.condition(o) for o in self.m.outcomes(d, lid, event, link) if o.happens]
            if all(conds):
                parts.append(f"({self.var[d]} == {lid} && ({' || '.join(conds)}))")
            else:
                free.append(lid)
        if free:
            parts.insert(0, self._in(d, free))
        return "(" + " || ".join(parts) + ")" if len(parts) > 1 else parts[0]

    def _in(self, d: int, lids: list[int]) -> str:
        if not lids:
            return "false"
        return "(" + " || ".join(f"{self.var[d]} == {i}" for i in lids) + ")"

    def condition(self, o: Reaction) -> str:
        """Another device's state the outcome's guard read (explore/conditions.py rule 1)."""
        parts = []
        for leaf, value in o.choices:
            ref = foreign_leaf(leaf)
            if ref is None or ref[0] not in self.m.position:
                continue
            d = self.m.position[ref[0]]
            table = self.m.spaces[d].states_in(ref[1])
            test = self._in(d, [i for i, v in enumerate(table) if v])
            parts.append(test if value else f"!{test}")
        return " && ".join(parts)

    def outcome(self, d: int, o: Reaction, indent: str) -> list[str]:
        lines = [f"{indent}{self.var[d]} = {o.target};"]
        for i in self.m.fires(d, o):
            k = self.m.links[i]
            code = self.link_code[i]
            guard = self.expr(k.guard) if k.guard else "true"
            lines.append(
                f"{indent}if :: {guard} -> pend!{code} :: else -> skip fi; /* {k.label} */"
            )
        return lines

    def table(
        self, d: int, event: str, indent: str, only_handled: bool, link: int = -1
    ) -> list[str]:
        space = self.m.spaces[d]
        lines = [f"{indent}if"]
        for lid in range(len(space.snapshots)):
            outs = self.m.outcomes(d, lid, event, link)
            if only_handled:
                outs = tuple(o for o in outs if o.happens)
            if not outs or all(o.unhandled is Unhandled.DECLARED_IGNORED for o in outs):
                continue
            lines.append(f"{indent}:: {self.var[d]} == {lid} -> /* {space.state_of(lid)} */")
            lines.append(f"{indent}   if")
            for o in outs:
                cond = self.condition(o)
                when = f"{cond} -> " if cond else ""
                if o.happens:
                    body = self.outcome(d, o, indent + "      ")
                    body[0] = f"{indent}   :: {when}" + body[0].lstrip()
                    lines.extend(body)
                elif o.unhandled is Unhandled.GUARD_ERROR:
                    lines.append(
                        f'{indent}   :: {when}printf("guard error: {self.m.names[d]} in '
                        f'{space.state_of(lid)} gets {event}\\n"); assert(false)'
                    )
                elif o.unhandled is Unhandled.NO_TRANSITION and not (
                    link >= 0 and self.m.harmless[link]
                ):
                    lines.append(
                        f'{indent}   :: {when}printf("unhandled: {self.m.names[d]} in '
                        f'{space.state_of(lid)} gets {event}\\n"); assert(false)'
                    )
                else:
                    lines.append(f"{indent}   :: {when}skip")
            if any(self.condition(o) for o in outs):
                lines.append(
                    f"{indent}   :: else -> skip /* another device's state rules out the rest */"
                )
            lines.append(f"{indent}   fi")
        lines.append(f"{indent}:: else -> skip")
        lines.append(f"{indent}fi")
        return lines


def export_promela(model: Composed, *, invariants: bool = True, unhandled: bool = True) -> str:
    """The Promela text of ``model`` (rules 1-4)."""
    w = _Writer(model)
    out = [
        *_declarations(w, model),
        *_drain(w, model, unhandled),
        *_check(w, model, invariants),
        *_process(w, model),
    ]
    return "\n".join(out) + "\n"


def _declarations(w: _Writer, m: Composed) -> list[str]:
    """The header and the globals: one variable per device, the pending-delivery channel."""
    out = [
        f"/* cell {m.cell.name}: composed by statectl for SPIN (statectl verify "
        "--export promela) */"
    ]
    if m.distributed or m.dropped:
        out.append(
            "/* not exported: lossy, delayed and dropped link events (statectl verify explores "
            "them; docs/cells.md) */"
        )
    for d, space in enumerate(m.spaces):
        states = ", ".join(f"{i}={space.state_of(i)}" for i in range(len(space.snapshots)))
        kind = "byte" if len(space.snapshots) <= 256 else "short"
        out.append(f"{kind} {w.var[d]}; /* {m.names[d]}: {states} */")
    capacity = max(4, 4 * len(m.links))
    out.append(f"chan pend = [{capacity}] of {{ byte }}; /* queued link deliveries */")
    out.append("byte code;")
    out.append("")
    return out


def _drain(w: _Writer, m: Composed, unhandled: bool) -> list[str]:
    """``drain()``: deliver the queued link events, each by its target's table (rule 2)."""
    out: list[str] = []
    out.append("inline drain() {")
    out.append("  do")
    out.append("  :: nempty(pend) -> pend?code;")
    out.append("     if")
    for (t, event, _data, _harmless), c in w.code.items():
        out.append(f"     :: code == {c} -> /* {m.names[t]}.{event} */")
        link = w.via[c]
        out.extend(w.table(t, event, "        ", only_handled=not unhandled, link=link))
    out.append("     :: else -> skip")
    out.append("     fi")
    out.append("  :: empty(pend) -> break")
    out.append("  od;")
    out.append("  code = 0 /* so equal device states are one SPIN state */")
    out.append("}")
    out.append("")
    return out


def _check(w: _Writer, m: Composed, invariants: bool) -> list[str]:
    """``check()``: the invariants as asserts, run after every stimulus."""
    out: list[str] = []
    checks = (
        [f"  assert({w.expr(inv.expr)}); /* invariant {inv.name} */" for inv in m.cell.invariants]
        if invariants
        else []
    )
    out.append("inline check() {")
    out.extend(checks or ["  skip"])
    out.append("}")
    out.append("")
    return out


def _process(w: _Writer, m: Composed) -> list[str]:
    """The cell process: pick an initial state, then loop over the stimuli (rule 3)."""
    out: list[str] = []
    out.append("active proctype cell() {")
    out.append("  atomic {")
    out.append("    if")
    for g in m.initial:
        sets = "; ".join(f"{w.var[d]} = {lid}" for d, lid in enumerate(m.decode(g)))
        out.append(f"    :: {sets}")
    out.append("    fi;")
    out.append("    check()")
    out.append("  };")
    # one indivisible transition per stimulus, so SPIN's depth counts stimuli; free
    # choices need atomic (d_step would resolve them deterministically)
    block = "atomic" if any(sp.free_guards for sp in m.spaces) else "d_step"
    out.append("  do")
    for i, s in enumerate(m.stimuli):
        d = s.device
        space = m.spaces[d]
        lids = [
            lid
            for lid in range(len(space.snapshots))
            if m.enabled_locally(s, lid)
            and any(o.happens for o in m.outcomes(d, lid, s.event, m.via(s)))
        ]
        if not lids:
            continue
        guard = w.happens(d, s.event, lids, m.via(s))
        if s.when >= 0:
            when = m.cell.environment[s.when].when
            if when is not None:
                guard = f"{guard} && {w.expr(when)}"
        out.append(f"  :: {block} {{ {guard} -> /* {s.label(m.names)} */")
        out.append(f'       printf("{STEP_MARK} {i}\\n");')
        out.extend(w.table(d, s.event, "       ", only_handled=True, link=m.via(s)))
        out.append("       drain();")
        out.append("       check()")
        out.append("     }")
    out.append("  od")
    out.append("}")
    return out
