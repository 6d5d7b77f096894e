"""The dashboard's server under hostile or careless clients, over real HTTP on 127.0.0.1.

Each test starts a Dashboard on a free port with small limits and stops it in teardown;
requests are written byte for byte on a socket, so what the server does with the
connection (closes it, answers once, keeps it) is what is checked.
"""

from __future__ import annotations

import http.client
import json
import logging
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from statectl.channels.cli.demo import motor_chart
from statectl.channels.web.app import Limits
from statectl.channels.web.server import Dashboard
from statectl.run.devices import SimMotor
from statectl.run.runner import DeviceSetup, System
from statectl.run.runtime import SimClock

TOKEN = "limits-test-token"
SMALL = Limits(
    streams=3, body=4096, idle_timeout=0.5, body_timeout=0.5, stream_buffer=64 * 1024, linger=0.5
)


@dataclass
class Server:
    dash: Dashboard
    system: System

    @property
    def port(self) -> int:
        return self.dash.port

    @property
    def host(self) -> str:
        return f"127.0.0.1:{self.port}"

    def connect(self) -> socket.socket:
        sock = socket.create_connection(("127.0.0.1", self.port), timeout=5)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return sock

    def stream(self) -> http.client.HTTPResponse:
        """An open event stream whose snapshot was read already."""
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=5)
        conn.request("GET", "/api/events")
        reply = conn.getresponse()
        assert reply.status == 200
        assert next_message(reply)["type"] == "snapshot"
        return reply


def start(limits: Limits) -> Server:
    system = System((DeviceSetup("Motor", motor_chart(), driver=SimMotor()),), SimClock())
    dash = Dashboard(system.subjects.values(), post=system.post, token=TOKEN, limits=limits)
    dash.start("127.0.0.1", 0)
    system.start()
    return Server(dash, system)


@pytest.fixture
def server() -> Iterator[Server]:
    s = start(SMALL)
    try:
        yield s
    finally:
        s.dash.stop()
        s.system.close()


def next_message(reply: http.client.HTTPResponse) -> dict[str, object]:
    """The next ``data:`` message of an event stream, with its ``id`` when it has one."""
    ident = None
    while True:
        line = reply.readline().decode()
        if not line:
            raise EOFError("the stream ended")
        if line.startswith("id: "):
            ident = int(line[4:])
        if line.startswith("data: "):
            message: dict[str, object] = json.loads(line[6:])
            if ident is not None:
                message["_id"] = ident
            return message


def read_response(sock: socket.socket) -> tuple[int, dict[str, str], bytes]:
    """One HTTP/1.1 response with a Content-Length, read off ``sock``."""
    data = b""
    while b"\r\n\r\n" not in data:
        more = sock.recv(65536)
        if not more:
            raise EOFError(f"closed after {data!r}")
        data += more
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode().split("\r\n")
    headers = {k.lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:])}
    length = int(headers.get("content-length", "0"))
    while len(body) < length:
        more = sock.recv(65536)
        if not more:
            raise EOFError("closed in the body")
        body += more
    return int(lines[0].split()[1]), headers, body


def closed_by_server(sock: socket.socket, within: float = 5.0) -> bool:
    """True when the server closes ``sock`` (EOF or reset) and sends nothing more."""
    sock.settimeout(within)
    try:
        return sock.recv(65536) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def drained_to_the_end(sock: socket.socket, within: float = 5.0) -> bool:
    """Read ``sock`` until the server ends it (EOF or reset); False if it is still open."""
    sock.settimeout(within)
    try:
        while sock.recv(1 << 20):
            pass
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False
    return True


def request(
    host: str, method: str, path: str, body: bytes = b"", extra: str = "", length: bool = True
) -> bytes:
    size = f"Content-Length: {len(body)}\r\n" if length else ""
    return f"{method} {path} HTTP/1.1\r\nHost: {host}\r\n{extra}{size}\r\n".encode() + body


