"""Executable content of an SCXML document: the actions, data, params and invokes.

The base of the reader: it holds the diagnostics and turns ``<onentry>``,
``<transition>`` bodies, ``<datamodel>`` and ``<invoke>`` into model values;
:mod:`statectl.out.scxml.reader` adds states, transitions and the chart on top.
"""

from __future__ import annotations

from pathlib import Path

from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.model import (
    Action,
    Assign,
    Block,
    Cancel,
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
    Transition,
)
from statectl.out.scxml.safecheck import src_outside
from statectl.out.scxml.timeouts import is_timeout_handler
from statectl.out.scxml.xmltree import (
    SCXML_NS,
    STATECTL_NS,
    _Node,
    _number,
    read_src_text,
    serialise,
)


class ContentReader:
    """Reads executable content and data; collects the diagnostics of one document."""

    def __init__(self, file: str, base: Path) -> None:
        self.file = file
        self.base = base
        self.trusted = False  # a python document may read any src; others stay in base
        self.diagnostics: list[Diagnostic] = []
        self.states: list[State] = []
        self.transitions: list[Transition] = []
        self.ids: set[str] = set()
        self.generated = 0
        self.references: list[tuple[str, tuple[str, ...], Location]] = []  # initial/default
        self.ignored: set[tuple[str, str]] = set()
        self.rows: dict[int, int] = {}  # transition index -> statectl:row (the chart's order)

    def at(self, node: _Node) -> Location:
        return Location(self.file, node.line)

    def problem(
        self, code: str, node: _Node, message: str, hint: str, *, warn: bool = False
    ) -> None:
        severity = Severity.WARNING if warn else Severity.ERROR
        self.diagnostics.append(Diagnostic(code, severity, self.at(node), message, hint))

    def need(self, node: _Node, attr: str) -> str:
        value = node.get(attr)
        if value is None:
            self.problem(
                "S603",
                node,
                f"<{node.tag}> has no '{attr}' attribute",
                f'add {attr}="..." to the <{node.tag}> element',
            )
            return ""
        return value

    # -- executable content -------------------------------------------------------------------

    def content_of(self, node: _Node | None) -> Content | None:
        if node is None:
            return None
        elements = [c for c in node.children]
        body: str | None
        if elements:
            body = "".join(serialise(c) for c in elements)
        else:
            text = node.content_text
            body = text if text.strip() or node.get("expr") is None else None
        if node.get("expr") is not None:
            body = None
        return Content(node.get("expr"), body, self.at(node))

    def params_of(self, node: _Node) -> tuple[Param, ...]:
        return tuple(
            Param(self.need(p, "name"), p.get("expr"), p.get("location"), self.at(p))
            for p in node.scxml_children("param")
        )

    def executable(self, node: _Node) -> tuple[Action, ...]:
        out: list[Action] = []
        for c in node.children:
            if c.ns == STATECTL_NS and c.tag == "notify":
                out.append(self.notify(c))
                continue
            if c.ns != SCXML_NS:
                continue
            action = self.action(c)
            if action is not None:
                out.append(action)
        return tuple(out)

    def notify(self, c: _Node) -> Notify:
        text = c.get("invoke") or "0"
        number = _number(text)
        if number is None:
            self.problem("S603", c, f"notify invoke {text[:20]!r} is not a number", "use 0, 1, ...")
            number = 0
        return Notify(number, c.get("name") or "", c.get("method") or "", c.get("event") or "")

    def action(self, c: _Node) -> Action | None:
        at = self.at(c)
        tag = c.tag
        if tag == "raise":
            return Raise(self.need(c, "event"))
        if tag == "log":
            return Log(c.get("label") or "", c.get("message") or "", c.get("expr"), at)
        if tag == "assign":
            body = (
                None
                if c.get("expr") is not None
                else ("".join(serialise(x) for x in c.children) or c.content_text)
            )
            return Assign(self.need(c, "location"), c.get("expr"), body, at)
        if tag == "script":
            return Script(self.script_source(c), at)
        if tag == "if":
            return self.if_action(c)
        if tag == "foreach":
            return Foreach(
                self.need(c, "array"), self.need(c, "item"), c.get("index"), self.executable(c), at
            )
        if tag == "send":
            content = c.scxml_children("content")
            return Send(
                event=c.get("event"),
                eventexpr=c.get("eventexpr"),
                target=c.get("target"),
                targetexpr=c.get("targetexpr"),
                type=c.get("type"),
                typeexpr=c.get("typeexpr"),
                id=c.get("id"),
                idlocation=c.get("idlocation"),
                delay=c.get("delay"),
                delayexpr=c.get("delayexpr"),
                namelist=tuple((c.get("namelist") or "").split()),
                params=self.params_of(c),
                content=self.content_of(content[0] if content else None),
                origin=at,
            )
        if tag == "cancel":
            return Cancel(c.get("sendid"), c.get("sendidexpr"), at)
        self.problem(
            "S606",
            c,
            f"<{tag}> is not executable content; it was skipped",
            "use raise, log, assign, script, if, foreach, send or cancel",
            warn=True,
        )
        return None

    def if_action(self, c: _Node) -> If:
        branches: list[tuple[str | None, tuple[Action, ...]]] = []
        cond: str | None = self.need(c, "cond")
        current: list[Action] = []
        for x in c.children:
            if x.ns != SCXML_NS:
                continue
            if x.tag in ("elseif", "else"):
                branches.append((cond, tuple(current)))
                cond = self.need(x, "cond") if x.tag == "elseif" else None
                current = []
                continue
            action = self.action(x)
            if action is not None:
                current.append(action)
        branches.append((cond, tuple(current)))
        return If(tuple(branches), self.at(c))

    def script_source(self, c: _Node) -> str:
        src = c.get("src")
        if src is None:
            return c.content_text
        text = self.read_src(c, src)
        return text or ""

    def read_src(self, node: _Node, src: str) -> str | None:
        """A ``<content src>`` or ``<script src>`` read at load, bounded; an untrusted
        (safe or null) document reads only regular files inside its own directory."""
        path = self.base / src.strip().removeprefix("file:")
        why = None if self.trusted else src_outside(src, path, self.base.resolve())
        if why is not None:
            self.problem("S607", node, f"src {src!r} {why}", "keep src files beside the document")
            return None
        try:
            return read_src_text(path)
        except (OSError, ValueError) as exc:
            why = getattr(exc, "strerror", None) or str(exc)
            self.problem("S607", node, f"cannot read src {src!r}: {why}", "check the path")
            return None

    def handlers(self, node: _Node, tag: str) -> tuple[Action, ...]:
        blocks = [self.executable(h) for h in node.scxml_children(tag) if not is_timeout_handler(h)]
        if len(blocks) == 1:
            return blocks[0]
        return tuple(Block(b) for b in blocks)

    def data_items(self, node: _Node) -> tuple[DataItem, ...]:
        items: list[DataItem] = []
        for dm in node.scxml_children("datamodel"):
            for d in dm.scxml_children("data"):
                body: str | None = None
                if d.get("expr") is None and d.get("src") is None:
                    body = "".join(serialise(x) for x in d.children) or d.content_text
                    body = body if body.strip() else None
                items.append(
                    DataItem(self.need(d, "id"), d.get("expr"), self.at(d), d.get("src"), body)
                )
        return tuple(items)

    def invoke_def(self, c: _Node) -> ChildInvoke:
        content = c.scxml_children("content")
        finalize = c.scxml_children("finalize")
        return ChildInvoke(
            type=c.get("type"),
            typeexpr=c.get("typeexpr"),
            src=c.get("src"),
            srcexpr=c.get("srcexpr"),
            id=c.get("id"),
            idlocation=c.get("idlocation"),
            namelist=tuple((c.get("namelist") or "").split()),
            autoforward=(c.get("autoforward") or "false").strip() == "true",
            params=self.params_of(c),
            content=self.content_of(content[0] if content else None),
            finalize=self.executable(finalize[0]) if finalize else (),
            origin=self.at(c),
        )
