"""The dashboard over HTTP: page and assets offline, state, diagrams, SSE, token and origin."""

from __future__ import annotations

import http.client
import json
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

from statectl.channels.cli.demo import motor_chart
from statectl.channels.web.server import Dashboard
from statectl.channels.web.svg import fallback_svg
from statectl.out.render.diagram import from_chart
from statectl.run.devices import SimMotor
from statectl.run.runner import DeviceSetup, System
from statectl.run.runtime import SimClock

TOKEN = "test-token"


@dataclass
class Served:
    system: System
    dash: Dashboard
    port: int

    def request(
        self, method: str, path: str, body: object = None, headers: dict[str, str] | None = None
    ) -> tuple[int, dict[str, str], bytes]:
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=10)
        try:
            data = json.dumps(body).encode() if body is not None else None
            conn.request(method, path, body=data, headers=headers or {})
            reply = conn.getresponse()
            return reply.status, dict(reply.getheaders()), reply.read()
        finally:
            conn.close()


@pytest.fixture
def served() -> Iterator[Served]:
    chart = motor_chart()
    system = System((DeviceSetup("Motor", chart, driver=SimMotor()),), SimClock())
    dash = Dashboard(system.subjects.values(), post=system.post, token=TOKEN)
    dash.start("127.0.0.1", 0)
    try:
        system.start()
        yield Served(system, dash, dash.port)
    finally:
        dash.stop()
        system.close()


POST = {"Content-Type": "application/json", "X-Statectl-Token": TOKEN}


@pytest.mark.parametrize(
    ("path", "ctype", "needle"),
    [
        ("/", "text/html", b"/static/app.js"),
        ("/static/app.js", "text/javascript", b"EventSource"),
        ("/static/style.css", "text/css", b".active"),
        ("/api/diagram/Motor.svg", "image/svg+xml", b"<svg"),
    ],
)
def test_the_page_and_its_assets_are_served_from_the_package(
    served: Served, path: str, ctype: str, needle: bytes
) -> None:
    """Everything the page needs comes from this server: no CDN, works offline."""
    status, headers, body = served.request("GET", path)
    assert (status, headers["Content-Type"].split(";")[0]) == (200, ctype)
    assert needle in body
    assert b"https://" not in body or path.endswith(".svg")


def test_state_lists_active_states_invokes_and_monitors(served: Served) -> None:
    """/api/state: the Motor in Blocked, its invoke numbers with the observer, its monitor."""
    status, _, body = served.request("GET", "/api/state")
    motor = json.loads(body)["devices"][0]
    assert status == 200
    assert motor["active"] == ["Blocked"]
    assert [(i["number"], i["method"], i["observer"]) for i in motor["invokes"]] == [
        (0, "Movement", "SimMotor"),
        (1, "Initialization", "SimMotor"),
        (2, "Error", "SimMotor"),
    ]
    assert motor["monitors"] == [{"state": "Moving", "status": "idle"}]


def test_an_event_with_the_token_reaches_the_device(served: Served) -> None:
    """POST with the token: accepted; the owner processes it and the state shows Moving."""
    status, _, body = served.request(
        "POST", "/api/post", {"device": "Motor", "event": "Movement", "data": {"amount": 5}}, POST
    )
    assert (status, json.loads(body)["accepted"]) == (200, True)
    served.system.drain()
    motor = json.loads(served.request("GET", "/api/state")[2])["devices"][0]
    assert (motor["active"], motor["monitors"][0]["status"]) == (["Moving"], "running")