POST_OK = f"Content-Type: application/json\r\nX-Statectl-Token: {TOKEN}\r\n"


# -- refused requests close their connection -------------------------------------------------

SMUGGLED = b"GET /api/state HTTP/1.1\r\nHost: x\r\n\r\n"

REFUSALS: list[tuple[str, Callable[[str], bytes], int]] = [
    ("no token", lambda h: request(h, "POST", "/api/post", SMUGGLED,
                                   "Content-Type: application/json\r\n"), 401),
    ("form body", lambda h: request(h, "POST", "/api/post", SMUGGLED,
                                    f"Content-Type: text/plain\r\nX-Statectl-Token: {TOKEN}\r\n"),
     415),
    ("foreign origin", lambda h: request(h, "POST", "/api/post", SMUGGLED,
                                         POST_OK + "Origin: http://evil.example\r\n"), 403),
    ("foreign host", lambda h: request("evil.example", "POST", "/api/post", SMUGGLED, POST_OK),
     403),
    ("nowhere", lambda h: request(h, "POST", "/nowhere", SMUGGLED, POST_OK), 404),
    ("two hosts", lambda h: request(h, "GET", "/api/state", b"", f"Host: {h}\r\n"), 400),
    ("no host", lambda h: b"GET /api/state HTTP/1.1\r\n\r\n" + SMUGGLED, 400),
    ("absolute-form, another host",
     lambda h: request(h, "GET", "http://evil.example/api/state"), 400),
    ("absolute-form https, another host",
     lambda h: request(h, "GET", "https://evil.example/api/state"), 400),
    ("absolute-form, another port",
     lambda h: request(h, "GET", f"http://{h.rsplit(':', 1)[0]}:1/api/state"), 400),
    ("asterisk-form", lambda h: request(h, "OPTIONS", "*"), 400),
    ("two origins", lambda h: request(h, "GET", "/api/state", b"",
                                      f"Origin: http://{h}\r\nOrigin: http://{h}\r\n"), 403),
    ("body too large", lambda h: request(h, "POST", "/api/post", b"{" * 5000, POST_OK), 413),
    ("bad json", lambda h: request(h, "POST", "/api/post", SMUGGLED, POST_OK), 400),
]  # fmt: skip


@pytest.mark.parametrize(("case", "make", "status"), REFUSALS, ids=[r[0] for r in REFUSALS])
def test_a_refused_request_gets_one_answer_and_its_connection_closed(
    server: Server, case: str, make: Callable[[str], bytes], status: int
) -> None:
    """The refusal's status, Connection: close, then EOF: the unread body is never served."""
    sock = server.connect()
    try:
        sock.sendall(make(server.host))
        assert read_response(sock)[0] == status
        assert closed_by_server(sock)
    finally:
        sock.close()
    assert server.system.subjects["Motor"].queued == 0


def test_an_absolute_form_target_naming_this_server_is_served(server: Server) -> None:
    """RFC 9112 lets a client send an absolute target: naming our own Host, it is answered."""
    sock = server.connect()
    try:
        sock.sendall(request(server.host, "GET", f"http://{server.host}/api/state"))
        assert read_response(sock)[0] == 200
    finally:
        sock.close()


def test_a_chunked_body_over_the_cap_is_refused_with_413(server: Server) -> None:
    """Without Content-Length the cap still holds: 413 once the chunks pass it."""
    sock = server.connect()
    try:
        piece = b'{"event": "Movement", "data": "' + b"x" * 8000 + b'"}'
        body = b"%x\r\n%s\r\n0\r\n\r\n" % (len(piece), piece)
        extra = POST_OK + "Transfer-Encoding: chunked\r\n"
        sock.sendall(request(server.host, "POST", "/api/post", body, extra, length=False))
        assert read_response(sock)[0] == 413
        assert closed_by_server(sock)
    finally:
        sock.close()


# -- idle and slow clients --------------------------------------------------------------------

