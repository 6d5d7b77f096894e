"""The live dashboard: running devices' statecharts, event log and observer calls in a browser.

Rules:
1. Standard library only: one :class:`ThreadingHTTPServer` on a daemon thread,
   bound to 127.0.0.1 unless told otherwise; the page and its script ship in the
   package (``statectl/web/assets``) and diagrams are SVG rendered here, so the
   page works offline.
2. Live updates are Server-Sent Events (``GET /api/events``): a snapshot of every
   device first, then one message per trace record with the device's state after
   it. Records are turned into messages on the device's owner thread and queued
   per client (bounded; a slow client loses the oldest), so a browser never
   slows a device down.
3. Reading is open; posting an event (``POST /api/post``) needs the token printed
   at start-up (header ``X-Statectl-Token``) and a JSON body. A request whose
   ``Origin`` is not this server's, or whose ``Host`` is not an address the
   server answers on (DNS rebinding), is refused with 403.
4. With a journal the reply to a post comes once the event is durable and says
   so (``"durable": true``); without one the event is queued (``false``).
"""

from __future__ import annotations

import hmac
import json
import secrets
import threading
from collections import deque
from collections.abc import Callable, Iterable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib.resources import files
from typing import Any

from statectl.errors import StatectlError
from statectl.observers import extract
from statectl.render import render
from statectl.render.diagram import from_chart
from statectl.runtime.records import (
    FaultDetected,
    MonitorStarted,
    MonitorStopped,
    ObserverCalled,
    Record,
)
from statectl.runtime.subject import Subject
from statectl.runtime.trace import format_record, kind_of
from statectl.web.svg import fallback_svg

__all__ = ["LOG_SIZE", "Dashboard", "PostFn"]

#: Messages kept for a page that connects later, and per client queue.
LOG_SIZE = 500
#: ``post(device, event, data)``: returns a ticket-like object with ``seq`` and ``wait()``, or None.
PostFn = Callable[[str | None, str, Any], Any]

_ASSETS = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/static/app.js": ("app.js", "text/javascript; charset=utf-8"),
    "/static/style.css": ("style.css", "text/css; charset=utf-8"),
}
_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
        "connect-src 'self'; frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}


class _Client:
    """One SSE connection's queue."""

    def __init__(self) -> None:
        self.queue: deque[str] = deque(maxlen=LOG_SIZE)
        self.cond = threading.Condition()


class _Device:
    """What the page shows of one Subject, kept up to date by its records."""

    def __init__(self, subject: Subject) -> None:
        self.subject = subject
        chart = subject.chart
        diagram = from_chart(chart)
        self.ids = {n.name: n.id for n in diagram.nodes}
        self.monitors: dict[str, str] = {m.state: "idle" for m in extract(chart).monitors}
        self.calls = 0
        self.svg: str | None = None

    def state(self) -> dict[str, Any]:
        s = self.subject
        active = sorted(s.configuration)
        invokes = []
        for i in s.chart.invokes:
            observer = s.observer_for(i.number)
            invokes.append(
                {
                    "number": i.number,
                    "name": i.name,
                    "method": i.method,
                    "observer": type(observer).__name__ if observer is not None else None,
                }
            )
        return {
            "name": s.name,
            "chart": s.chart.name,
            "active": active,
            "active_ids": [self.ids[a] for a in active if a in self.ids],
            "events": list(s.chart.event_names),
            "invokes": invokes,
            "monitors": [{"state": k, "status": v} for k, v in self.monitors.items()],
            "events_processed": s.events_processed,
            "invokes_issued": s.invokes_issued,
            "observer_calls": self.calls,
        }

    def diagram(self) -> str:
        if self.svg is None:
            chart = self.subject.chart
            try:
                self.svg = render(chart, "svg")
            except StatectlError:  # no Graphviz: a plain layout drawn here
                self.svg = fallback_svg(from_chart(chart))
        return self.svg


