"""The Zenoh session of a node and the state message a device's snapshot travels in.

Kept apart from :mod:`statectl.distributed.wire` so that an operator station's view reads
state messages without the wire's streams.
"""

from __future__ import annotations

import json
import time
from typing import Any

from statectl.cell.nodes import Node
from statectl.journal.format import decode_snapshot, encode_snapshot
from statectl.semantics import Snapshot

__all__ = ["parse_snapshot", "session_config", "snapshot_payload"]

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