@pytest.mark.parametrize(
    ("headers", "status"),
    [
        ({"Content-Type": "application/json"}, 401),
        ({"Content-Type": "application/json", "X-Statectl-Token": "wrong"}, 401),
        ({"Content-Type": "application/json", "X-Statectl-Token": "\u00e9" * 24}, 401),
        ({**POST, "Origin": "http://evil.example"}, 403),
        ({**POST, "Host": "evil.example"}, 403),
        ({**POST, "Content-Type": "text/plain"}, 415),
    ],
)
def test_posts_without_token_or_from_elsewhere_are_refused(
    served: Served, headers: dict[str, str], status: int
) -> None:
    """No token, a wrong token (one of bytes that are not UTF-8 too: it used to be a 500 and
    a traceback), a foreign origin or host, a form body: refused, nothing posted."""
    got, _, _ = served.request("POST", "/api/post", {"event": "Movement"}, headers)
    assert got == status
    assert served.system.subjects["Motor"].queued == 0


@pytest.mark.parametrize(
    ("headers", "status"),
    [
        ({}, 200),
        ({"Host": "localhost:{port}"}, 200),
        ({"Origin": "http://127.0.0.1:{port}"}, 200),
        ({"Origin": "http://localhost:{port}"}, 200),
        ({"Host": "evil.example:{port}"}, 403),
        ({"Host": "127.0.0.1:1"}, 403),
        ({"Origin": "http://evil.example"}, 403),
        ({"Origin": "null"}, 403),
        ({"Origin": "https://127.0.0.1:{port}"}, 403),
    ],
)
def test_reading_follows_the_host_and_origin_rules_too(
    served: Served, headers: dict[str, str], status: int
) -> None:
    """GET /api/state: a foreign Host (DNS rebinding) or Origin is refused like a post."""
    filled = {k: v.format(port=served.port) for k, v in headers.items()}
    assert served.request("GET", "/api/state", headers=filled)[0] == status


def test_a_same_origin_post_is_accepted(served: Served) -> None:
    """The page's own origin passes the origin check."""
    headers = {**POST, "Origin": f"http://127.0.0.1:{served.port}"}
    assert served.request("POST", "/api/post", {"event": "Movement", "data": {"amount": 1}},
                          headers)[0] == 200  # fmt: skip


def test_the_event_stream_starts_with_a_snapshot_then_records(served: Served) -> None:
    """SSE: the snapshot, the backlog, then an event's records with the new state."""
    conn = http.client.HTTPConnection("127.0.0.1", served.port, timeout=10)
    try:
        conn.request("GET", "/api/events")
        reply = conn.getresponse()
        assert reply.getheader("Content-Type") == "text/event-stream"

        def message() -> dict[str, object]:
            while True:
                line = reply.fp.readline().decode()
                if line.startswith("data: "):
                    result: dict[str, object] = json.loads(line[6:])
                    return result

        assert message()["type"] == "snapshot"
        served.system.post("Motor", "Movement", {"amount": 5})
        served.system.drain()
        seen = []
        while not seen or seen[-1] != "api":
            m = message()
            seen.append(m["kind"])
        assert seen[:2] == ["run", "enter"]  # the backlog: the start
        assert seen[2:4] == ["event", "exit"]
        assert m["state"]["active"] == ["Moving"]  # type: ignore[index]
        assert "invokes" not in m["state"]  # type: ignore[operator]  # the snapshot's part
    finally:
        conn.close()


def test_the_fallback_diagram_marks_nodes_like_graphviz() -> None:
    """Without Graphviz each state is a g.node with its id as title, names escaped."""
    svg = fallback_svg(from_chart(motor_chart()))
    assert svg.count('<g class="node"><title>') == 3
    assert "<title>Moving</title>" in svg


def test_an_ipv6_loopback_dashboard_takes_its_bracketed_host() -> None:
    """On ::1 the URL and the accepted Host are [::1]:port; a bare ::1 Host is refused."""
    dash = Dashboard([])
    try:
        url = dash.start("::1", 0)
    except OSError:
        pytest.skip("no IPv6 loopback here")
    try:
        assert url == f"http://[::1]:{dash.port}/"
        statuses = []
        for host in (f"[::1]:{dash.port}", f"::1:{dash.port}"):
            conn = http.client.HTTPConnection("::1", dash.port, timeout=10)
            try:
                conn.request("GET", "/api/state", headers={"Host": host})
                reply = conn.getresponse()
                reply.read()
                statuses.append(reply.status)
            finally:
                conn.close()
        assert statuses == [200, 403]
    finally:
        dash.stop()


