"""Load-time checks of a ``datamodel="safe"`` document: nothing escapes the safe language.

Rules:
1. Every condition and expression (guards, ``<data expr>``, ``<log>``, ``<assign>``,
   ``<if>``/``<elseif>``, ``<foreach array>``, every ``*expr`` of ``<send>``,
   ``<cancel>`` and ``<invoke>``, ``<param>`` and ``<content>`` expressions) must be
   accepted by :func:`statectl.kernel.expr.compile_expression` (X301 does not parse, X302
   refused construct) and read only declared names (X303).
2. Declared names: every ``<data id>`` of the document, the ``<foreach>`` item and
   index variables, ``_event``, and ``previous`` (which device charts' guards read).
3. Every location (``<assign location>``, ``<param location>``, ``namelist``,
   ``idlocation``, ``<foreach item/index>``) is a plain declared name; anything
   else (an attribute, a subscript, a system variable) is X302, an undeclared name
   X303.
4. ``<script>`` is refused (X302): the safe datamodel runs no code.
5. The whitelist holds names: a ``<data id>``, ``<foreach item/index>`` or any
   location named like a callable (``len``, ``str``, ``In``, ...) or starting with
   ``_`` is X302, so no variable can stand where a function is called.
6. ``<data src>`` and ``<invoke src>`` that leave the document's directory (an
   absolute path, a ``..`` step, a URL scheme other than ``file:``) are X302; a
   relative ``src`` loads, and the session reads it only when run with
   ``allow_src`` (``statectl scxml run --allow-src``), confined to that directory.
7. Each diagnostic carries the line of the element it is about.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.expr import CALLABLE_NAMES, check_names, compile_expression
from statectl.kernel.model import (
    Action,
    Assign,
    Block,
    Cancel,
    Chart,
    ChildInvoke,
    Content,
    Foreach,
    If,
    Log,
    Param,
    Script,
    Send,
)

__all__ = ["check_safe", "src_escapes"]

#: Names a safe document may read without declaring them.
IMPLICIT = frozenset({"_event", "previous"})


def src_escapes(src: str) -> str | None:
    """Why a ``src`` would leave the document's directory, or ``None`` when it stays inside."""
    text = src.strip()
    path = text.removeprefix("file:")
    if ":" in path.split("/", 1)[0] or text.startswith("file://"):
        return "names a URL or a drive"
    if path.startswith(("/", "\\")) or path == "":
        return "is an absolute path" if path else "is empty"
    if ".." in path.replace("\\", "/").split("/"):
        return "steps out with '..'"
    return None


def src_outside(src: str, path: Path, root: Path) -> str | None:
    """Why ``src`` (read as ``path``) is not inside ``root``, or ``None`` when it is.

    The written name must stay inside (:func:`src_escapes`), and so must the file it
    resolves to: a symbolic link out of the directory is refused too.
    """
    why = src_escapes(src)
    if why is not None:
        return why
    try:
        inside = path.resolve().is_relative_to(root)
    except (OSError, RuntimeError):  # a link loop
        inside = False
    return None if inside else "leaves the document's directory through a link"


def _foreach_names(actions: Iterable[Action]) -> Iterator[str]:
    for a in actions:
        if isinstance(a, Foreach):
            yield a.item.strip()
            if a.index is not None:
                yield a.index.strip()
            yield from _foreach_names(a.actions)
        elif isinstance(a, If):
            for _, branch in a.branches:
                yield from _foreach_names(branch)
        elif isinstance(a, Block):
            yield from _foreach_names(a.actions)


def _all_actions(chart: Chart) -> Iterator[tuple[Action, ...]]:
    yield chart.script
    for s in chart.states:
        yield s.on_entry
        yield s.on_exit
        yield s.initial_actions
        yield s.history_actions
        for d in s.invokes:
            yield d.finalize
    for t in chart.transitions:
        yield t.actions


