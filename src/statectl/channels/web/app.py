"""The dashboard's HTTP surface as an aiohttp application.

Rules:
1. Every request passes the guard first: exactly one ``Host`` header (else 400),
   naming an address this server answers on (else 403, DNS rebinding); a request
   target that is a path, or an absolute ``http://`` URL naming that same host
   (else 400: ``GET http://evil.example/api/state``); at most one ``Origin``, and
   it must be ours (else 403).
2. A refused request (any status >= 400) closes its connection, so a body it did
   not read is never taken for a second request.
3. ``POST /api/post``: the token (``X-Statectl-Token``, 401), a JSON content type
   (415), a body of at most ``Limits.body`` bytes (413) that arrives within
   ``Limits.body_timeout`` (408) and parses to ``{"event": ...}`` (400, also for
   nesting too deep to parse), naming an event the device's chart knows (422,
   with the events it knows). The event is handed to ``post`` on a worker
   thread, so a journal's wait for durability never blocks the loop; an event the
   System's commands policy refuses gets 403.
4. ``GET /api/events`` beyond ``Limits.streams`` open streams gets 503 with
   ``Retry-After``.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from http import HTTPStatus
from importlib.resources import files
from typing import TYPE_CHECKING, Any

from aiohttp import web
from aiohttp.typedefs import Middleware

from statectl.channels.web.stream import Fanout
from statectl.kernel.errors import StatectlError
from statectl.run.commands import CommandRefused

if TYPE_CHECKING:
    from statectl.channels.web.server import Dashboard

__all__ = ["Limits", "make_app"]

_ASSETS = {
    "/": ("index.html", "text/html"),
    "/static/app.js": ("app.js", "text/javascript"),
    "/static/style.css": ("style.css", "text/css"),
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
_BODY_SHAPE = 'the body is {"device": ..., "event": ..., "data": ...}'


@dataclass(frozen=True)
class Limits:
    """What one client may hold; the defaults suit a control room, tests shrink them."""

    #: Concurrent event streams; one more gets 503.
    streams: int = 1000
    #: Largest request body in bytes; a larger one gets 413.
    body: int = 65536
    #: Seconds a connection may sit without a complete request (idle keep-alive or slow headers).
    idle_timeout: float = 15.0
    #: Seconds a request body may take to arrive; a slower one gets 408.
    body_timeout: float = 10.0
    #: Bytes queued for one stream before it is dropped as too slow.
    stream_buffer: int = 1 << 20
    #: Seconds between keep-alive comments on an otherwise quiet stream (and stall checks).
    heartbeat: float = 15.0
    #: Seconds an event stream may leave bytes waiting at every check before it is dropped.
    stall_timeout: float = 60.0
    #: Pending connections the kernel keeps before accept.
    backlog: int = 1024
    #: Seconds a refused request's unread body is read and thrown away before its connection
    #: closes (closing at once could reset the connection before the refusal is read).
    linger: float = 2.0
    #: Seconds the loop waits after a device's first new record before sending, so that the
    #: records of one step go to each stream in one write.
    gather: float = 0.002
    #: Seconds a post waits for its journal to make the event durable.
    durable_wait: float = 5.0


def _refuse(status: int, message: str, **headers: str) -> web.Response:
    """Rule 2: a JSON error and ``Connection: close``."""
    response = web.json_response({"error": message}, status=status, headers=headers)
    response.force_close()
    return response


def _target_names(target: str, host: str) -> bool:
    """Whether a request target is ours: origin-form (a path), or absolute-form naming
    ``http://`` and the very authority of the Host header (RFC 9112 3.2.2); aiohttp takes
    an absolute target's authority as the request's host, so a foreign one is refused."""
    if target.startswith("/"):
        return True
    scheme, sep, rest = target.partition("://")
    authority = rest.split("/", 1)[0].split("?", 1)[0]
    return bool(sep) and scheme.lower() == "http" and authority.lower() == host.lower()


def _asset(name: str) -> bytes:
    return (files("statectl.channels.web") / "assets" / name).read_bytes()


Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


def make_app(dash: Dashboard, fanout: Fanout, limits: Limits) -> web.Application:
    """The routes for ``dash``; ``fanout`` lives on the same loop as the app."""

    guard = _guard(dash)

    async def headers(request: web.Request, response: web.StreamResponse) -> None:
        for k, v in _HEADERS.items():
            response.headers.setdefault(k, v)
        response.headers["Server"] = "statectl"

    async def asset(request: web.Request) -> web.Response:
        name, ctype = _ASSETS[request.path]
        return web.Response(body=_asset(name), content_type=ctype, charset="utf-8")

    async def state(request: web.Request) -> web.Response:
        return web.json_response(dash.snapshot())

    async def diagram(request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        device = dash.devices.get(name)
        if device is None:
            return _refuse(HTTPStatus.NOT_FOUND, f"no device {name!r}")
        loop = asyncio.get_running_loop()
        svg = await loop.run_in_executor(None, device.diagram)  # Graphviz runs a process
        return web.Response(text=svg, content_type="image/svg+xml")

    async def events(request: web.Request) -> web.StreamResponse:
        loop = asyncio.get_running_loop()
        stream = fanout.admit(loop)
        if stream is None:
            return _refuse(
                HTTPStatus.SERVICE_UNAVAILABLE,
                f"{fanout.cap} event streams are open already; try again later",
                **{"Retry-After": "5"},
            )
        try:
            response = web.StreamResponse(
                headers={"Content-Type": "text/event-stream", "X-Accel-Buffering": "no"}
            )
            response.enable_chunked_encoding()  # stream.py frames each batch as one chunk
            await response.prepare(request)
            transport = request.transport
            if transport is None or transport.is_closing():
                return response
            first = b"data: %s\n\n" % json.dumps(dash.snapshot()).encode()
            fanout.start(stream, transport, first)
            await stream.closed
            return response
        finally:
            fanout.leave(stream)

    post = _post(dash, limits)

    app = web.Application(middlewares=[guard], client_max_size=limits.body)
    app.on_response_prepare.append(headers)
    for path in _ASSETS:
        app.router.add_get(path, asset)
    app.router.add_get("/api/state", state)
    app.router.add_get(r"/api/diagram/{name:.+}.svg", diagram)
    app.router.add_get("/api/events", events)
    app.router.add_post("/api/post", post)
    return app


def _guard(dash: Dashboard) -> Middleware:
    """The middleware every request passes: one Host we serve, an Origin we trust (no
    DNS rebinding, no cross-site posts), and aiohttp's own errors in our shape."""

    @web.middleware
    async def guard(request: web.Request, handler: Handler) -> web.StreamResponse:
        hosts = request.headers.getall("Host", [])
        if len(hosts) != 1:
            return _refuse(HTTPStatus.BAD_REQUEST, "a request has exactly one Host header")
        if hosts[0] not in dash.hosts:
            return _refuse(HTTPStatus.FORBIDDEN, f"host {hosts[0]!r} is not served here")
        if not _target_names(request.raw_path, hosts[0]):
            return _refuse(
                HTTPStatus.BAD_REQUEST, "the request target names another host than Host"
            )
        origins = request.headers.getall("Origin", [])
        if len(origins) > 1 or (origins and origins[0] not in dash.origins):
            return _refuse(HTTPStatus.FORBIDDEN, f"origin {', '.join(origins)!r} is refused")
        try:
            response = await handler(request)
        except web.HTTPException as exc:  # 404, 405, 413 from aiohttp: same shape as ours
            allow = {"Allow": exc.headers["Allow"]} if "Allow" in exc.headers else {}
            return _refuse(exc.status, exc.reason, **allow)
        if response.status >= 400:
            response.force_close()
        return response

    return guard


