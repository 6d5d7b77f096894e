"""The whole cell as its nodes publish it, for a process with no devices of its own.

An operator station's dashboard, a test or a monitoring script opens a
:class:`CellView`: a Zenoh session (peer mode, multicast scouting off) that
connects to the nodes' endpoints, keeps each device's last published snapshot
and which nodes are present, and may post events to any device (forwarded to
its node, as a node does for a device it does not run).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from statectl.cell.model import Cell
from statectl.channels.distributed.keys import Keys
from statectl.channels.distributed.messages import parse_snapshot
from statectl.channels.distributed.trust import session_config
from statectl.kernel.errors import StatectlError, did_you_mean
from statectl.kernel.semantics import Snapshot

__all__ = ["CellView"]


class CellView:
    """Each device's last published snapshot and the nodes present, live from Zenoh."""

    def __init__(
        self, cell: Cell, connect: Sequence[str] | None = None, *, station: str | None = None
    ) -> None:
        if cell.nodes is None:
            raise StatectlError(f"{cell.path}: the cell has no nodes: section")
        stations = cell.nodes.security.stations
        if cell.nodes.security.authenticated and station not in stations:
            raise StatectlError(
                f"{cell.path}: the cell's nodes authenticate their peers: name this station "
                f"(--as NAME, one of security: stations: {', '.join(stations) or 'none declared'})"
            )
        self.station = station or "station"
        self.cell = cell
        self._devices = {d.name for d in cell.devices}
        self.keys = Keys(cell.name)
        if connect is None:
            connect = [e for n in cell.nodes.nodes for e in n.listen]
        self.connect = tuple(connect)
        self.snapshots: dict[str, Snapshot] = {}
        self.times: dict[str, float] = {}
        self.nodes: set[str] = set()
        self.listeners: list[Callable[[str, Snapshot, float], None]] = []
        self._changed = threading.Condition()
        self._session: Any = None
        self._decls: list[Any] = []

    def open(self) -> CellView:
        import zenoh

        c = session_config(self.cell, self.station, listen=(), connect=self.connect)
        self._session = s = zenoh.open(c)
        root = self.keys.root
        self._decls = [
            s.declare_subscriber(f"{root}/state/*", self._on_state),
            s.liveliness().declare_subscriber(f"{root}/node/*", self._on_node, history=True),
        ]
        self.refresh()
        return self

    def refresh(self) -> None:
        """Ask every node for its devices' states now (a late joiner's first look)."""
        if self._session is not None:
            self._session.get(f"{self.keys.root}/state/*", self._on_reply)

    def close(self) -> None:
        if self._session is not None:
            session, self._session = self._session, None
            session.close()

    def __enter__(self) -> CellView:
        return self.open()

    def __exit__(self, *_: object) -> None:
        self.close()

    def post(self, device: str, event: str, data: Any = None) -> None:
        """Send ``event`` to ``device`` on whichever node runs it."""
        names = [d.name for d in self.cell.devices]
        if device not in names:
            maybe = did_you_mean(device, names)
            raise StatectlError(
                f"no device {device!r} in {self.cell.name}; {maybe}devices: {', '.join(names)}"
            )
        if self._session is None:
            raise StatectlError("the view is not open")
        self._session.put(self.keys.post(device), json.dumps({"ev": event, "d": data}))

    def active(self) -> dict[str, frozenset[str]]:
        with self._changed:
            return {d: s.active for d, s in self.snapshots.items()}

    def wait_for(
        self, check: Callable[[Mapping[str, frozenset[str]]], bool], timeout: float
    ) -> bool:
        """Block until ``check(active states)`` holds (True) or ``timeout`` passes (False)."""
        end = time.monotonic() + timeout
        with self._changed:
            while not check({d: s.active for d, s in self.snapshots.items()}):
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._changed.wait(min(left, 0.5))
                if self.nodes and len(self.snapshots) < len(self.cell.devices):
                    self.refresh()
        return True

    def _on_state(self, sample: Any) -> None:
        _, device = Keys.last(sample.key_expr)
        if device not in self._devices:  # only the cell's devices are kept and shown
            return
        try:  # a payload too long or too deep is dropped before it is decoded (Unreadable)
            snap, t = parse_snapshot(sample.payload.to_bytes())
        except (ValueError, KeyError, TypeError):
            return
        with self._changed:
            if t < self.times.get(device, 0.0):
                return  # a reply older than an update already seen
            self.snapshots[device] = snap
            self.times[device] = t
            self._changed.notify_all()
        for listener in self.listeners:
            listener(device, snap, t)

    def _on_reply(self, reply: Any) -> None:
        if reply.ok is not None:
            self._on_state(reply.ok)

    def _on_node(self, sample: Any) -> None:
        import zenoh

        _, node = Keys.last(sample.key_expr)
        with self._changed:
            if sample.kind == zenoh.SampleKind.PUT:
                self.nodes.add(node)
            else:
                self.nodes.discard(node)
            self._changed.notify_all()
        if sample.kind == zenoh.SampleKind.PUT:
            self.refresh()  # a node (re)started: its devices may be elsewhere than last heard
