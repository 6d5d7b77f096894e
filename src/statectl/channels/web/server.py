"""The live dashboard: running devices' statecharts, event log and observer calls in a browser.

Rules:
1. The HTTP side is aiohttp (``statectl.channels.web.app``) on its own asyncio event loop in
   one daemon thread, bound to 127.0.0.1 unless told otherwise; the page and its
   script ship in the package (``statectl/channels/web/assets``) and diagrams are SVG
   rendered here, so the page works offline.
2. Live updates are Server-Sent Events (``GET /api/events``): a snapshot of every
   device first, then the recent log, then one message per trace record with what
   the step may have changed of the device's state (active states, monitors, counts;
   the chart's events and invokes are in the snapshot only).
3. A device never waits for a web client: on the device's owner thread a step is
   only noted (one step record, ``listen_steps``), with the device's active states,
   counts and monitors after it, in a list under a lock held for the append only
   (its typed records and their JSON are made on the loop);
   the first append since the last hand-over wakes the loop with one
   ``call_soon_threadsafe``. The loop waits ``Limits.gather`` (2 ms) so the records
   of one step travel together, then numbers the messages and writes them to every
   stream (``statectl.channels.web.stream``); a stream that falls behind is dropped.
4. If the loop falls more than ``PENDING_MAX`` messages behind the devices, the
   messages are discarded and every stream is dropped (each page reconnects and
   starts from a snapshot): no page ever sees a gap.
5. Reading is open; posting an event (``POST /api/post``) needs the token (printed
   at start-up, or the one given by --token, the environment or the config; the 401
   reply says which) and the ``Origin`` and ``Host`` rules of ``statectl.channels.web.app``.
   With a journal the reply to a post comes once the event is durable and says
   so (``"durable": true``); without one the event is queued (``false``). Given an
   ``origin``, every post carries it to the System's commands policy, whose refusal
   is a 403.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import hmac
import json
import logging
import secrets
import socket
import sys
import threading
from collections.abc import Callable, Iterable
from typing import Any

import msgspec
from aiohttp import web
from aiohttp.http_exceptions import HttpProcessingError

from statectl.channels.web.app import Limits, make_app
from statectl.channels.web.stream import Fanout
from statectl.channels.web.svg import fallback_svg
from statectl.front.observers import extract
from statectl.kernel.errors import StatectlError, did_you_mean
from statectl.kernel.text import shown
from statectl.out.render import render
from statectl.out.render.diagram import from_chart
from statectl.run.commands import Origin
from statectl.run.runtime.records import (
    FaultDetected,
    MonitorStarted,
    MonitorStopped,
    ObserverCalled,
    Record,
    StepRecord,
)
from statectl.run.runtime.subject import Subject
from statectl.run.runtime.trace import format_record, kind_of

__all__ = ["LOG_SIZE", "PENDING_MAX", "Dashboard", "PostFn"]

#: Messages kept for a page that connects later.
LOG_SIZE = 500
#: Messages the loop may lag behind the devices before every stream is dropped (rule 4).
PENDING_MAX = 20_000
#: ``post(device, event, data)``: returns a ticket-like object with ``seq`` and ``wait()``, or None.
PostFn = Callable[[str | None, str, Any], Any]


class _Noted(msgspec.Struct, frozen=True):
    """A record and the device's state after it, taken on the owner thread.

    A frozen ``msgspec`` struct: it is made on the device's thread, where a named
    tuple's Python constructor costs several times more (a frozen dataclass more still).
    """

    device: _Device
    record: Record
    configuration: frozenset[str]
    events: int
    invokes: int
    calls: int
    monitors: tuple[tuple[str, str], ...]

    def message(self) -> str:
        """The record as the page's JSON message (on the loop)."""
        record = self.record
        return json.dumps(
            {
                "type": "record",
                "device": record.device,
                "time": record.time,
                "kind": kind_of(record),
                "text": format_record(record),
                "state": self.device.render_live(
                    self.configuration, self.events, self.invokes, self.calls, self.monitors
                ),
            }
        )


class _Stepped(msgspec.Struct, frozen=True):
    """One event's step and the device's state after it, taken on the owner thread (a
    struct, as :class:`_Noted`); its typed records are built and turned into messages
    on the loop (rule 3)."""

    device: _Device
    step: StepRecord
    configuration: frozenset[str]
    events: int
    invokes: int
    calls: int
    monitors: tuple[tuple[str, str], ...]

    def messages(self) -> list[str]:
        """A message per record of the step, each with the state after the step."""
        c = self
        return [
            _Noted(c.device, r, c.configuration, c.events, c.invokes, c.calls, c.monitors).message()
            for r in self.step.records
        ]


