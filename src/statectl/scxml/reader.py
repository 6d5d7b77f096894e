"""Read an SCXML document into a :class:`~statectl.model.Chart`.

Rules:
1. Every element keeps its line (:class:`~statectl.errors.Location`); every
   problem becomes a diagnostic with a stable code, and reading goes on:
   S601 not well-formed XML, S602 root is not ``<scxml>``, S603 missing required
   attribute, S604 duplicate state id, S605 unknown transition/initial target,
   S606 unknown or misplaced element (warning, skipped), S607 ``src`` file not
   readable (or larger than :data:`MAX_SRC_BYTES`, or not UTF-8).
2. States get document order, parents before children; a state without ``id``
   gets a generated one (``_state3``), which no document can name.
3. Executable content becomes model actions (``Raise``, ``Log``, ``Assign``,
   ``If``, ``Foreach``, ``Send``, ``Cancel``, ``Script``); expressions stay text
   for the session's datamodel. A state with several ``<onentry>`` (or
   ``<onexit>``) handlers keeps each as a ``Block``, so an error ends only one.
4. Inline ``<content>`` that holds elements (a child ``<scxml>``) is kept as
   serialised XML; ``<data>``/``<content>`` text is kept as text.
5. The ``statectl`` namespace carries what device tables know and SCXML does not
   (see :mod:`statectl.scxml.writer`): ``<statectl:event>``, ``<statectl:api>``,
   ``<statectl:invoke>``, ``<statectl:ignore>``, ``<statectl:notify>`` and the
   exact event name of a transition (``statectl:event-name``); transitions with a
   ``statectl:row`` are put back in that order, the chart's own.
6. A document with ``datamodel="safe"`` is checked as it loads: every condition
   and expression must be in the safe language and read only declared names,
   every location must be a declared name, and there is no ``<script>`` (X301-X303,
   from :mod:`statectl.expr`, with the element's line). ``python`` is explicit
   trust and is not checked; ``null`` is checked by its own evaluator at run time.
7. Hostile or broken documents end in a diagnostic, never an exception: elements
   nested deeper than :data:`MAX_XML_DEPTH` (S620), bytes in an encoding that
   cannot be read or an encoding the prolog names but Python does not know
   (S621), and any entity declaration in a DTD (S622: entity expansion bombs and
   external entities never reach the parser's expansion). Numbers in attributes
   are ASCII digits of at most nine places (S603).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from statectl.errors import Diagnostic, DiagnosticError, Location, Severity
from statectl.model import (
    Action,
    Api,
    Assign,
    Block,
    Cancel,
    Chart,
    Content,
    ControlKind,
    DataItem,
    DoneData,
    EventDef,
    EventKind,
    Foreach,
    If,
    Invoke,
    InvokeDef,
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
from statectl.scxml.safecheck import check_safe, src_escapes

__all__ = [
    "MAX_SRC_BYTES",
    "MAX_XML_DEPTH",
    "SCXML_NS",
    "STATECTL_NS",
    "read_scxml",
    "read_scxml_file",
    "read_src_text",
]

SCXML_NS = "http://www.w3.org/2005/07/scxml"
#: Device-table facts SCXML has no word for (controls, notifications) live here.
STATECTL_NS = "urn:statectl:scxml"
_SEP = "}"

#: Deepest element nesting a document may have (S620; docs/limits.md).
MAX_XML_DEPTH = 100
#: Largest file a ``src`` attribute may name, in bytes (S607).
MAX_SRC_BYTES = 1 << 20


class _Refused(Exception):
    """Raised inside an expat handler to stop parsing with a diagnostic."""

    def __init__(self, code: str, line: int, message: str, hint: str) -> None:
        super().__init__(message)
        self.code, self.line, self.message, self.hint = code, line, message, hint


def read_src_text(path: Path) -> str:
    """A ``src`` file's text, read with a bound: at most :data:`MAX_SRC_BYTES`, UTF-8.

    Raises ``OSError`` if it cannot be read and ``ValueError`` if it is too large
    (an endless stream such as ``/dev/zero`` stops here) or not UTF-8.
    """
    with path.open("rb") as fh:
        data = fh.read(MAX_SRC_BYTES + 1)
    if len(data) > MAX_SRC_BYTES:
        raise ValueError(f"larger than {MAX_SRC_BYTES} bytes (see docs/limits.md)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"not UTF-8 (byte {exc.start})") from None


def _number(text: str | None) -> int | None:
    """A small non-negative number written in ASCII digits, else ``None``."""
    if text is None or not text.isascii() or not text.isdigit() or len(text) > 9:
        return None
    return int(text)


@dataclass(slots=True)
class _Node:
    """A parsed element: namespace, local name, attributes, children, text, line."""

    ns: str
    tag: str
    attrs: dict[str, str]
    line: int
    children: list[_Node] = field(default_factory=list)
    text: list[str] = field(default_factory=list)  # text chunks, including between children

    def get(self, name: str) -> str | None:
        return self.attrs.get(name)

    @property
    def content_text(self) -> str:
        return "".join(self.text)

    def scxml_children(self, *tags: str) -> list[_Node]:
        return [c for c in self.children if c.ns == SCXML_NS and (not tags or c.tag in tags)]


def _parse_xml(text: str | bytes, file: str) -> tuple[_Node | None, list[Diagnostic]]:
    """Parse text (its prolog's encoding ignored) or bytes (decoded as the prolog says)."""
    parser = expat.ParserCreate(
        "UTF-8" if isinstance(text, str) else None, namespace_separator=_SEP
    )
    stack: list[_Node] = []
    root: list[_Node] = []

    def split(name: str) -> tuple[str, str]:
        if _SEP in name:
            ns, local = name.split(_SEP, 1)
            return ns, local
        return "", name

    def start(name: str, attrs: dict[str, str]) -> None:
        if len(stack) >= MAX_XML_DEPTH:
            raise _Refused(
                "S620",
                parser.CurrentLineNumber,
                f"elements nested deeper than {MAX_XML_DEPTH} levels",
                "flatten the document; see docs/limits.md",
            )
        ns, local = split(name)
        plain = {split(k)[1]: v for k, v in attrs.items()}
        node = _Node(ns, local, plain, parser.CurrentLineNumber)
        if stack:
            stack[-1].children.append(node)
        else:
            root.append(node)
        stack.append(node)

    def end(name: str) -> None:
        stack.pop()

    def chars(data: str) -> None:
        if stack:
            stack[-1].text.append(data)

    def entity(name: str, *_: object) -> None:
        raise _Refused(
            "S622",
            parser.CurrentLineNumber,
            f"the DTD declares the entity {name!r}: entity declarations are refused",
            "remove the <!ENTITY> declarations; SCXML needs no DTD",
        )

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.EntityDeclHandler = entity
    parser.UnparsedEntityDeclHandler = entity
    try:
        data = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text
        parser.Parse(data, True)
    except _Refused as exc:
        return None, [
            Diagnostic(exc.code, Severity.ERROR, Location(file, exc.line), exc.message, exc.hint)
        ]
    except (LookupError, UnicodeError, ValueError) as exc:  # the prolog's encoding
        return None, [
            Diagnostic(
                "S621",
                Severity.ERROR,
                Location(file, parser.CurrentLineNumber or 1),
                f"the document's encoding cannot be read: {exc}",
                'save the document as UTF-8 and declare encoding="UTF-8" (or nothing)',
            )
        ]
    except expat.ExpatError as exc:
        where = Location(file, exc.lineno)
        return None, [
            Diagnostic(
                "S601",
                Severity.ERROR,
                where,
                f"the document is not well-formed XML: {expat.errors.messages[exc.code]}",
                "fix the XML syntax at that line (unclosed tag, stray '<' or '&')",
            )
        ]
    return root[0], []


def serialise(node: _Node, parent_ns: str | None = None) -> str:
    """Write a parsed element back as XML text (for inline ``<content>``)."""
    from xml.sax.saxutils import escape, quoteattr

    attrs = "".join(f" {k}={quoteattr(v)}" for k, v in node.attrs.items())
    if node.ns != parent_ns and node.ns:
        attrs = f" xmlns={quoteattr(node.ns)}" + attrs
    inner = escape("".join(node.text)) + "".join(serialise(c, node.ns) for c in node.children)
    return f"<{node.tag}{attrs}>{inner}</{node.tag}>"


class _Reader:
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
        why = None if self.trusted else src_escapes(src)
        if why is None and not self.trusted:
            try:
                inside = path.resolve().is_relative_to(self.base.resolve())
            except (OSError, RuntimeError):
                inside = False
            if not inside:
                why = "leaves the document's directory through a link"
            elif not path.is_file():
                why = "is not a regular file"
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
        blocks = [self.executable(h) for h in node.scxml_children(tag)]
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

    def invoke_def(self, c: _Node) -> InvokeDef:
        content = c.scxml_children("content")
        finalize = c.scxml_children("finalize")
        return InvokeDef(
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

    # -- states -------------------------------------------------------------------------------

    def state_id(self, node: _Node) -> str:
        sid = node.get("id")
        if sid is None:
            self.generated += 1
            return f"_state{self.generated}"
        if sid in self.ids:
            self.problem(
                "S604", node, f"state id {sid!r} is used twice", "give every state a unique id"
            )
        self.ids.add(sid)
        return sid

    def controls(self, node: _Node) -> frozenset[ControlKind]:
        found: set[ControlKind] = set()
        for word in (node.get("controls") or "").split():
            try:
                found.add(ControlKind(word.replace("-", " ")))
            except ValueError:
                self.problem(
                    "S603",
                    node,
                    f"unknown state control {word!r}",
                    "use default, monitoring-required or event-trigger-required",
                    warn=True,
                )
        return frozenset(found)

    def transition(self, source: str, t: _Node) -> Transition:
        exact = t.get("event-name")
        return Transition(
            source=source,
            events=(exact,) if exact is not None else tuple((t.get("event") or "").split()),
            targets=tuple((t.get("target") or "").split()),
            guard=t.get("cond"),
            condition=t.get("condition") or "",
            internal=(t.get("type") or "external") == "internal",
            actions=self.executable(t),
            origin=self.at(t),
        )

    def state(self, node: _Node, parent: str | None) -> None:
        tag = node.tag
        name = self.state_id(node)
        index = len(self.states)
        self.states.append(State(name))  # placeholder keeps document order
        for c in node.children:
            if c.ns == STATECTL_NS and c.tag == "ignore":
                self.ignored.add((name, self.need(c, "event")))
        children = [c for c in node.scxml_children("state", "parallel", "final", "history")]
        initial: tuple[str, ...] = tuple((node.get("initial") or "").split())
        initial_actions: tuple[Action, ...] = ()
        for init in node.scxml_children("initial"):
            ts = init.scxml_children("transition")
            if ts:
                initial = tuple((ts[0].get("target") or "").split())
                initial_actions = self.executable(ts[0])
        self.references.append((name, initial, self.at(node)))
        history_default: tuple[str, ...] = ()
        history_actions: tuple[Action, ...] = ()
        if tag == "state":
            kind = StateKind.COMPOUND if children else StateKind.ATOMIC
        elif tag == "parallel":
            kind = StateKind.PARALLEL
        elif tag == "final":
            kind = StateKind.FINAL
        else:
            deep = (node.get("type") or "shallow") == "deep"
            kind = StateKind.HISTORY_DEEP if deep else StateKind.HISTORY_SHALLOW
            ts = node.scxml_children("transition")
            if ts:
                history_default = tuple((ts[0].get("target") or "").split())
                history_actions = self.executable(ts[0])
        donedata = None
        if tag == "final":
            for dd in node.scxml_children("donedata"):
                content = dd.scxml_children("content")
                donedata = DoneData(
                    self.params_of(dd), self.content_of(content[0] if content else None)
                )
        if tag != "history":
            for t in node.scxml_children("transition"):
                self.transitions.append(self.transition(name, t))
                row = _number(t.get("row"))
                if row is not None:
                    self.rows[len(self.transitions) - 1] = row
        self.states[index] = State(
            name,
            kind,
            parent,
            initial if kind is StateKind.COMPOUND else (),
            on_entry=self.handlers(node, "onentry"),
            on_exit=self.handlers(node, "onexit"),
            history_default=history_default,
            controls=self.controls(node),
            description=node.get("description") or "",
            component=node.get("component") or "",
            origin=self.at(node),
            initial_actions=initial_actions,
            history_actions=history_actions,
            data=self.data_items(node),
            invokes=tuple(self.invoke_def(i) for i in node.scxml_children("invoke")),
            donedata=donedata,
        )
        for c in children:
            self.state(c, name)

    def check_targets(self, chart: Chart) -> None:
        known = {s.name for s in chart.states}
        names = sorted(known)
        listing = "known states: " + ", ".join(names[:20])  # once, and short
        if len(names) > 20:
            listing += f" and {len(names) - 20} more"
        for t in chart.transitions:
            for x in t.targets:
                if x not in known:
                    self.diagnostics.append(
                        Diagnostic(
                            "S605",
                            Severity.ERROR,
                            t.origin,
                            f"transition from {t.source!r} targets unknown state {x!r}",
                            listing,
                        )
                    )
        references = [
            *self.references,
            *((s.name, s.history_default, s.origin) for s in chart.states),
        ]
        for name, targets, origin in references:
            for x in targets:
                if x not in known:
                    self.diagnostics.append(
                        Diagnostic(
                            "S605",
                            Severity.ERROR,
                            origin,
                            f"state {name!r} names unknown initial/default state {x!r}",
                            listing,
                        )
                    )
        for x in chart.initial:
            if x not in known:
                self.diagnostics.append(
                    Diagnostic(
                        "S605",
                        Severity.ERROR,
                        chart.origin,
                        f"<scxml initial> names unknown state {x!r}",
                        listing,
                    )
                )

    def device_facts(
        self, root: _Node
    ) -> tuple[tuple[EventDef, ...], tuple[Api, ...], tuple[Invoke, ...]]:
        """The ``statectl`` declarations of events, APIs and invoke numbers (rule 5)."""
        events: list[EventDef] = []
        apis: list[Api] = []
        invokes: list[Invoke] = []
        for c in root.children:
            if c.ns != STATECTL_NS:
                continue
            if c.tag == "event":
                text = c.get("kind") or "command"
                try:
                    kind = EventKind(text)
                except ValueError:
                    self.problem(
                        "S603",
                        c,
                        f"unknown event kind {text!r}",
                        "use " + ", ".join(k.value for k in EventKind),
                    )
                    kind = EventKind.COMMAND
                events.append(
                    EventDef(
                        self.need(c, "name"),
                        kind,
                        c.get("api"),
                        c.get("description") or "",
                        self.at(c),
                    )
                )
            elif c.tag == "api":
                uses = tuple(
                    self.need(u, "event")
                    for u in c.children
                    if u.ns == STATECTL_NS and u.tag == "uses"
                )
                apis.append(Api(self.need(c, "method"), uses, self.at(c)))
            elif c.tag == "invoke":
                text = c.get("number") or ""
                number = _number(text)
                if number is None:
                    self.problem("S603", c, f"invoke number {text[:20]!r} is not a number", "0, 1")
                    number = 0
                invokes.append(Invoke(number, self.need(c, "name"), self.need(c, "method")))
        return tuple(events), tuple(apis), tuple(invokes)

    def chart(self, root: _Node, default_name: str) -> Chart:
        self.trusted = root.get("datamodel") == "python"
        scripts = tuple(
            Script(self.script_source(s), self.at(s)) for s in root.scxml_children("script")
        )
        for c in root.scxml_children("state", "parallel", "final"):
            self.state(c, None)
        events, apis, invokes = self.device_facts(root)
        if self.rows:  # stable: transitions without a row keep their place after those with one
            order = sorted(
                range(len(self.transitions)),
                key=lambda i: self.rows.get(i, len(self.transitions) + i),
            )
            self.transitions = [self.transitions[i] for i in order]
        chart = Chart(
            name=root.get("name") or default_name,
            states=tuple(self.states),
            transitions=tuple(self.transitions),
            initial=tuple((root.get("initial") or "").split()),
            events=events,
            apis=apis,
            invokes=invokes,
            ignored=frozenset(self.ignored),
            data=self.data_items(root),
            datamodel=root.get("datamodel") or "null",
            component=root.get("component") or "",
            origin=self.at(root),
            binding=root.get("binding") or "early",
            script=scripts,
        )
        self.check_targets(chart)
        return chart


def read_scxml(
    text: str | bytes, file: str = "<memory>", base: str | None = None
) -> tuple[Chart | None, list[Diagnostic]]:
    """Parse SCXML text or bytes; return the chart (``None`` on errors) and every diagnostic.

    Text is parsed as it is (an ``encoding`` in its prolog is ignored); bytes are
    decoded as the prolog declares (UTF-8 when it declares nothing).
    """
    root, diagnostics = _parse_xml(text, file)
    if root is None:
        return None, diagnostics
    if root.ns != SCXML_NS or root.tag != "scxml":
        return None, [
            Diagnostic(
                "S602",
                Severity.ERROR,
                Location(file, root.line),
                f"the root element is <{root.tag}>, not <scxml> in the SCXML namespace",
                f'start the document with <scxml xmlns="{SCXML_NS}" version="1.0">',
            )
        ]
    reader = _Reader(file, Path(base) if base is not None else Path(os.getcwd()))
    stem = Path(file).stem if file != "<memory>" else "scxml"
    chart = reader.chart(root, stem)
    diagnostics = reader.diagnostics
    if chart.datamodel == "safe":
        diagnostics.extend(check_safe(chart))
    if any(d.severity is Severity.ERROR for d in diagnostics):
        return None, diagnostics
    return chart, diagnostics


def read_scxml_file(path: str) -> Chart:
    """Read a file; raise :class:`DiagnosticError` with every problem if it has errors."""
    try:
        text = Path(path).read_bytes()
    except OSError as exc:
        raise DiagnosticError(
            [
                Diagnostic(
                    "S607",
                    Severity.ERROR,
                    Location(path),
                    f"cannot read: {exc.strerror}",
                    "check the path",
                )
            ]
        ) from exc
    chart, diagnostics = read_scxml(text, path, str(Path(path).parent))
    if chart is None:
        raise DiagnosticError(diagnostics)
    return chart
