"""Write a :class:`~statectl.kernel.model.Chart` as an SCXML document.

Rules:
1. States nest as in the chart; document order is kept, so reading the output
   back gives the same states, transitions and content (only locations change).
2. Everything SCXML has a word for is written as SCXML; the device-table facts
   it has none for (``Notify``, the paper's controls, description, component)
   go into attributes and elements of the ``statectl`` namespace, which other
   SCXML processors ignore and :mod:`statectl.out.scxml.reader` reads back.
3. Generated state ids (``_state3``) are left out, so they are generated again.
4. Device charts keep everything the tables gave them: the event declarations
   (kind, API, description), the observer APIs and invoke numbers, each state's
   ignored events and the chart's component, as ``statectl`` elements. An event
   name SCXML cannot hold (one with spaces: "Movement completion") is written with
   ``_`` for the spaces in ``event`` and exactly in ``statectl:event-name``.
5. Transitions nest in their source state; when the chart lists them in another
   order (a device table's row order), each carries its place as ``statectl:row``
   so the reader restores the chart's order.
"""

from __future__ import annotations

from statectl.kernel.model import (
    Action,
    Assign,
    Block,
    Cancel,
    Chart,
    ChildInvoke,
    Content,
    DataItem,
    Foreach,
    If,
    Log,
    Notify,
    Param,
    Raise,
    Script,
    Send,
    State,
    StateKind,
    Transition,
)
from statectl.out.escape.xml import attribute as quoteattr
from statectl.out.escape.xml import text as escape
from statectl.out.scxml.timeouts import timeout_lines
from statectl.out.scxml.xmltree import SCXML_NS, STATECTL_NS

__all__ = ["write_scxml"]

_TAG = {
    StateKind.ATOMIC: "state",
    StateKind.COMPOUND: "state",
    StateKind.PARALLEL: "parallel",
    StateKind.FINAL: "final",
    StateKind.HISTORY_SHALLOW: "history",
    StateKind.HISTORY_DEEP: "history",
}


def _attrs(**values: str | None) -> str:
    return "".join(
        f" {k.rstrip('_').replace('__', ':').replace('_', '-')}={quoteattr(v)}"
        for k, v in values.items()
        if v is not None
    )


def scxml_event(name: str) -> str:
    """An event name as one SCXML event token: whitespace runs become ``_``."""
    return "_".join(name.split())


