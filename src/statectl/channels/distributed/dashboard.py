"""The whole cell's dashboard, from Zenoh: on a node, or on a station with no devices.

Rules:
1. The dashboard is today's (statectl.channels.web: the page, its token, Origin and Host
   rules, its limits). A device of this node is its Subject; a device on another
   node is a :class:`MirrorSubject` that the states published on
   ``statectl/<cell>/state/<device>`` move, as ``exit``/``enter`` records.
2. Posting an event from the page needs the token, as today; an event for a
   device on another node is forwarded to that node (``statectl/<cell>/post/...``).
3. ``statectl dashboard CELL`` is an operator station: a
   :class:`~statectl.channels.distributed.view.CellView` and the page, no devices of its own.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, TextIO, cast

from statectl.cell.model import Cell
from statectl.kernel.errors import MissingExtra, StatectlError
from statectl.kernel.exits import OK
from statectl.kernel.model import Chart
from statectl.kernel.semantics import Snapshot
from statectl.run.runtime import Subject
from statectl.run.runtime.records import MicrostepTaken, Record, StepRecord

__all__ = ["MirrorSubject", "serve_cell"]


class MirrorSubject:
    """A device on another node as the page sees it: its published states, as records."""

    def __init__(self, name: str, chart: Chart) -> None:
        self.name = name
        self.chart = chart
        self.configuration: frozenset[str] = frozenset()
        self.events_processed = 0
        self.invokes_issued = 0
        self._listeners: list[Callable[[Record], object]] = []
        self._lock = threading.Lock()
        self._wall = 0.0

    def observer_for(self, number: int) -> None:
        return None

    def listen(self, callback: Callable[[Record], object]) -> Callable[[], None]:
        self._listeners.append(callback)
        return lambda: self._listeners.remove(callback)

    def listen_steps(self, callback: Callable[[StepRecord], object]) -> Callable[[], None]:
        """As :meth:`listen`, each record as a step record of its own (the dashboard
        hears steps; a mirror has no steps, only the states it was told)."""

        def one(record: Record) -> None:
            callback(StepRecord.of(record))

        return self.listen(one)

    def update(self, snapshot: Snapshot, wall: float) -> None:
        """Move to a published snapshot (newest wins): exits, then entries, as records."""
        with self._lock:
            if wall < self._wall:
                return
            self._wall = wall
            old, new = self.configuration, snapshot.active
            if old == new:
                return
            self.configuration = new
            self.events_processed += 1
            exited, entered = tuple(sorted(old - new)), tuple(sorted(new - old))
            records: list[Record] = [MicrostepTaken(self.name, wall, None, exited, (), entered)]
        for r in records:
            for listener in tuple(self._listeners):
                listener(r)


def serve_cell(
    cell: Cell,
    subjects: dict[str, Subject],
    on_state: list[Callable[[str, Snapshot, float], None]],
    post: Callable[[str | None, str, Any], Any],
    settings: tuple[str, int, str | None],
    streams: int | None = None,
) -> tuple[Any, str]:
    """Start the dashboard of the whole cell (rule 1); the started Dashboard and its URL."""
    try:
        from statectl.channels.web.app import Limits
        from statectl.channels.web.server import Dashboard
    except ImportError:
        raise MissingExtra("the dashboard", "aiohttp", "dashboard") from None
    mirrors = {
        d.name: MirrorSubject(d.name, d.chart) for d in cell.devices if d.name not in subjects
    }

    def moved(device: str, snapshot: Snapshot, wall: float) -> None:
        mirror = mirrors.get(device)
        if mirror is not None:
            mirror.update(snapshot, wall)

    on_state.append(moved)
    shown = [subjects.get(d.name) or cast(Subject, mirrors[d.name]) for d in cell.devices]
    limits = Limits() if streams is None else Limits(streams=streams)
    host, port, token = settings
    server = Dashboard(shown, post=post, token=token, limits=limits)
    return server, server.start(host, port)


def station(
    cell: Cell,
    *,
    connect: list[str] | None,
    settings: tuple[str, int, str | None],
    token_from: str,
    out: TextIO,
    stop: threading.Event,
    streams: int | None = None,
    ready: Callable[[str], object] | None = None,
    station: str | None = None,
) -> int:
    """Rule 3: an operator station's dashboard until ``stop``; the exit code."""
    from statectl.channels.distributed.view import CellView

    view = CellView(cell, connect, station=station)
    server = None
    try:
        view.open()

        def post(device: str | None, event: str, data: Any) -> None:
            if device is None:
                raise StatectlError("name the device: " + ", ".join(d.name for d in cell.devices))
            view.post(device, event, data)

        server, url = serve_cell(cell, {}, view.listeners, post, settings, streams)
        for device, snap in list(view.snapshots.items()):
            view.listeners[-1](device, snap, view.times.get(device, 0.0))
        view.refresh()
        shown = server.token if settings[2] is None else f"(from {token_from})"
        out.write(f"dashboard: {url}\ntoken: {shown}\n")
        out.flush()
        if ready is not None:
            ready(url)
        stop.wait()
        return OK
    finally:
        if server is not None:
            server.stop()
        view.close()