@pytest.mark.parametrize(
    ("body", "status", "says"),
    [
        ({"device": "Motor", "event": "Bogus"}, 422, "Motor has no event 'Bogus'; its events: "),
        ({"event": "Movement completed"}, 422, "Motor has no event 'Movement completed'"),
        ({"device": "Nope", "event": "Movement"}, 400, "no device 'Nope'"),
    ],
)
def test_an_event_the_chart_does_not_know_is_refused(
    served: Served, body: dict[str, str], status: int, says: str
) -> None:
    """An unknown event (or device) is refused with a 4xx naming it; nothing reaches the device."""
    got, _, reply = served.request("POST", "/api/post", body, POST)
    assert (got, says in json.loads(reply)["error"]) == (status, True), reply
    served.system.drain()
    assert served.system.subjects["Motor"].events_processed == 0


def test_a_command_the_policy_refuses_gets_403_and_nothing_moves() -> None:
    """The dashboard posts with its origin; the System's commands policy refuses what no
    grant of the dashboard covers: 403 with the reason, and the Motor stays Blocked."""
    from statectl.run.commands import Commands, Grant, Origin

    system = System(
        (DeviceSetup("Motor", motor_chart()),),
        SimClock(),
        commands=Commands([Grant("dashboard", events=frozenset({"Initialization"}))]),
    )
    dash = Dashboard(
        system.subjects.values(), post=system.post, token=TOKEN, origin=Origin("dashboard", "t")
    )
    dash.start("127.0.0.1", 0)
    try:
        system.start()
        served = Served(system, dash, dash.port)
        refused = served.request("POST", "/api/post", {"event": "Movement"}, POST)
        allowed = served.request("POST", "/api/post", {"event": "Initialization"}, POST)
        system.drain()
        assert (refused[0], allowed[0]) == (403, 200)
        assert (
            "Motor: Movement refused: dashboard t may not send it"
            in json.loads(refused[2])["error"]
        )
        assert system.subjects["Motor"].configuration == frozenset({"Blocked"})
        assert system.subjects["Motor"].events_processed == 1  # Initialization only
    finally:
        dash.stop()
        system.close()


@pytest.mark.parametrize(
    ("token", "token_from", "says", "not_said"),
    [
        (None, None, "printed at start-up", "set by"),
        (TOKEN, "--token", "set by --token", "printed at start-up"),
        (TOKEN, None, "set by --token, $STATECTL_DASHBOARD_TOKEN or the config", "printed"),
    ],
)
def test_the_401_says_where_the_token_comes_from(
    token: str | None, token_from: str | None, says: str, not_said: str
) -> None:
    """A token given (--token, environment, config) is not 'printed at start-up'; it used to
    say so whatever gave it."""
    system = System((DeviceSetup("Motor", motor_chart(), driver=SimMotor()),), SimClock())
    dash = Dashboard(system.subjects.values(), post=system.post, token=token, token_from=token_from)
    dash.start("127.0.0.1", 0)
    try:
        served = Served(system, dash, dash.port)
        status, _, body = served.request(
            "POST", "/api/post", {"event": "Movement"}, {"Content-Type": "application/json"}
        )
    finally:
        dash.stop()
        system.close()
    text = body.decode()
    assert (status, says in text, not_said in text) == (401, True, False), text


def test_an_unknown_event_posted_says_did_you_mean(served: Served) -> None:
    """A mistyped event name is refused with the closest the device knows, as check does."""
    status, _, body = served.request("POST", "/api/post", {"event": "Movment"}, POST)
    assert (status, "did you mean 'Movement'?" in body.decode()) == (422, True), body
