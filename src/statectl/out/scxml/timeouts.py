"""A state's timeout and deferred events in SCXML, and back.

Rules:
1. A timeout is written as SCXML says a timer is: an ``<onentry>`` that sends the event
   with a ``delay`` and an id, and an ``<onexit>`` that cancels that id. Both handlers
   carry ``statectl:timeout-of`` (the state's name), so statectl's reader takes them
   back as the state's :class:`~statectl.kernel.model.Timeout` rather than as executable
   content; any other SCXML processor runs them as the timer they are. The event is
   written as one SCXML token (spaces as ``_``, as transitions are), its exact name in
   ``statectl:event-name``; the delay in milliseconds (``3000ms``).
1a. statectl's own session (``statectl scxml run``) runs a chart's timeouts the same
   way: entering the state performs :func:`send_of`, leaving it :func:`cancel_of`.
2. SCXML has no deferral: ``defer`` is a ``<statectl:defer event="..."/>`` element per
   event, which other processors ignore (a deferred event is then dropped, as the state
   table's ``ignore`` would drop it).
"""

from __future__ import annotations

from collections.abc import Iterator

from statectl.kernel.model import Cancel, Send, State, Timeout
from statectl.out.escape.xml import attribute as quoteattr
from statectl.out.scxml.xmltree import STATECTL_NS, _Node

__all__ = ["cancel_of", "read_defer", "read_timeout", "send_of", "timeout_lines"]

#: The attribute (local name) that marks a handler as a state's timeout.
MARK = "timeout-of"


def _id(state: str) -> str:
    return "statectl.timeout." + "_".join(state.split())


def timeout_lines(s: State) -> Iterator[tuple[int, str]]:
    """``(extra depth, line)`` of the state's timeout handlers and defer elements."""
    t = s.timeout
    if t is not None:
        ms = round(t.seconds * 1000)
        token = "_".join(t.event.split())
        mark = f" statectl:{MARK}={quoteattr(s.name)}"
        exact = f" statectl:event-name={quoteattr(t.event)}" if token != t.event else ""
        yield 0, f"<onentry{mark}>"
        yield (
            1,
            (
                f"<send event={quoteattr(token)}{exact} delay={quoteattr(f'{ms}ms')} "
                f"id={quoteattr(_id(s.name))}/>"
            ),
        )
        yield 0, "</onentry>"
        yield 0, f"<onexit{mark}>"
        yield 1, f"<cancel sendid={quoteattr(_id(s.name))}/>"
        yield 0, "</onexit>"
    for event in s.defer:
        yield 0, f"<statectl:defer event={quoteattr(event)}/>"


def is_timeout_handler(handler: _Node) -> bool:
    """A handler :func:`timeout_lines` wrote: read as the timeout, not as content."""
    return handler.get(MARK) is not None


def read_timeout(node: _Node) -> Timeout | None:
    """The state's timeout from its marked ``<onentry>`` (rule 1), if any."""
    for h in node.scxml_children("onentry"):
        if not is_timeout_handler(h):
            continue
        for send in h.scxml_children("send"):
            delay = (send.get("delay") or "").strip()
            event = send.get("event-name") or send.get("event") or ""
            if delay.endswith("ms") and delay[:-2].isdigit() and event:
                return Timeout(int(delay[:-2]) / 1000, event)
    return None


def read_defer(node: _Node) -> tuple[str, ...]:
    """The state's deferred events from its ``statectl:defer`` elements (rule 2)."""
    return tuple(
        c.get("event") or ""
        for c in node.children
        if c.ns == STATECTL_NS and c.tag == "defer" and c.get("event")
    )


def send_of(s: State) -> Send | None:
    """The delayed ``<send>`` that arms the state's timeout (rule 1a), if it has one."""
    t = s.timeout
    if t is None:
        return None
    return Send(event=t.event, delay=f"{round(t.seconds * 1000)}ms", id=_id(s.name))


def cancel_of(s: State) -> Cancel | None:
    """The ``<cancel>`` that disarms it on exit."""
    return Cancel(sendid=_id(s.name)) if s.timeout is not None else None