class Dashboard:
    """Serve the dashboard for ``subjects``; ``post`` sends events (journalled or not)."""

    def __init__(
        self,
        subjects: Iterable[Subject],
        *,
        post: PostFn | None = None,
        token: str | None = None,
    ) -> None:
        self.devices = {s.name: _Device(s) for s in subjects}
        self.post = post
        self.token = token or secrets.token_urlsafe(18)
        self.log: deque[str] = deque(maxlen=LOG_SIZE)
        self._clients: set[_Client] = set()
        self._lock = threading.Lock()
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None
        self._unlisten = [s.listen(self._on_record) for s in self.devices_subjects()]
        self.stopping = threading.Event()
        self.origins: frozenset[str] = frozenset()
        self.hosts: frozenset[str] = frozenset()

    def devices_subjects(self) -> tuple[Subject, ...]:
        return tuple(d.subject for d in self.devices.values())

    # -- records -> messages (owner threads) ---------------------------------------------

    def _on_record(self, record: Record) -> None:
        device = self.devices.get(record.device)
        if device is None:
            return
        match record:
            case MonitorStarted(state=state):
                device.monitors[state] = "running"
            case MonitorStopped(state=state):
                device.monitors[state] = "idle"
            case FaultDetected(state=state, detail=detail):
                device.monitors[state] = f"fault: {detail}"
            case ObserverCalled():
                device.calls += 1
            case _:
                pass
        message = {
            "type": "record",
            "device": record.device,
            "time": record.time,
            "kind": kind_of(record),
            "text": format_record(record),
            "state": device.state(),
        }
        self.publish(json.dumps(message))

    def publish(self, text: str) -> None:
        """Queue ``text`` for every connected page and keep it for later ones."""
        with self._lock:
            self.log.append(text)
            clients = tuple(self._clients)
        for c in clients:
            with c.cond:
                c.queue.append(text)
                c.cond.notify()

    def snapshot(self) -> dict[str, Any]:
        return {
            "type": "snapshot",
            "devices": [d.state() for d in self.devices.values()],
            "writable": self.post is not None,
        }

    # -- serving -------------------------------------------------------------------------

    def start(self, host: str = "127.0.0.1", port: int = 0) -> str:
        """Serve on ``host:port`` (0: any free port) on a daemon thread; returns the URL."""
        if self._server is not None:
            raise StatectlError("the dashboard is running already")
        server = ThreadingHTTPServer((host, port), _handler(self))
        server.daemon_threads = True
        self._server = server
        bound = server.server_address[1]
        names = {host, "127.0.0.1", "localhost"} if host in ("127.0.0.1", "localhost") else {host}
        self.hosts = frozenset(f"{n}:{bound}" for n in names)
        self.origins = frozenset(f"http://{h}" for h in self.hosts)
        self._thread = threading.Thread(
            target=server.serve_forever, kwargs={"poll_interval": 0.2}, daemon=True,
            name="statectl-dashboard",
        )  # fmt: skip
        self._thread.start()
        return f"http://{host}:{bound}/"

    @property
    def port(self) -> int:
        if self._server is None:
            raise StatectlError("the dashboard is not running")
        return int(self._server.server_address[1])

    def stop(self) -> None:
        """Stop serving, end every event stream and stop listening to the devices."""
        self.stopping.set()
        for c in tuple(self._clients):
            with c.cond:
                c.cond.notify_all()
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        for unlisten in self._unlisten:
            unlisten()
        self._unlisten = []

    def subscribe(self) -> _Client:
        c = _Client()
        with self._lock:
            self._clients.add(c)
        return c

    def unsubscribe(self, c: _Client) -> None:
        with self._lock:
            self._clients.discard(c)

    def authorised(self, given: str | None) -> bool:
        return given is not None and hmac.compare_digest(given.encode(), self.token.encode())


def _asset(name: str) -> bytes:
    return (files("statectl.web") / "assets" / name).read_bytes()


