"""The Zenoh session of a node and the messages on it: a device's state, a link event.

Kept apart from :mod:`statectl.channels.distributed.wire` so that an operator station's view reads
state messages without the wire's streams.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any

import msgspec

from statectl.cell.nodes import Node
from statectl.kernel.semantics import Snapshot
from statectl.run.journal.format import decode_snapshot, encode_snapshot

__all__ = [
    "LinkEvent",
    "decode_link",
    "encode_link",
    "parse_snapshot",
    "refuse_non_finite",
    "session_config",
    "snapshot_payload",
]

_ENC = json.JSONEncoder(separators=(",", ":"), allow_nan=False)


def session_config(node: Node) -> Any:
    """Rule 1: the Zenoh configuration of a node (peer, no multicast, its endpoints, lease)."""
    import zenoh

    c = zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "true")
    c.insert_json5("listen/endpoints", json.dumps(list(node.listen)))
    c.insert_json5("connect/endpoints", json.dumps(list(node.connect)))
    c.insert_json5("transport/link/tx/lease", str(max(50, int(node.lease * 1000))))
    c.insert_json5("transport/link/tx/keep_alive", "4")
    return c


def snapshot_payload(snapshot: Snapshot) -> bytes:
    """A device's state message: its snapshot and the wall time it was put (newest wins)."""
    t = time.time()
    active, history, previous = encode_snapshot(snapshot)
    return f'{{"a":{active},"h":{history},"p":{_ENC.encode(previous)},"t":{t}}}'.encode()


def parse_snapshot(payload: bytes) -> tuple[Snapshot, float]:
    """The snapshot and wall time of a state message (:func:`snapshot_payload`)."""
    msg = json.loads(payload)
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
