"""``<send>`` and ``<invoke>``: where a session's messages go and how children start.

Kept out of :mod:`statectl.out.scxml.session` (which calls these for its
:class:`~statectl.out.scxml.session.Session`) because routing and invoking have their
own rules (4 and 5 there) and bounds, which read best together.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from statectl.kernel.model import ChildInvoke, Send
from statectl.kernel.semantics import Event
from statectl.out.scxml.datamodel import EvaluationError
from statectl.out.scxml.reader import read_scxml
from statectl.out.scxml.scheduler import parse_delay

if TYPE_CHECKING:
    from statectl.out.scxml.session import Session

#: Deepest chain of invoked sessions (a document invoking itself stops here).
MAX_INVOKE_DEPTH = 16
#: Most sessions running at once in one scheduler (a document and its invoked children).
MAX_SESSIONS = 256


SCXML_IO = "http://www.w3.org/TR/scxml/#SCXMLEventProcessor"
SCXML_INVOKE = "http://www.w3.org/TR/scxml/"
_SCXML_TYPES = frozenset({SCXML_IO, "scxml"})
_INVOKE_TYPES = frozenset({SCXML_INVOKE, SCXML_INVOKE.rstrip("/"), "scxml"})


class SendError(EvaluationError):
    """A send that cannot be dispatched: ends the block with ``event`` carrying the sendid."""

    def __init__(self, message: str, event: str, sendid: str) -> None:
        super().__init__(message)
        self.event = event
        self.sendid = sendid


def send(session: Session, s: Send) -> None:
    """Evaluate a ``<send>`` and deliver it now or on the scheduler's clock."""
    dm = session.datamodel
    sendid = s.id or ""
    if s.idlocation is not None:
        sendid = session.new_id("send")
        dm.assign(s.idlocation, sendid)
    name = s.event if s.eventexpr is None else str(dm.evaluate(s.eventexpr))
    target = s.target if s.targetexpr is None else str(dm.evaluate(s.targetexpr))
    kind = s.type if s.typeexpr is None else str(dm.evaluate(s.typeexpr))
    delay = 0.0
    if s.delayexpr is not None:
        delay = parse_delay(str(dm.evaluate(s.delayexpr)))
    elif s.delay is not None:
        delay = parse_delay(s.delay)
    if s.content is not None:
        data: Any = session.content_value(s.content)
    elif s.namelist or s.params:
        data = session.params_value(s.namelist, s.params)
    else:
        data = None
    if kind is not None and kind not in _SCXML_TYPES:
        raise EvaluationError(f"send type {kind!r} is not supported")
    if name is None:
        raise EvaluationError("<send> names no event")
    event = Event(
        name,
        data,
        "external",
        sendid,
        session.origin,
        SCXML_IO,
        session.invokeid if target == "#_parent" else "",
    )
    deliver = session.route(target, event, sendid)
    if deliver is None:
        return
    if delay > 0:
        session.scheduler.add_timer(session, delay, sendid, deliver)
    else:
        deliver()


def route(
    session: Session, target: str | None, event: Event, sendid: str
) -> Callable[[], None] | None:
    """Where a send goes, as a function that delivers it; errors are raised here."""
    if target is None or target == "":
        return lambda: session.post(event)
    if target == "#_internal":
        return lambda: session.run.raise_event(replace(event, type="internal"))
    if target == "#_parent":
        parent = session.parent
        if parent is None:
            session.error("error.communication", sendid)
            return None
        return lambda: parent.post(event)
    if target.startswith("#_scxml_"):
        other = session.scheduler.sessions.get(target.removeprefix("#_scxml_"))
        if other is None:
            session.error("error.communication", sendid)
            return None
        return lambda: other.post(event)
    if target.startswith("#_"):
        invokeid = target.removeprefix("#_")

        def to_child() -> None:
            entry = session.invocations.get(invokeid)
            if entry is None or entry[2] is None or not entry[2].running:
                session.error("error.communication", sendid)
                return
            entry[2].post(event)

        if invokeid not in session.invocations:
            session.error("error.communication", sendid)
            return None
        return to_child
    raise SendError(f"send target {target!r} is not supported", "error.execution", sendid)


# -- invoke -------------------------------------------------------------------------------------


def check_invoke_bounds(session: Session) -> None:
    """Refuse an invoke past :data:`MAX_INVOKE_DEPTH` or :data:`MAX_SESSIONS`."""
    if session.depth + 1 > MAX_INVOKE_DEPTH:
        raise EvaluationError(
            f"invokes nest deeper than {MAX_INVOKE_DEPTH} sessions (a document invoking itself?)"
        )
    running = sum(1 for s in session.scheduler.sessions.values() if s.running)
    if running >= MAX_SESSIONS:
        raise EvaluationError(f"more than {MAX_SESSIONS} sessions would run at once")


def invoke(session: Session, state: str, d: ChildInvoke) -> None:
    """Start an invoked child session for ``state`` (errors become ``error.execution``)."""
    from statectl.out.scxml.session import Session

    dm = session.datamodel
    invokeid = d.id or f"{state}.{session.new_id('invoke')}"
    try:
        if d.idlocation is not None:
            dm.assign(d.idlocation, invokeid)
        kind = d.type if d.typeexpr is None else str(dm.evaluate(d.typeexpr))
        if kind is not None and kind not in _INVOKE_TYPES:
            raise EvaluationError(f"invoke type {kind!r} is not supported")
        if d.content is not None:
            text = session.content_value(d.content)
            base = session.base
        else:
            src = d.src if d.srcexpr is None else str(dm.evaluate(d.srcexpr))
            if src is None:
                raise EvaluationError("<invoke> has neither src, srcexpr nor content")
            text, base = session.read_src(src)
        values = session.params_value(d.namelist, d.params)
        session.check_invoke_bounds()
    except EvaluationError as exc:
        session.scheduler.trace(f"invoke failed: {exc}")
        session.error("error.execution")
        return
    if not isinstance(text, str):
        session.error("error.execution")
        return
    chart, _diagnostics = read_scxml(text, f"<invoke {invokeid}>", str(base))
    if chart is None:
        session.error("error.execution")
        return
    if chart.datamodel == "python" and not session.trusted:
        # Trust is never gained: only a document that is itself trusted (python)
        # may start a python child; a safe or null parent gets error.execution.
        session.scheduler.trace(
            f"invoke {invokeid!r} refused: a {session.chart.datamodel!r} document "
            "cannot invoke a 'python' datamodel child (trust is never gained)"
        )
        session.error("error.execution")
        return
    child = Session(
        chart, session.scheduler, base=base, parent=session, invokeid=invokeid, initial_data=values
    )
    session.invocations[invokeid] = (state, d, child)
