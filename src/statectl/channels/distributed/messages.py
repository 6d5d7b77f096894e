"""The messages on a node's Zenoh session: a device's state, a link event.

Kept apart from :mod:`statectl.channels.distributed.wire` so that an operator station's view reads
state messages without the wire's streams.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from typing import Any

import msgspec

from statectl.channels.distributed.trust import (
    data_problem,
    name_problem,
    payload_problem,
    shown,
)
from statectl.kernel.semantics import Snapshot
from statectl.run.journal.format import decode_snapshot, encode_snapshot

__all__ = [
    "LinkEvent",
    "Unreadable",
    "decode_link",
    "encode_link",
    "parse_snapshot",
    "read_ack",
    "read_hello",
    "read_post",
    "refuse_non_finite",
    "snapshot_payload",
]

_ENC = json.JSONEncoder(separators=(",", ":"), allow_nan=False)
#: one JSON value at an index of a text: json.loads without its per-call checks (acks)
_scan: Callable[[str, int], tuple[Any, int]] = getattr(json.JSONDecoder(), "scan_once")  # noqa: B009


def snapshot_payload(snapshot: Snapshot) -> bytes:
    """A device's state message: its snapshot and the wall time it was put (newest wins)."""
    t = time.time()
    active, history, previous = encode_snapshot(snapshot)
    return f'{{"a":{active},"h":{history},"p":{_ENC.encode(previous)},"t":{t}}}'.encode()


class Unreadable(ValueError):
    """A message refused before anything acts on it; its text says why (printable)."""


def _bounded(payload: bytes) -> bytes:
    """Trust rule 3: a payload too long or nested too deep is not decoded at all."""
    problem = payload_problem(payload)
    if problem is not None:
        raise Unreadable(problem)
    return payload


def parse_snapshot(payload: bytes) -> tuple[Snapshot, float]:
    """The snapshot and wall time of a state message (:func:`snapshot_payload`)."""
    msg = json.loads(_bounded(payload))
    snap = decode_snapshot(json.dumps(msg["a"]), json.dumps(msg["h"]), msg["p"])
    return snap, float(msg.get("t", 0.0))


class LinkEvent(msgspec.Struct, array_like=True, frozen=True):
    """A link event on the wire: ``[e, n, ev, d]`` (epoch, number, event, data), JSON."""

    e: str
    n: int
    ev: str
    d: Any = None


_LINK = msgspec.json.Decoder(LinkEvent)
_LINK_OUT = msgspec.json.Encoder()


def decode_link(payload: bytes) -> LinkEvent:
    """A link event from its payload; ``msgspec.DecodeError`` when it is not one."""
    return _LINK.decode(payload)


def encode_link(epoch: str, n: int, event: str, data: Any) -> bytes:
    """``[e, n, ev, d]`` as JSON (msgspec: one call on the hot path)."""
    return _LINK_OUT.encode((epoch, n, event, data))


def read_ack(payload: bytes) -> tuple[str, int, bool]:
    """``{e, n, r}``: the epoch, how far the receiver got, whether to send the rest again."""
    try:
        msg = _scan(_bounded(payload).decode(), 0)[0]
        return str(msg["e"]), int(msg["n"]), bool(msg.get("r"))
    except Unreadable:
        raise
    except (ValueError, KeyError, TypeError, StopIteration, AttributeError):
        raise Unreadable("a payload that is not {e, n, r}") from None


def read_hello(payload: bytes) -> str:
    """``{e}``: the epoch a sender announces (streams rule 4); printable, 1-64 characters."""
    try:
        e = json.loads(_bounded(payload))["e"]
    except Unreadable:
        raise
    except (ValueError, KeyError, TypeError):
        raise Unreadable("a payload that is not {e}") from None
    if not isinstance(e, str) or not 0 < len(e) <= 64 or not e.isprintable():
        raise Unreadable(f"epoch {shown(str(e))} is no epoch")
    return e


def read_post(payload: bytes) -> tuple[str, Any]:
    """``{ev, d}``: an operator's event, its name bounded and printable (trust rule 3)."""
    try:
        msg = json.loads(_bounded(payload))
        event, data = msg["ev"], msg.get("d")
    except Unreadable:
        raise
    except (ValueError, KeyError, TypeError, AttributeError):
        raise Unreadable("a payload that is not {ev, d}") from None
    if not isinstance(event, str):
        raise Unreadable("an event name that is not text")
    problem = name_problem(event) or data_problem(data)
    if problem is not None:
        raise Unreadable(problem)
    return event, data


def refuse_non_finite(data: Any, device: str, event: str) -> None:
    """JSON has no NaN or infinity, and msgspec would send ``null``: refuse, as
    ``json`` with ``allow_nan=False`` does, before the event is numbered or kept."""
    values = [data]
    while values:
        value = values.pop()
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(
                f"link event {event!r} to {device!r}: its data holds {value!r}, which JSON "
                "cannot carry; send a finite number or a string"
            )
        if isinstance(value, dict):
            values.extend(value.values())
        elif isinstance(value, list | tuple):
            values.extend(value)