SLOW = [
    ("silent", b""),
    ("half a request line", b"GET /api/st"),
    ("headers never ended", b"GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\n"),
]


@pytest.mark.parametrize(("case", "sent"), SLOW, ids=[s[0] for s in SLOW])
def test_a_connection_without_a_complete_request_is_closed_after_the_idle_timeout(
    server: Server, case: str, sent: bytes
) -> None:
    """A client that connects and stalls does not hold its connection (idle_timeout 0.5 s)."""
    sock = server.connect()
    try:
        sock.sendall(sent)
        assert closed_by_server(sock, within=5.0)
    finally:
        sock.close()


def test_a_keep_alive_connection_left_idle_is_closed(server: Server) -> None:
    """After a full exchange the connection is kept, then closed once idle too long."""
    sock = server.connect()
    try:
        sock.sendall(request(server.host, "GET", "/api/state"))
        assert read_response(sock)[0] == 200
        assert closed_by_server(sock, within=5.0)
    finally:
        sock.close()


def test_a_body_that_stops_arriving_gets_408_and_a_closed_connection(server: Server) -> None:
    """Content-Length promised but the body stalls: 408 after body_timeout, then EOF."""
    sock = server.connect()
    try:
        head = request(server.host, "POST", "/api/post", b"", POST_OK, length=False)
        sock.sendall(head[:-2] + b"Content-Length: 100\r\n\r\n" + b'{"event": ')
        assert read_response(sock)[0] == 408
        assert closed_by_server(sock)
    finally:
        sock.close()


# -- bodies -----------------------------------------------------------------------------------

DEEP = 30_000


@pytest.mark.parametrize(
    "body",
    [
        b"[" * DEEP + b"]" * DEEP,
        b'{"event": "Movement", "data": ' + b"[" * DEEP + b"]" * DEEP + b"}",
        b'{"event": "Movement", "data": ' + b'{"a":' * DEEP + b"1" + b"}" * DEEP + b"}",
    ],
    ids=["array", "data array", "data object"],
)
def test_json_nested_30000_deep_is_refused_cleanly(body: bytes) -> None:
    """400 with a message, nothing posted, and the server answers the next request."""
    big = Limits(body=1 << 20)
    s = start(big)
    try:
        sock = s.connect()
        try:
            sock.sendall(request(s.host, "POST", "/api/post", body, POST_OK))
            status, _, reply = read_response(sock)
            assert (status, json.loads(reply)["error"]) == (400, "the body is nested too deeply"
                                                             " to read")  # fmt: skip
        finally:
            sock.close()
        assert s.system.subjects["Motor"].queued == 0
        sock = s.connect()
        try:
            sock.sendall(request(s.host, "GET", "/api/state"))
            assert read_response(sock)[0] == 200
        finally:
            sock.close()
    finally:
        s.dash.stop()
        s.system.close()


def test_every_keep_alive_response_arrives_in_one_piece() -> None:
    """Headers and body are written together: the first read of each response holds all of it."""
    big = Limits(idle_timeout=10.0)
    s = start(big)
    try:
        sock = s.connect()
        try:
            for _ in range(20):
                sock.sendall(request(s.host, "GET", "/api/state"))
                sock.settimeout(5)
                first = sock.recv(1 << 20)
                head, _, body = first.partition(b"\r\n\r\n")
                length = int(next(line.split(b":")[1] for line in head.split(b"\r\n")
                                  if line.lower().startswith(b"content-length")))  # fmt: skip
                assert len(body) == length
                assert b"connection: close" not in head.lower()
        finally:
            sock.close()
    finally:
        s.dash.stop()
        s.system.close()


# -- event streams ----------------------------------------------------------------------------