class _Device:
    """What the page shows of one Subject, kept up to date by its records."""

    def __init__(self, subject: Subject) -> None:
        self.subject = subject
        chart = subject.chart
        diagram = from_chart(chart)
        self.ids = {n.name: n.id for n in diagram.nodes}
        self.monitors: dict[str, str] = {m.state: "idle" for m in extract(chart).monitors}
        self.monitor_items = tuple(self.monitors.items())  # what records carry, kept current
        self.calls = 0
        self.svg: str | None = None

    def state(self) -> dict[str, Any]:
        """Everything the page shows of the device (the snapshot's part)."""
        s = self.subject
        invokes = []
        for i in s.chart.invokes:
            observer = s.observer_for(i.number)
            invokes.append(
                {
                    "number": i.number,
                    "name": shown(i.name),
                    "method": shown(i.method),
                    "observer": type(observer).__name__ if observer is not None else None,
                }
            )
        return {
            **self.live(),
            "chart": s.chart.name,
            "events": list(s.chart.event_names),
            "events_shown": [shown(e) for e in s.chart.event_names],
            "invokes": invokes,
        }

    def live(self) -> dict[str, Any]:
        """What a step may change (a record's part; the page merges it into the snapshot's)."""
        s = self.subject
        return self.render_live(
            s.configuration, s.events_processed, s.invokes_issued, self.calls,
            self.monitor_items,
        )  # fmt: skip

    def render_live(
        self,
        configuration: frozenset[str],
        events: int,
        invokes: int,
        calls: int,
        monitors: tuple[tuple[str, str], ...],
    ) -> dict[str, Any]:
        active = sorted(configuration)
        return {
            "name": self.subject.name,
            "active": active,
            "active_ids": [self.ids[a] for a in active if a in self.ids],
            # what the page prints: names as kernel.text.shown writes them (keys stay raw)
            "shown": {"name": shown(self.subject.name), "active": [shown(a) for a in active]},
            "monitors": [{"state": shown(k), "status": shown(v)} for k, v in monitors],
            "events_processed": events,
            "invokes_issued": invokes,
            "observer_calls": calls,
        }

    def diagram(self) -> str:
        if self.svg is None:
            chart = self.subject.chart
            try:
                self.svg = render(chart, "svg")
            except StatectlError:  # no Graphviz: a plain layout drawn here
                self.svg = fallback_svg(from_chart(chart))
        return self.svg


class _HttpLog(logging.Logger):
    """aiohttp's connection log: a client's fault is one debug line, not a traceback.

    Malformed requests (aiohttp answers 400 and closes) and connections that go away
    are the client's doing; any other exception is a bug here and keeps its traceback.
    """

    def exception(self, msg: object, *args: object, exc_info: Any = True, **kw: Any) -> None:
        exc = exc_info if isinstance(exc_info, BaseException) else sys.exc_info()[1]
        if isinstance(exc, HttpProcessingError | ConnectionError | asyncio.CancelledError):
            self.debug("%s: %s", str(msg) % args if args else msg, exc)
        else:
            super().exception(msg, *args, exc_info=exc_info, **kw)


_LOG = _HttpLog("statectl.channels.web.http")
_LOG.parent = logging.getLogger("statectl.channels.web")


