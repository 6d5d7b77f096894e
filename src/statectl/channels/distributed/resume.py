"""What a node's journal says of its links, read when the node opens (wire rule 6).

The epoch of its outbound streams (with the inbox position it started at), each inbound
stream's last accepted number, and, on ``--resume``, the link events its journal holds
for remote devices: they are sent again, numbered as before.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["EPOCH_KEY", "INBOUND_KEY", "Links", "read_links"]

#: The journal's meta key of the outbound epoch: ``"<epoch> <inbox seq at its start>"``.
EPOCH_KEY = "link-epoch"
#: The prefix of an inbound stream's meta key (``link-in/<node>/<device>``): ``"<e> <n>"``.
INBOUND_KEY = "link-in/"


@dataclass(frozen=True)
class Links:
    """What the journal holds: ``epoch`` only when resuming one, ``top`` the last inbox seq."""

    epoch: str | None = None
    top: int = 0
    backlog: dict[str, list[tuple[str, Any]]] = field(default_factory=dict)
    last: dict[tuple[str, str], tuple[str, int]] = field(default_factory=dict)


def read_links(path: Path | None, resume: bool, remote: Sequence[str]) -> Links:
    """Read the journal at ``path`` (absent or empty: nothing), read-only."""
    meta: dict[str, str] = {}
    top = 0
    backlog: dict[str, list[tuple[str, Any]]] = {}
    if path is not None and path.exists() and path.stat().st_size > 0:
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            meta = dict(db.execute("SELECT key, value FROM meta WHERE key LIKE 'link-%'"))
            top = int(db.execute("SELECT coalesce(max(seq), 0) FROM inbox").fetchone()[0])
            if resume and EPOCH_KEY in meta:
                base = meta[EPOCH_KEY].partition(" ")[2]
                marks = ",".join("?" * len(remote))
                rows = db.execute(
                    f"SELECT device, event, data FROM inbox WHERE seq > ? "
                    f"AND device IN ({marks}) ORDER BY seq",
                    (int(base or 0), *remote),
                )
                for device, event, data in rows:
                    backlog.setdefault(device, []).append((event, json.loads(data)))
        finally:
            db.close()
    last: dict[tuple[str, str], tuple[str, int]] = {}
    for key, value in meta.items():
        if key.startswith(INBOUND_KEY):
            node, _, device = key[len(INBOUND_KEY) :].partition("/")
            e, _, n = value.partition(" ")
            last[node, device] = (e, int(n))
    epoch = meta[EPOCH_KEY].partition(" ")[0] if resume and EPOCH_KEY in meta else None
    return Links(epoch, top, backlog, last)