def test_streams_beyond_the_cap_get_503_and_a_freed_slot_is_reused(server: Server) -> None:
    """With streams=3 the fourth stream is refused (503, Retry-After); closing one frees a slot."""
    open_ = [server.stream() for _ in range(3)]
    sock = server.connect()
    try:
        sock.sendall(request(server.host, "GET", "/api/events"))
        status, headers, body = read_response(sock)
        assert (status, headers.get("retry-after")) == (503, "5")
        assert "3 event streams" in json.loads(body)["error"]
        assert closed_by_server(sock)
    finally:
        sock.close()
    open_.pop().close()
    deadline = time.monotonic() + 5
    while len(server.dash.fanout.streams) >= 3 and time.monotonic() < deadline:
        time.sleep(0.02)
    open_.append(server.stream())
    for reply in open_:
        reply.close()


def test_every_stream_gets_every_message_in_order_from_many_threads(server: Server) -> None:
    """Messages published by 4 threads reach each of 3 streams, numbered without a gap."""
    streams = [server.stream() for _ in range(3)]
    per_thread = 300

    def publish(n: int) -> None:
        for i in range(per_thread):
            server.dash.publish(json.dumps({"type": "test", "thread": n, "i": i}))

    threads = [threading.Thread(target=publish, args=(n,)) for n in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    try:
        for reply in streams:
            seen: dict[int, list[int]] = {n: [] for n in range(4)}
            ids = []
            while sum(map(len, seen.values())) < 4 * per_thread:
                m = next_message(reply)
                if m["type"] == "test":
                    seen[m["thread"]].append(m["i"])  # type: ignore[index]
                    ids.append(m["_id"])
            assert all(v == list(range(per_thread)) for v in seen.values())
            assert ids == list(range(ids[0], ids[0] + len(ids)))
    finally:
        for reply in streams:
            reply.close()


def test_a_stream_that_does_not_read_is_dropped_and_the_others_get_everything(
    server: Server,
) -> None:
    """A client that stops reading is cut off at its buffer; a reader that keeps up misses nothing.

    Messages go out in bursts of 8 (64 KB, under the 64 KB buffer plus what the kernel
    holds) and the next burst waits for the reader, so only the stalled client falls behind.
    """
    reader = server.stream()
    stalled = socket.socket()
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.connect(("127.0.0.1", server.port))
    stalled.sendall(request(server.host, "GET", "/api/events"))
    deadline = time.monotonic() + 5
    while len(server.dash.fanout.streams) < 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    filler = "x" * 8000
    count = 2000  # 16 MB: far beyond the 64 KB buffer and the kernel's socket buffers
    received: list[int] = []
    try:
        for i in range(count):
            server.dash.publish(json.dumps({"type": "test", "i": i, "pad": filler}))
            if i % 8 == 7:
                while len(received) <= i:
                    m = next_message(reader)
                    if m["type"] == "test":
                        received.append(m["i"])  # type: ignore[arg-type]
        assert received == list(range(count))
        assert server.dash.fanout.dropped == 1
        assert len(server.dash.fanout.streams) == 1
        assert drained_to_the_end(stalled)
    finally:
        reader.close()
        stalled.close()


def test_clients_that_go_away_leave_no_traceback(
    server: Server, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]
) -> None:
    """Streams reset mid-flow, posts cut mid-body, replies unread, malformed requests: no log."""
    caplog.set_level(logging.DEBUG - 1, logger="aiohttp")
    caplog.set_level(logging.WARNING)
    linger = struct.pack("ii", 1, 0)  # close() sends RST
    for _ in range(6):
        socks = []
        for make in (
            lambda: request(server.host, "GET", "/api/events"),
            lambda: request(server.host, "POST", "/api/post", b'{"event"', POST_OK)[:-3],
            lambda: request(server.host, "GET", "/api/state"),
            lambda: request(server.host, "GET", "/api/diagram/Motor.svg"),
            lambda: request(server.host, "GET", "/api/state", b"", f"Host: {server.host}\r\n"),
            lambda: b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03" + b"\x00" * 40,
        ):
            sock = server.connect()
            sock.sendall(make())
            socks.append(sock)
        for i in range(50):
            server.dash.publish(json.dumps({"type": "test", "i": i}))
        time.sleep(0.05)
        for sock in socks:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, linger)
            sock.close()
        for i in range(50):
            server.dash.publish(json.dumps({"type": "test", "i": i}))
    time.sleep(0.5)
    sock = server.connect()
    try:
        sock.sendall(request(server.host, "GET", "/api/state"))
        assert read_response(sock)[0] == 200
    finally:
        sock.close()
    server.dash.stop()
    bad = [r for r in caplog.records if r.levelno >= logging.WARNING or r.exc_info]
    assert bad == []
    assert "Traceback" not in capfd.readouterr().err