def _handler(dash: Dashboard) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "statectl"
        sys_version = ""
        protocol_version = "HTTP/1.1"

        def log_message(self, format: str, *args: Any) -> None:
            pass  # the trace is the log; requests are not

        def _send(self, status: int, body: bytes, ctype: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            for k, v in _HEADERS.items():
                self.send_header(k, v)
            self.end_headers()
            self.wfile.write(body)

        def _json(self, status: int, value: Any) -> None:
            self._send(status, json.dumps(value).encode(), "application/json")

        def _guard(self) -> bool:
            """Rule 3: the Host must be ours and an Origin, if sent, must be ours."""
            host = self.headers.get("Host", "")
            if host not in dash.hosts:
                self._json(HTTPStatus.FORBIDDEN, {"error": f"host {host!r} is not served here"})
                return False
            origin = self.headers.get("Origin")
            if origin is not None and origin not in dash.origins:
                self._json(HTTPStatus.FORBIDDEN, {"error": f"origin {origin!r} is refused"})
                return False
            return True

        def do_GET(self) -> None:
            if not self._guard():
                return
            path = self.path.split("?", 1)[0]
            if path in _ASSETS:
                name, ctype = _ASSETS[path]
                self._send(HTTPStatus.OK, _asset(name), ctype)
            elif path == "/api/state":
                self._json(HTTPStatus.OK, dash.snapshot())
            elif path.startswith("/api/diagram/") and path.endswith(".svg"):
                from urllib.parse import unquote

                name = unquote(path[len("/api/diagram/") : -len(".svg")])
                device = dash.devices.get(name)
                if device is None:
                    self._json(HTTPStatus.NOT_FOUND, {"error": f"no device {name!r}"})
                else:
                    self._send(HTTPStatus.OK, device.diagram().encode(), "image/svg+xml")
            elif path == "/api/events":
                self._stream()
            else:
                self._json(HTTPStatus.NOT_FOUND, {"error": f"nothing at {path}"})

        def _stream(self) -> None:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.end_headers()
            client = dash.subscribe()
            try:
                with dash._lock:
                    backlog = list(dash.log)
                first = [json.dumps(dash.snapshot()), *backlog]
                self.wfile.write("".join(f"data: {m}\n\n" for m in first).encode())
                self.wfile.flush()
                while not dash.stopping.is_set():
                    with client.cond:
                        if not client.queue:
                            client.cond.wait(0.5)
                        batch = list(client.queue)
                        client.queue.clear()
                    if batch:
                        self.wfile.write("".join(f"data: {m}\n\n" for m in batch).encode())
                    else:
                        self.wfile.write(b": idle\n\n")
                    self.wfile.flush()
            except (BrokenPipeError, ConnectionResetError, OSError):
                pass
            finally:
                dash.unsubscribe(client)
                self.close_connection = True

        def do_POST(self) -> None:
            if not self._guard():
                return
            if self.path != "/api/post":
                self._json(HTTPStatus.NOT_FOUND, {"error": f"nothing to post at {self.path}"})
                return
            if dash.post is None:
                self._json(HTTPStatus.FORBIDDEN, {"error": "this dashboard is read-only"})
                return
            if not dash.authorised(self.headers.get("X-Statectl-Token")):
                self._json(
                    HTTPStatus.UNAUTHORIZED,
                    {"error": "posting needs the token printed at start-up (X-Statectl-Token)"},
                )
                return
            if self.headers.get("Content-Type", "").split(";")[0].strip() != "application/json":
                self._json(HTTPStatus.UNSUPPORTED_MEDIA_TYPE, {"error": "send application/json"})
                return
            try:
                length = int(self.headers.get("Content-Length", "0"))
                if not 0 < length <= 65536:
                    raise ValueError(f"body of {length} bytes")
                body = json.loads(self.rfile.read(length))
                if not isinstance(body, dict) or not isinstance(body.get("event"), str):
                    raise ValueError('the body is {"device": ..., "event": ..., "data": ...}')
                device = body.get("device")
                if device is not None and not isinstance(device, str):
                    raise ValueError("device must be a name")
                ticket = dash.post(device, body["event"], body.get("data"))
                durable = False
                seq = None
                if ticket is not None:
                    seq = ticket.seq
                    durable = bool(ticket.wait(5.0))
            except (ValueError, StatectlError) as exc:
                self._json(HTTPStatus.BAD_REQUEST, {"error": str(exc)})
                return
            self._json(HTTPStatus.OK, {"accepted": True, "seq": seq, "durable": durable})

    return Handler