def _post(dash: Dashboard, limits: Limits) -> Handler:
    """``POST /api/post``: an event for the System, refused unless writable, authorised,
    JSON, within the body limits, naming a known event and allowed by the commands policy."""

    async def post(request: web.Request) -> web.StreamResponse:
        send = dash.post
        if send is None:
            return _refuse(HTTPStatus.FORBIDDEN, "this dashboard is read-only")
        if not dash.authorised(request.headers.get("X-Statectl-Token")):
            return _refuse(
                HTTPStatus.UNAUTHORIZED,
                f"posting needs the token {dash.token_source} (X-Statectl-Token)",
            )
        if request.content_type != "application/json":
            return _refuse(HTTPStatus.UNSUPPORTED_MEDIA_TYPE, "send application/json")
        length = request.content_length
        if length is not None and length > limits.body:
            return _refuse(
                HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"a body is at most {limits.body} bytes"
            )
        try:
            raw = await asyncio.wait_for(request.read(), limits.body_timeout)
        except web.HTTPRequestEntityTooLarge:
            return _refuse(
                HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"a body is at most {limits.body} bytes"
            )
        except TimeoutError:
            return _refuse(
                HTTPStatus.REQUEST_TIMEOUT, f"the body did not arrive in {limits.body_timeout} s"
            )
        try:
            device, event, data = _parse(raw)
        except ValueError as exc:
            return _refuse(HTTPStatus.BAD_REQUEST, str(exc))
        unknown = dash.unknown_event(device, event)
        if unknown is not None:
            return _refuse(HTTPStatus.UNPROCESSABLE_ENTITY, unknown)
        loop = asyncio.get_running_loop()
        try:
            seq, durable = await loop.run_in_executor(
                None, _deliver, send, device, event, data, limits.durable_wait
            )
        except CommandRefused as exc:  # the System's commands policy (run/commands.py)
            return _refuse(HTTPStatus.FORBIDDEN, str(exc))
        except StatectlError as exc:
            return _refuse(HTTPStatus.BAD_REQUEST, str(exc))
        return web.json_response({"accepted": True, "seq": seq, "durable": durable})

    return post


def _parse(raw: bytes) -> tuple[str | None, str, Any]:
    """``(device, event, data)`` from a post's body; ValueError says what is wrong."""
    if not raw:
        raise ValueError(f"an empty body: {_BODY_SHAPE}")
    try:
        body = json.loads(raw)
    except RecursionError:
        raise ValueError("the body is nested too deeply to read") from None
    except ValueError as exc:  # JSONDecodeError and bad UTF-8
        raise ValueError(f"the body is not JSON: {exc}") from None
    if not isinstance(body, dict) or not isinstance(body.get("event"), str):
        raise ValueError(_BODY_SHAPE)
    device = body.get("device")
    if device is not None and not isinstance(device, str):
        raise ValueError("device must be a name")
    return device, body["event"], body.get("data")


def _deliver(
    send: Callable[[str | None, str, Any], Any],
    device: str | None,
    event: str,
    data: Any,
    wait: float,
) -> tuple[int | None, bool]:
    """Post on a worker thread; with a journal, wait (bounded) until the event is durable."""
    ticket = send(device, event, data)
    if ticket is None:
        return None, False
    return ticket.seq, bool(ticket.wait(wait))
