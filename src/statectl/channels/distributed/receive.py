"""The receiving end of one link stream: the hot path of a link event (wire rules 3-4, 7).

Rule 7 (what a stream accepts): a link stream ``node`` -> ``device`` takes only
the events the cell's links from ``node``'s devices (and the invariants ``node``
watches) send to ``device`` (:func:`statectl.channels.distributed.trust.carried`),
with data only where such a link sends some, and that data's text printable;
its payload is bounded in size and nesting before it is decoded; its epoch must be
the stream's or one a hello announced, its number in range
(statectl.channels.distributed.streams rule 4). Anything else is refused: one line
in the node's log, a note in its journal, nothing applied, the stream's position
kept. Which node may put on the stream's key at all is Zenoh's access control
(trust rule 2), when the cell authenticates its nodes. An event the stream accepts
enters at the System's one door (``System.submit``, origin ``link`` and the sending
node), which runs it on this thread while nobody owns the devices; a refusal of the
commands policy is one log line and a ``refused`` step, nothing applied.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import msgspec

from statectl.channels.distributed.messages import decode_link
from statectl.channels.distributed.resume import INBOUND_KEY
from statectl.channels.distributed.streams import MAX_NUMBER, Verdict
from statectl.channels.distributed.trust import data_problem, payload_problem, printable, shown
from statectl.kernel.errors import StatectlError
from statectl.run.commands import Origin

if TYPE_CHECKING:
    from statectl.channels.distributed.wire import Wire

__all__ = ["REFUSED_KEY", "refuse", "stream_receiver"]

#: The journal's meta keys of refused messages: ``zenoh-refused/NN`` and the run's count.
REFUSED_KEY = "zenoh-refused/"


def refuse(
    wire: Wire, key: str, reason: str, device: str | None = None, event: str | None = None
) -> None:
    """Rule 7: one log line and a journal note (the run's last 100); an event ``device``
    knows is a ``refused`` step in its journal too, as the System's door writes one."""
    wire.refused += 1
    text = f"refused on {key}: {reason}"
    wire._say(text)
    journal = wire.system.journal
    if journal is None:
        return
    journal.note(f"{REFUSED_KEY}{wire.refused % 100:02d}", f"{time.time():.3f} {printable(text)}")
    journal.note(REFUSED_KEY.rstrip("/"), str(wire.refused))
    bound = wire.system.bound.get(device) if device is not None else None
    if bound is not None and event in bound.subject.chart.event_names:
        with wire.system.owner:  # between the device's steps, as the door does
            bound.refused(event, None, printable(f"zenoh {key}: {reason}"))


def stream_receiver(
    wire: Wire, node: str, device: str, events: dict[str, bool]
) -> Callable[[Any], None]:
    """The subscriber of one stream: everything per stream is looked up once here (the
    key is known, so only the payload is parsed; the device, its journal binding, the
    stream's inbound note, the events the stream carries)."""
    decode = decode_link
    inbound = wire.inbound
    lock = inbound.lock
    offer = inbound.offer
    system = wire.system
    bound = system.bound.get(device)
    note = f"{INBOUND_KEY}{node}/{device}"
    ack = wire._ack
    wake = wire._wake
    submit = system.submit  # the System's one door (statectl.run.system rule 8)
    origin = Origin("link", node)  # the commands policy's link grants
    key = wire.keys.link(node, device)

    def refused(reason: str, event: str) -> None:  # a refused step too, if the device knows it
        refuse(wire, key, reason, device, event)

    def why(e: str, n: int) -> str:
        if not 1 <= n <= MAX_NUMBER:
            return f"a number is 1 to {MAX_NUMBER}"
        return "an epoch changes only after a hello names it"

    def on_link(sample: Any) -> None:
        payload = sample.payload.to_bytes()
        problem = payload_problem(payload)
        if problem is not None:
            refuse(wire, key, problem)
            return
        try:
            msg = decode(payload)
        except (msgspec.DecodeError, AttributeError):
            refuse(wire, key, "a payload that is not [epoch, number, event, data]")
            return
        e, n, event = msg.e, msg.n, msg.ev
        with_data = events.get(event)
        if with_data is None:  # rule 7: only what a link from that node carries
            refused(f"event {shown(event)}: no link from {node} sends it to {device}", event)
            return
        if msg.d is not None:
            problem = data_problem(msg.d) if with_data else "data, which no link sends with it"
            if problem is not None:
                refused(f"event {shown(event)} with {problem}", event)
                return
        with lock:
            verdict, last = offer(node, device, e, n)
            if verdict is Verdict.DUPLICATE or verdict is Verdict.GAP:
                ack(node, device, e, last, verdict is Verdict.GAP)
                wake.set()
                return
            if verdict is Verdict.APPLY:
                try:  # under the lock: the stream's next event waits until this one ran
                    if bound is not None:  # acknowledged once committed (_committed)
                        ticket = submit(
                            device, event, msg.d, origin=origin, note=(note, f"{e} {n}")
                        )
                        assert ticket.ticket is not None
                        wire._acks.append((ticket.ticket.seq, node, device, e, n))
                    else:  # run here by the door if nobody owns the devices, else queued
                        submit(device, event, msg.d, origin=origin)
                except StatectlError as exc:  # a refusal too: dropped, one line (journalled)
                    wire._say(f"link event {shown(event)} from {node} to {device}: {exc}")
        if verdict is Verdict.REFUSED:  # out of the stream's lock: its journal row takes the owner
            refused(f"{shown(event)} numbered {n} in epoch {shown(e)}: {why(e, n)}", event)
            return
        if bound is None:
            ack(node, device, e, n, False)
            if not wake.is_set():
                wake.set()

    return on_link