class _Checker:
    def __init__(self, chart: Chart) -> None:
        names = {d.name for d in chart.data}
        names.update(d.name for s in chart.states for d in s.data)
        for actions in _all_actions(chart):
            names.update(_foreach_names(actions))
        self.known = frozenset(names | IMPLICIT)
        self.out: list[Diagnostic] = []

    def expr(self, source: str | None, where: Location, what: str) -> None:
        if source is None:
            return
        expression, problems = compile_expression(source, where, what=what)
        self.out.extend(problems)
        if expression is not None:
            self.out.extend(check_names(expression, self.known, where, what=what))

    def src(self, src: str | None, where: Location, what: str) -> None:
        why = None if src is None else src_escapes(src)
        if why is not None:
            self.out.append(
                Diagnostic(
                    "X302",
                    Severity.ERROR,
                    where,
                    f"{what} {src!r} {why}: a datamodel='safe' document reads no file "
                    "outside its own directory",
                    "put the file next to the document and name it relatively, or inline the value",
                )
            )

    def variable(self, name: str, where: Location, what: str) -> None:
        text = name.strip()
        if text in CALLABLE_NAMES or text.startswith("_") or not text.isidentifier():
            self.out.append(
                Diagnostic(
                    "X302",
                    Severity.ERROR,
                    where,
                    f"{what} {name!r} cannot be a variable of the safe datamodel",
                    "variables are plain names, do not start with '_' and are not a callable "
                    "name (" + ", ".join(sorted(CALLABLE_NAMES)) + "); rename it",
                )
            )

    def location(self, name: str | None, where: Location, what: str) -> None:
        if name is None:
            return
        text = name.strip()
        if text in CALLABLE_NAMES:
            self.variable(text, where, what)
        elif not text.isidentifier() or text.startswith("_"):
            self.out.append(
                Diagnostic(
                    "X302",
                    Severity.ERROR,
                    where,
                    f"{what} {name!r} is not a plain variable name, which the safe "
                    "datamodel requires",
                    "name a variable declared with <data id=...>; attributes, subscripts "
                    "and system variables are not locations in the safe datamodel",
                )
            )
        elif text not in self.known:
            self.out.append(
                Diagnostic(
                    "X303",
                    Severity.ERROR,
                    where,
                    f"{what} {name!r} is not a declared variable",
                    "declare it with <data id=...> in a <datamodel>",
                )
            )

    def params(self, params: Iterable[Param]) -> None:
        for p in params:
            self.expr(p.expr, p.origin, "param expression")
            self.location(p.location, p.origin, "param location")

    def content(self, content: Content | None) -> None:
        if content is not None:
            self.expr(content.expr, content.origin, "content expression")

    def actions(self, actions: Iterable[Action], where: Location) -> None:
        for a in actions:
            self.action(a, where)

    def action(self, a: Action, where: Location) -> None:
        if isinstance(a, Block):
            self.actions(a.actions, where)
        elif isinstance(a, Log):
            self.expr(a.expr, a.origin, "log expression")
        elif isinstance(a, Assign):
            self.location(a.location, a.origin, "assign location")
            self.expr(a.expr, a.origin, "assign expression")
        elif isinstance(a, Script):
            self.out.append(
                Diagnostic(
                    "X302",
                    Severity.ERROR,
                    a.origin,
                    "<script> in a datamodel='safe' document: the safe datamodel runs no code",
                    "use <assign> and <if>, or declare datamodel='python' if you trust "
                    "the document as you would a script",
                )
            )
        elif isinstance(a, If):
            for cond, branch in a.branches:
                self.expr(cond, a.origin, "condition")
                self.actions(branch, a.origin)
        elif isinstance(a, Foreach):
            self.expr(a.array, a.origin, "foreach array")
            self.location(a.item, a.origin, "foreach item")
            self.location(a.index, a.origin, "foreach index")
            self.actions(a.actions, a.origin)
        elif isinstance(a, Send):
            for what, source in (
                ("send eventexpr", a.eventexpr),
                ("send targetexpr", a.targetexpr),
                ("send typeexpr", a.typeexpr),
                ("send delayexpr", a.delayexpr),
            ):
                self.expr(source, a.origin, what)
            self.location(a.idlocation, a.origin, "send idlocation")
            for name in a.namelist:
                self.location(name, a.origin, "send namelist entry")
            self.params(a.params)
            self.content(a.content)
        elif isinstance(a, Cancel):
            self.expr(a.sendidexpr, a.origin, "cancel sendidexpr")

    def invoke(self, d: ChildInvoke) -> None:
        self.src(d.src, d.origin, "invoke src")
        self.expr(d.typeexpr, d.origin, "invoke typeexpr")
        self.expr(d.srcexpr, d.origin, "invoke srcexpr")
        self.location(d.idlocation, d.origin, "invoke idlocation")
        for name in d.namelist:
            self.location(name, d.origin, "invoke namelist entry")
        self.params(d.params)
        self.content(d.content)
        self.actions(d.finalize, d.origin)

    def chart(self, chart: Chart) -> list[Diagnostic]:
        items = list(chart.data) + [d for s in chart.states for d in s.data]
        for item in items:
            self.variable(item.name, item.origin, "data id")
            self.src(item.src, item.origin, "data src")
            self.expr(item.expr, item.origin, "data expression")
        self.actions(chart.script, chart.origin)
        for s in chart.states:
            for actions in (s.on_entry, s.on_exit, s.initial_actions, s.history_actions):
                self.actions(actions, s.origin)
            for d in s.invokes:
                self.invoke(d)
            if s.donedata is not None:
                self.params(s.donedata.params)
                self.content(s.donedata.content)
        for t in chart.transitions:
            self.expr(t.guard, t.origin, "guard")
            self.actions(t.actions, t.origin)
        return self.out


def check_safe(chart: Chart) -> list[Diagnostic]:
    """Every way ``chart`` (with ``datamodel="safe"``) escapes the safe language."""
    return _Checker(chart).chart(chart)