def test_publishing_never_waits_for_a_stalled_loop_and_an_overrun_drops_every_stream(
    server: Server,
) -> None:
    """With the loop held a device steps and PENDING_MAX + 1 messages publish; then streams drop.

    A page that stayed would miss messages, so none stays: it reconnects to a snapshot.
    """
    from statectl.channels.web.server import PENDING_MAX

    reply = server.stream()
    deadline = time.monotonic() + 5
    while server.dash.fanout.seq < 2 and time.monotonic() < deadline:
        time.sleep(0.01)  # the start's records (run, enter) are out: nothing pending
    held, release = threading.Event(), threading.Event()

    def hold() -> None:
        held.set()
        release.wait(10)

    loop = server.dash._loop
    assert loop is not None
    loop.call_soon_threadsafe(hold)
    assert held.wait(5)
    try:
        server.system.post("Motor", "Movement", {"amount": 5})
        server.system.drain()  # a device step with the loop held: done, nothing waited
        assert server.system.subjects["Motor"].configuration == {"Moving"}
        for i in range(PENDING_MAX + 1):
            server.dash.publish(json.dumps({"type": "test", "i": i}))
        assert not release.is_set()  # all published while the loop was held
    finally:
        release.set()
    with pytest.raises((EOFError, http.client.IncompleteRead, ConnectionError)):
        while True:
            next_message(reply)
    reply.close()
    after = server.stream()
    server.dash.publish(json.dumps({"type": "test", "i": "after"}))
    got = [next_message(after)]
    while got[-1].get("i") != "after":
        got.append(next_message(after))
    seen = [m.get("kind", m.get("i")) for m in got]
    # the backlog: the start, then what was published after the overrun's discard, then ours
    tail = seen[2:-1]
    assert seen[:2] == ["run", "enter"] and seen[-1] == "after"
    assert tail == list(range(PENDING_MAX + 1 - len(tail), PENDING_MAX + 1))
    after.close()


def test_a_stream_that_takes_nothing_is_dropped_after_the_stall_timeout() -> None:
    """Under its buffer cap but backed up at every check for stall_timeout: dropped.

    The device then goes quiet; a reader that keeps up stays.
    """
    s = start(Limits(heartbeat=0.1, stall_timeout=0.5, stream_buffer=64 << 20))
    reader = s.stream()
    stalled = socket.socket()
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.connect(("127.0.0.1", s.port))
    try:
        stalled.sendall(request(s.host, "GET", "/api/events"))
        deadline = time.monotonic() + 5
        while len(s.dash.fanout.streams) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        filler = "x" * 8000
        for i in range(1000):  # 8 MB: more than the kernel holds for the stalled client
            s.dash.publish(json.dumps({"type": "test", "i": i, "pad": filler}))
            if i % 8 == 7:
                while next_message(reader).get("i") != i:
                    pass
        deadline = time.monotonic() + 10
        while len(s.dash.fanout.streams) > 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert (len(s.dash.fanout.streams), s.dash.fanout.dropped) == (1, 1)
        s.dash.publish(json.dumps({"type": "test", "i": "still here"}))
        while (m := next_message(reader)).get("type") != "test" or m["i"] != "still here":
            pass
        assert drained_to_the_end(stalled)
    finally:
        reader.close()
        stalled.close()
        s.dash.stop()
        s.system.close()
