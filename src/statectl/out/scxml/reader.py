"""Read an SCXML document into a :class:`~statectl.kernel.model.Chart`.

Rules:
1. Every element keeps its line (:class:`~statectl.kernel.errors.Location`); every
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
   (see :mod:`statectl.out.scxml.writer`): ``<statectl:event>``, ``<statectl:api>``,
   ``<statectl:invoke>``, ``<statectl:ignore>``, ``<statectl:notify>`` and the
   exact event name of a transition (``statectl:event-name``); transitions with a
   ``statectl:row`` are put back in that order, the chart's own.
6. A document with ``datamodel="safe"`` is checked as it loads: every condition
   and expression must be in the safe language and read only declared names,
   every location must be a declared name, and there is no ``<script>`` (X301-X303,
   from :mod:`statectl.kernel.expr`, with the element's line). ``python`` is explicit
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
from pathlib import Path

from statectl.kernel.errors import Diagnostic, DiagnosticError, Location, Severity
from statectl.kernel.model import (
    Action,
    Api,
    Chart,
    ControlKind,
    DoneData,
    EventDef,
    EventKind,
    InvokeNumber,
    Script,
    State,
    StateKind,
    Transition,
)
from statectl.out.scxml.executable import ContentReader
from statectl.out.scxml.safecheck import check_safe
from statectl.out.scxml.timeouts import read_defer, read_timeout
from statectl.out.scxml.xmltree import (
    SCXML_NS,
    STATECTL_NS,
    _Node,
    _number,
    _parse_xml,
)

__all__ = ["read_scxml", "read_scxml_file", "statectl_elements"]


def _fields(text: str) -> tuple[tuple[str, str], ...]:
    """``statectl:event data="pressure: float, part: str"``: the event's declared fields."""
    pairs = (part.partition(":") for part in text.split(","))
    return tuple((k.strip(), v.strip()) for k, _, v in pairs if k.strip())


class _Reader(ContentReader):
    """Adds states, transitions, targets and the chart to the content reader."""

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

    def number(self, node: _Node) -> int | None:
        """A state's ``statectl:number`` (its table's ``number``): digits up to 2**31 - 1."""
        text = node.get("number")
        if text is None:
            return None
        if text.isascii() and text.isdigit() and len(text) <= 10 and int(text) < 2**31:
            return int(text)
        self.problem(
            "S603",
            node,
            f"state number {text!r} is not a whole number from 0 to {2**31 - 1}",
            "write the number in digits, or leave statectl:number out",
            warn=True,
        )
        return None

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
            timeout=read_timeout(node),
            defer=read_defer(node),
            number=self.number(node),
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
    ) -> tuple[tuple[EventDef, ...], tuple[Api, ...], tuple[InvokeNumber, ...]]:
        """The ``statectl`` declarations of events, APIs and invoke numbers (rule 5)."""
        events: list[EventDef] = []
        apis: list[Api] = []
        invokes: list[InvokeNumber] = []
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
                        _fields(c.get("data") or ""),
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
                invokes.append(InvokeNumber(number, self.need(c, "name"), self.need(c, "method")))
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
            profile=root.get("profile") or "",
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
        if Path(path).exists() and not Path(path).is_file() and not Path(path).is_dir():
            # a FIFO would block the read forever, a device such as /dev/zero never end it
            raise OSError(0, "not a regular file (a FIFO, device or socket); name a file")
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


def statectl_elements(text: str | bytes, tag: str) -> list[tuple[dict[str, str], int]]:
    """The ``statectl:TAG`` children of the root, as (attributes, line), in order.

    Device facts that are no part of the chart (the Recovery table travels as
    ``<statectl:recovery>``) are read by the layer that owns them; a document that
    does not parse has none (:func:`read_scxml` reports why).
    """
    root, _ = _parse_xml(text, "<memory>")
    if root is None:
        return []
    return [(dict(c.attrs), c.line) for c in root.children if c.ns == STATECTL_NS and c.tag == tag]