class _Writer:
    def __init__(self, chart: Chart) -> None:
        self.chart = chart
        self.lines: list[str] = []
        self.by_source: dict[str, list[tuple[int, Transition]]] = {}
        for index, t in enumerate(chart.transitions):
            self.by_source.setdefault(t.source, []).append((index, t))
        in_document = [i for s in chart.states for i, _ in self.by_source.get(s.name, [])]
        #: the chart lists transitions in another order than the states nest them (rule 5)
        self.reordered = in_document != list(range(len(chart.transitions)))

    def emit(self, depth: int, text: str) -> None:
        self.lines.append("  " * depth + text)

    def element(self, depth: int, open_tag: str, body: list[str] | None = None) -> None:
        name = open_tag.split(" ", 1)[0]
        if not body:
            self.emit(depth, f"<{open_tag}/>")
            return
        self.emit(depth, f"<{open_tag}>")
        self.lines.extend(body)
        self.emit(depth, f"</{name}>")

    def sub(self, fn: object, *args: object) -> list[str]:
        """Collect the lines ``fn`` emits (for an element's children)."""
        saved, self.lines = self.lines, []
        fn(*args)  # type: ignore[operator]
        out, self.lines = self.lines, saved
        return out

    # -- content ---------------------------------------------------------------------------------

    def params(self, depth: int, params: tuple[Param, ...]) -> None:
        for p in params:
            self.emit(depth, f"<param{_attrs(name=p.name, expr=p.expr, location=p.location)}/>")

    def content(self, depth: int, c: Content | None) -> None:
        if c is None:
            return
        if c.expr is not None:
            self.emit(depth, f"<content{_attrs(expr=c.expr)}/>")
        elif c.body is not None and c.body.lstrip().startswith("<"):
            self.emit(depth, f"<content>{c.body}</content>")
        else:
            self.emit(depth, f"<content>{escape(c.body or '')}</content>")

    def actions(self, depth: int, actions: tuple[Action, ...]) -> None:
        for a in actions:
            self.action(depth, a)

    def action(self, depth: int, a: Action) -> None:
        if isinstance(a, Raise):
            self.emit(depth, f"<raise{_attrs(event=a.event)}/>")
        elif isinstance(a, Log):
            attrs = _attrs(label=a.label or None, expr=a.expr, statectl__message=a.message or None)
            self.emit(depth, f"<log{attrs}/>")
        elif isinstance(a, Notify):
            attrs = _attrs(invoke=str(a.invoke), name=a.name, method=a.method, event=a.event)
            self.emit(depth, f"<statectl:notify{attrs}/>")
        elif isinstance(a, Assign):
            if a.expr is not None or a.body is None:
                self.emit(depth, f"<assign{_attrs(location=a.location, expr=a.expr)}/>")
            else:
                self.emit(depth, f"<assign{_attrs(location=a.location)}>{escape(a.body)}</assign>")
        elif isinstance(a, Script):
            self.emit(depth, f"<script>{escape(a.source)}</script>")
        elif isinstance(a, If):
            self.if_(depth, a)
        elif isinstance(a, Foreach):
            attrs = _attrs(array=a.array, item=a.item, index=a.index)
            self.element(depth, f"foreach{attrs}", self.sub(self.actions, depth + 1, a.actions))
        elif isinstance(a, Send):
            self.send(depth, a)
        elif isinstance(a, Cancel):
            self.emit(depth, f"<cancel{_attrs(sendid=a.sendid, sendidexpr=a.sendidexpr)}/>")
        elif isinstance(a, Block):
            self.actions(depth, a.actions)

    def if_(self, depth: int, a: If) -> None:
        (cond, first), *rest = a.branches
        body = self.sub(self.actions, depth + 1, first)
        for c, branch in rest:
            tag = f"<elseif{_attrs(cond=c)}/>" if c is not None else "<else/>"
            body.append("  " * (depth + 1) + tag)
            body.extend(self.sub(self.actions, depth + 1, branch))
        self.emit(depth, f"<if{_attrs(cond=cond)}>")
        self.lines.extend(body)
        self.emit(depth, "</if>")

    def send(self, depth: int, a: Send) -> None:
        attrs = _attrs(
            event=a.event,
            eventexpr=a.eventexpr,
            target=a.target,
            targetexpr=a.targetexpr,
            type=a.type,
            typeexpr=a.typeexpr,
            id=a.id,
            idlocation=a.idlocation,
            delay=a.delay,
            delayexpr=a.delayexpr,
            namelist=" ".join(a.namelist) or None,
        )
        body = self.sub(self.params, depth + 1, a.params)
        body += self.sub(self.content, depth + 1, a.content)
        self.element(depth, "send" + attrs, body)

    def handlers(self, depth: int, tag: str, actions: tuple[Action, ...]) -> None:
        if not actions:
            return
        blocks = (
            [b.actions for b in actions if isinstance(b, Block)]
            if all(isinstance(b, Block) for b in actions)
            else [actions]
        )
        for block in blocks:
            self.element(depth, tag, self.sub(self.actions, depth + 1, block))

    def datamodel(self, depth: int, items: tuple[DataItem, ...]) -> None:
        if not items:
            return
        self.emit(depth, "<datamodel>")
        for d in items:
            attrs = _attrs(id=d.name, expr=d.expr, src=d.src)
            if d.body is not None and d.expr is None and d.src is None:
                self.emit(depth + 1, f"<data{attrs}>{escape(d.body)}</data>")
            else:
                self.emit(depth + 1, f"<data{attrs}/>")
        self.emit(depth, "</datamodel>")

    def invoke(self, depth: int, d: ChildInvoke) -> None:
        attrs = _attrs(
            type=d.type,
            typeexpr=d.typeexpr,
            src=d.src,
            srcexpr=d.srcexpr,
            id=d.id,
            idlocation=d.idlocation,
            namelist=" ".join(d.namelist) or None,
            autoforward="true" if d.autoforward else None,
        )
        body = self.sub(self.params, depth + 1, d.params)
        body += self.sub(self.content, depth + 1, d.content)
        if d.finalize:
            body += self.sub(
                self.element,
                depth + 1,
                "finalize",
                self.sub(self.actions, depth + 2, d.finalize),
            )
        self.element(depth, "invoke" + attrs, body)

    def transition(self, depth: int, t: Transition, index: int | None = None) -> None:
        tokens = [scxml_event(e) for e in t.events]
        exact = t.events[0] if len(t.events) == 1 and tokens[0] != t.events[0] else None
        attrs = _attrs(
            event=" ".join(tokens) or None,
            statectl__event_name=exact,
            cond=t.guard,
            target=" ".join(t.targets) or None,
            type="internal" if t.internal else None,
            statectl__condition=t.condition or None,
            statectl__row=str(index) if index is not None else None,
        )
        self.element(depth, "transition" + attrs, self.sub(self.actions, depth + 1, t.actions))

    # -- states ------------------------------------------------------------------------------------

    def state(self, depth: int, s: State) -> None:
        tag = _TAG[s.kind]
        controls = " ".join(sorted(c.value.replace(" ", "-") for c in s.controls)) or None
        attrs = _attrs(
            id=None if s.name.startswith("_state") else s.name,
            initial=" ".join(s.initial) or None if not s.initial_actions else None,
            type="deep" if s.kind is StateKind.HISTORY_DEEP else None,
            statectl__controls=controls,
            statectl__description=s.description or None,
            statectl__component=s.component or None,
            statectl__number=str(s.number) if s.number is not None else None,
        )
        body = self.sub(self.state_body, depth + 1, s)
        self.element(depth, tag + attrs, body)

    def state_body(self, depth: int, s: State) -> None:
        if s.initial_actions:
            inner = self.sub(
                self.element,
                depth + 1,
                "transition" + _attrs(target=" ".join(s.initial)),
                self.sub(self.actions, depth + 2, s.initial_actions),
            )
            self.element(depth, "initial", inner)
        if s.kind.is_history and s.history_default:
            self.element(
                depth,
                "transition" + _attrs(target=" ".join(s.history_default)),
                self.sub(self.actions, depth + 1, s.history_actions),
            )
        self.datamodel(depth, s.data)
        self.handlers(depth, "onentry", s.on_entry)
        self.handlers(depth, "onexit", s.on_exit)
        for extra, line in timeout_lines(s):  # statectl.out.scxml.timeouts
            self.emit(depth + extra, line)
        for event in sorted(e for state, e in self.chart.ignored if state == s.name):
            self.emit(depth, f"<statectl:ignore{_attrs(event=event)}/>")
        for index, t in self.by_source.get(s.name, []):
            self.transition(depth, t, index if self.reordered else None)
        for d in s.invokes:
            self.invoke(depth, d)
        if s.donedata is not None:
            inner = self.sub(self.params, depth + 1, s.donedata.params)
            inner += self.sub(self.content, depth + 1, s.donedata.content)
            self.element(depth, "donedata", inner)
        for child in self.chart.children(s.name):
            self.state(depth, child)

    def device_facts(self, depth: int) -> None:
        """Event declarations, observer APIs and invoke numbers (rule 4)."""
        c = self.chart
        for e in c.events:
            attrs = _attrs(
                name=e.name,
                kind=e.kind.value,
                api=e.api,
                description=e.description or None,
                data=", ".join(f"{k}: {v}" for k, v in e.fields) or None,
            )
            self.emit(depth, f"<statectl:event{attrs}/>")
        for a in c.apis:
            uses = ["  " * (depth + 1) + f"<statectl:uses{_attrs(event=e)}/>" for e in a.events]
            self.element(depth, "statectl:api" + _attrs(method=a.method), uses)
        for i in c.invokes:
            attrs = _attrs(number=str(i.number), name=i.name, method=i.method)
            self.emit(depth, f"<statectl:invoke{attrs}/>")

    def document(self) -> str:
        c = self.chart
        attrs = _attrs(
            xmlns=SCXML_NS,
            xmlns__statectl=STATECTL_NS,
            version="1.0",
            name=c.name,
            initial=" ".join(c.initial) or None,
            datamodel=c.datamodel,
            binding=c.binding if c.binding != "early" else None,
            statectl__component=c.component or None,
            statectl__profile=c.profile or None,
        )
        self.emit(0, '<?xml version="1.0" encoding="UTF-8"?>')
        self.emit(0, f"<scxml{attrs}>")
        self.device_facts(1)
        self.datamodel(1, c.data)
        for script in c.script:
            self.action(1, script)
        for s in c.children(None):
            self.state(1, s)
        self.emit(0, "</scxml>")
        return "\n".join(self.lines) + "\n"


def write_scxml(chart: Chart) -> str:
    """The chart as SCXML text; :func:`~statectl.out.scxml.reader.read_scxml` reads it back."""
    return _Writer(chart).document()