class Dashboard:
    """Serve the dashboard for ``subjects``; ``post`` sends events (journalled or not)."""

    def __init__(
        self,
        subjects: Iterable[Subject],
        *,
        post: PostFn | None = None,
        token: str | None = None,
        limits: Limits | None = None,
        origin: Origin | None = None,
        token_from: str | None = None,
    ) -> None:
        self.devices = {s.name: _Device(s) for s in subjects}
        #: rule 5: ``origin`` is passed with every post, for the System's commands policy
        send: Callable[..., Any] | None = post  # a System's post takes the origin too
        if send is not None and origin is not None:
            send = functools.partial(send, origin=origin)
        self.post: PostFn | None = send
        self.token = token or secrets.token_urlsafe(18)
        #: Where the token comes from, as the 401 reply says it (rule 5).
        self.token_source = (
            "printed at start-up"
            if not token
            else f"set by {token_from or '--token, $STATECTL_DASHBOARD_TOKEN or the config'}"
        )
        self.limits = limits or Limits()
        self.origins: frozenset[str] = frozenset()
        self.hosts: frozenset[str] = frozenset()
        self._lock = threading.Lock()
        self._pending: list[str | _Noted | _Stepped] = []
        self._overrun = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake_sent = False
        self._thread: threading.Thread | None = None
        self._stop: asyncio.Event | None = None
        self._port = 0
        self.fanout = Fanout(
            streams=self.limits.streams, buffer=self.limits.stream_buffer, log_size=LOG_SIZE
        )
        self._unlisten = [d.subject.listen_steps(self._on_step) for d in self.devices.values()]

    def devices_subjects(self) -> tuple[Subject, ...]:
        return tuple(d.subject for d in self.devices.values())

    # -- records -> messages (owner threads) ---------------------------------------------

    def _on_step(self, step: StepRecord) -> None:
        """On the owner thread: note the step and what the device is after it (rule 3).

        Only values are taken here (the step record, the active states, the counts):
        its typed records are built and turned into JSON on the loop, so a step costs
        the device one step record and one struct.
        """
        device = self.devices.get(step.device)
        if device is None:
            return
        if step.event is None:  # a record made outside any event: noted as it is
            for record in step.records:
                self._on_record(device, record)
            return
        for record in step.meanwhile:
            self._watch(device, record)
        device.calls += step.api_calls
        s = device.subject
        self._hand(
            _Stepped(
                device, step, s.configuration, s.events_processed, s.invokes_issued,
                device.calls, device.monitor_items,
            )
        )  # fmt: skip

    @staticmethod
    def _watch(device: _Device, record: Record) -> None:
        """Keep the device's monitors and API call count up to date with ``record``."""
        match record:
            case MonitorStarted(state=state):
                device.monitors[state] = "running"
                device.monitor_items = tuple(device.monitors.items())
            case MonitorStopped(state=state):
                device.monitors[state] = "idle"
                device.monitor_items = tuple(device.monitors.items())
            case FaultDetected(state=state, detail=detail):
                device.monitors[state] = f"fault: {detail}"
                device.monitor_items = tuple(device.monitors.items())
            case ObserverCalled():
                device.calls += 1
            case _:
                pass

    def _on_record(self, device: _Device, record: Record) -> None:
        """On the owner thread: note one record and what the device is after it."""
        self._watch(device, record)
        s = device.subject
        self._hand(
            _Noted(
                device, record, s.configuration, s.events_processed, s.invokes_issued,
                device.calls, device.monitor_items,
            )
        )  # fmt: skip

    def publish(self, text: str) -> None:
        """Hand ``text`` to every connected page and keep it for later ones (rule 3).

        Any thread may call this; it never blocks on the network.
        """
        self._hand(text)

    def _hand(self, item: str | _Noted | _Stepped) -> None:
        with self._lock:
            self._pending.append(item)
            loop = self._loop
            if loop is None:  # not serving: only the log for later pages matters
                if len(self._pending) >= 2 * LOG_SIZE:  # cut back now and then, not per step
                    del self._pending[:-LOG_SIZE]
                return
            if len(self._pending) > PENDING_MAX:  # rule 4
                self._pending.clear()
                self._overrun = True
            if self._wake_sent:
                return
            self._wake_sent = True
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(self._gather, loop)

    def _gather(self, loop: asyncio.AbstractEventLoop) -> None:
        """On the loop: hand over once the step that woke it has likely said everything."""
        loop.call_later(self.limits.gather, self._hand_over)

    def _hand_over(self) -> None:
        """On the loop: take every pending message and send it to every stream."""
        with self._lock:
            items, self._pending = self._pending, []
            overrun, self._overrun = self._overrun, False
            self._wake_sent = False
        if overrun:
            self.fanout.drop_all("overrun")
        messages: list[str] = []
        for i in items:
            if isinstance(i, str):
                messages.append(i)
            elif isinstance(i, _Noted):
                messages.append(i.message())
            else:
                messages.extend(i.messages())
        self.fanout.publish(messages)

    def snapshot(self) -> dict[str, Any]:
        return {
            "type": "snapshot",
            "devices": [d.state() for d in self.devices.values()],
            "writable": self.post is not None,
        }

    # -- serving -------------------------------------------------------------------------

    def start(self, host: str = "127.0.0.1", port: int = 0) -> str:
        """Serve on ``host:port`` (0: any free port) on a daemon thread; returns the URL.

        The socket is bound here, so an address in use raises ``OSError`` to the caller.
        """
        if self._thread is not None:
            raise StatectlError("the dashboard is running already")
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        sock = socket.create_server((host, port), family=family, backlog=self.limits.backlog)
        bound = int(sock.getsockname()[1])
        self._port = bound
        shown = f"[{host}]" if ":" in host else host  # an IPv6 address in a URL or Host
        names = {host, "127.0.0.1", "localhost"} if host in ("127.0.0.1", "localhost") else {shown}
        self.hosts = frozenset(f"{n}:{bound}" for n in names)
        self.origins = frozenset(f"http://{h}" for h in self.hosts)
        ready = threading.Event()
        failure: list[BaseException] = []
        self._thread = threading.Thread(
            target=self._serve, args=(sock, ready, failure), daemon=True,
            name="statectl-dashboard",
        )  # fmt: skip
        self._thread.start()
        ready.wait(10.0)
        if failure:
            self._thread.join(2.0)
            self._thread = None
            raise StatectlError(f"the dashboard did not start: {failure[0]}")
        return f"http://{shown}:{bound}/"

    def _serve(
        self, sock: socket.socket, ready: threading.Event, failure: list[BaseException]
    ) -> None:
        loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._main(loop, sock, ready))
        except Exception as exc:  # reported to start(); the devices go on
            failure.append(exc)
        finally:
            with self._lock:
                self._loop = None
            loop.run_until_complete(loop.shutdown_default_executor())
            loop.close()
            sock.close()
            ready.set()

    async def _main(
        self, loop: asyncio.AbstractEventLoop, sock: socket.socket, ready: threading.Event
    ) -> None:
        limits = self.limits
        runner = web.AppRunner(
            make_app(self, self.fanout, limits),
            handle_signals=False,
            access_log=None,
            logger=_LOG,
            keepalive_timeout=limits.idle_timeout,
            lingering_time=limits.linger,
            handler_cancellation=True,  # a page that goes away ends its handler
            shutdown_timeout=2.0,
        )
        await runner.setup()
        site = web.SockSite(runner, sock)
        await site.start()
        self._stop = asyncio.Event()
        with self._lock:
            self._loop = loop
            self._wake_sent = True
        self._hand_over()  # what the devices said before the server ran
        ready.set()
        beat = loop.create_task(self._heartbeat(limits.heartbeat))
        try:
            await self._stop.wait()
        finally:
            beat.cancel()
            with self._lock:
                self._loop = None
            for stream in tuple(self.fanout.streams):
                stream.end("stopping")
            await asyncio.sleep(0)  # let the stream handlers return their responses
            await runner.cleanup()

    async def _heartbeat(self, every: float) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(every)
            self.fanout.heartbeat(loop.time(), self.limits.stall_timeout)

    @property
    def port(self) -> int:
        if self._thread is None:
            raise StatectlError("the dashboard is not running")
        return self._port

    def stop(self) -> None:
        """Stop serving, end every event stream and stop listening to the devices."""
        thread, self._thread = self._thread, None
        with self._lock:
            loop = self._loop
        if loop is not None and self._stop is not None:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self._stop.set)
        if thread is not None:
            thread.join(10.0)
        for unlisten in self._unlisten:
            unlisten()
        self._unlisten = []

    def unknown_event(self, device: str | None, event: str) -> str | None:
        """Why ``event`` cannot go to ``device``: its chart does not know it; else None.

        A device that is not named (several devices) or not served is left to ``post``,
        which says so.
        """
        if device is None:
            entry = next(iter(self.devices.values())) if len(self.devices) == 1 else None
        else:
            entry = self.devices.get(device)
        if entry is None:
            return None
        names = entry.subject.chart.event_names
        if event in names:
            return None
        maybe = did_you_mean(event, names)
        return f"{entry.subject.name} has no event {event!r}; {maybe}its events: {', '.join(names)}"

    def authorised(self, given: str | None) -> bool:
        """The token's bytes compared in constant time; a header of bytes that are not
        UTF-8 (aiohttp keeps them as surrogates) is compared as sent, never a 500."""
        if given is None:
            return False
        sent = given.encode("utf-8", "surrogateescape")
        return hmac.compare_digest(sent, self.token.encode("utf-8", "surrogateescape"))
