"""Trust on the plant network: what a `statectl node` accepts from Zenoh, and from whom.

Each attack of issue 28 is played against a real node (its `node_main`, in this process,
or `statectl node` processes) with real Zenoh sessions on 127.0.0.1 only: peer mode,
multicast scouting off, explicit endpoints on ports the OS gave out. Every process a
test starts is stopped by its PID. See docs/distributed.md, "Security".
"""

from __future__ import annotations

import io
import json
import os
import re
import signal
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from statectl.cell.model import load_cell
from statectl.channels.distributed.messages import Unreadable, parse_snapshot, read_post
from statectl.channels.distributed.trust import (
    MAX_DEPTH,
    access_control,
    payload_problem,
    printable,
    shown,
)

zenoh = pytest.importorskip("zenoh")
pytest.importorskip("cryptography")

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "pick-and-place"
WAIT = 20.0  # seconds a step may take on this shared machine, at most
DEEP = b"[" * 1000 + b"]" * 1000


def free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def example_cell(tmp: Path, name: str, base: int, extra: str = "") -> tuple[Path, dict[str, int]]:
    """An example cell file copied to ``tmp`` on free ports (its device files by path)."""
    ports = dict(zip(("line", "arm", "gripper"), free_ports(3), strict=True))
    text = (EXAMPLE / name).read_text()
    for i, node in enumerate(("line", "arm", "gripper")):
        text = text.replace(f"127.0.0.1:{base + i}", f"127.0.0.1:{ports[node]}")
    for device in ("conveyor", "arm", "gripper", "sensor"):
        text = text.replace(f": {device}.yaml", f": {EXAMPLE / (device + '.yaml')}")
    path = tmp / "cell.yaml"
    path.write_text(text + extra)
    return path, ports


class InProcess:
    """`statectl node CELL --node NAME --driver none --journal DB` on a thread of this test."""

    def __init__(self, cell: Path, node: str, journal: Path, config: Path | None = None) -> None:
        from statectl.channels.cli.node import node_main

        self.out = io.StringIO()
        self.err = io.StringIO()
        self.journal = journal
        self.stop = threading.Event()
        self.code: int | None = None
        args = {"node": node, "driver": "none", "journal": str(journal)}
        if config is not None:
            args["config"] = str(config)

        def run() -> None:
            self.code = node_main(
                str(cell), **args, events=io.StringIO(), out=self.out, err=self.err, stop=self.stop
            )

        self.thread = threading.Thread(target=run, name=f"node-{node}")
        self.thread.start()
        self.wait_for(f"node {node}: running")

    def wait_for(self, text: str) -> None:
        deadline = time.monotonic() + WAIT
        while text not in self.out.getvalue():
            assert self.code is None, self.out.getvalue() + self.err.getvalue()
            assert time.monotonic() < deadline, f"no {text!r} in:\n{self.out.getvalue()}"
            time.sleep(0.02)

    def close(self) -> int | None:
        self.stop.set()
        self.thread.join(WAIT)
        return self.code

    def inbox(self) -> list[tuple[str, str]]:
        db = sqlite3.connect(self.journal)
        try:
            return list(db.execute("SELECT device, event FROM inbox ORDER BY seq"))
        finally:
            db.close()

    def refused_steps(self) -> list[tuple[str, str]]:
        """The journal's ``refused`` steps: (event, outcome)."""
        db = sqlite3.connect(self.journal)
        try:
            rows = db.execute("SELECT event, outcome FROM steps WHERE outcome LIKE 'refused%'")
            return list(rows)
        finally:
            db.close()

    def meta(self, key: str) -> str | None:
        db = sqlite3.connect(self.journal)
        try:
            row = db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
            return None if row is None else str(row[0])
        finally:
            db.close()


def session(
    endpoint: str,
    tls: dict[str, Any] | None = None,
    *,
    auth: dict[str, str] | None = None,
    refused: bool = False,
) -> Any:
    """A Zenoh session that connects to ``endpoint`` only (an attacker or a stand-in node).

    ``exit_on_failure``: opening fails when the endpoint refuses it (no certificate of
    the cell's CA) within the connect timeout, instead of retrying in the background;
    ``refused``: the test expects that, so the timeout is short.
    """
    c = zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("connect/endpoints", json.dumps([endpoint]))
    c.insert_json5("connect/timeout_ms", "1500" if refused else "10000")
    c.insert_json5("connect/exit_on_failure", "true")
    if tls is not None:
        c.insert_json5("transport/link/tls", json.dumps(tls))
    if auth:
        c.insert_json5("transport/auth/usrpwd", json.dumps(auth))
    return zenoh.open(c)


def synced(s: Any, root: str, node: str, device: str, epoch: str) -> None:
    """A hello on the stream ``node`` -> ``device`` and wait for its acknowledgement: what
    ``s`` put before has been taken or refused by then (one session's puts stay in order)."""
    got = threading.Event()
    sub = s.declare_subscriber(f"{root}/ack/{node}/{device}", lambda sample: got.set())
    deadline = time.monotonic() + WAIT
    while not got.is_set():
        s.put(f"{root}/hello/{node}/{device}", json.dumps({"e": epoch}))
        got.wait(0.5)
        assert time.monotonic() < deadline, "no acknowledgement of the hello"
    sub.undeclare()


ROOT = "statectl/PickAndPlace"
LINK = f"{ROOT}/link/line/arm"
POST = f"{ROOT}/post/arm"


@pytest.fixture
def cleanup() -> Iterator[list[Any]]:
    """Sessions and nodes to close at the end, whatever happens."""
    things: list[Any] = []
    yield things
    for thing in reversed(things):
        thing.close()


# -- the open loopback cell: what reaches the arm is checked all the same ----------------------


class Attack:
    """The arm's node (open loopback cell, with a journal) and a foreign Zenoh session that
    reaches its endpoint: ``play`` puts each payload, in order, then waits until the node
    has taken or refused them all, and stops the node."""

    def __init__(self, tmp_path: Path, cleanup: list[Any], config: Path | None = None) -> None:
        cell, ports = example_cell(tmp_path, "cell-nodes.yaml", 7451)
        self.arm = InProcess(cell, "arm", tmp_path / "arm.db", config)
        cleanup.append(self.arm)
        self.s = session(f"tcp/127.0.0.1:{ports['arm']}")
        cleanup.append(self.s)

    def hello(self, epoch: str) -> None:
        """As the line's node says hello on its stream (anyone may, on an open cell)."""
        synced(self.s, ROOT, "line", "arm", epoch)

    def play(self, *puts: tuple[str, bytes]) -> str:
        for key, payload in puts:
            self.s.put(key, payload)
        self.hello("A")  # one session's puts stay in order: they are past when this is acked
        assert self.arm.close() == 0, self.arm.out.getvalue() + self.arm.err.getvalue()
        return self.arm.out.getvalue()

    def refused(self) -> list[str]:
        return [line for line in self.arm.out.getvalue().splitlines() if "refused on" in line]


def test_an_open_cell_says_so_in_its_banner(tmp_path: Path, cleanup: list[Any]) -> None:
    """A cell whose nodes are all on loopback may stay open; the node's banner says so."""
    attack = Attack(tmp_path, cleanup)
    assert "security open on loopback: any local process may command" in attack.play()


def test_a_link_event_in_an_epoch_no_hello_named_is_refused(
    tmp_path: Path, cleanup: list[Any]
) -> None:
    """["A",1,"Movement",null] on the line's stream to the arm, with no hello before it:
    refused with one log line and a journal note; the arm stays Blocked, nothing accepted."""
    attack = Attack(tmp_path, cleanup)
    out = attack.play((LINK, b'["A",1,"Movement",null]'))
    assert len(attack.refused()) == 1
    assert "an epoch changes only after a hello names it" in attack.refused()[0]
    assert attack.arm.inbox() == []
    assert attack.arm.meta("zenoh-refused") == "1"
    assert "final arm: Blocked" in out


def test_a_fault_no_link_carries_is_refused_on_a_link_stream(
    tmp_path: Path, cleanup: list[Any]
) -> None:
    """After the stream's one accepted Movement, an Error (a fault: no link from the line
    sends it) on the same stream is refused: the arm stays Moving, never Returning."""
    attack = Attack(tmp_path, cleanup)
    attack.hello("A")
    out = attack.play((LINK, b'["A",1,"Movement",null]'), (LINK, b'["A",2,"Error",null]'))
    assert attack.arm.inbox() == [("arm", "Movement")]
    assert len(attack.refused()) == 1 and "'Error': no link from line" in attack.refused()[0]
    assert "final arm: Moving" in out
    assert attack.arm.refused_steps() == [
        ("Error", f"refused: zenoh {LINK}: event 'Error': no link from line sends it to arm")
    ]


@pytest.mark.parametrize(
    "payload",
    [
        b'["B",-5,"Movement",null]',
        b'["B",1180591620717411303424,"Movement",null]',  # 2**70
        b'["A",-5,"Movement",null]',
        b'["A",1180591620717411303424,"Movement",null]',
    ],
    ids=["new-epoch-minus-5", "new-epoch-2**70", "same-epoch-minus-5", "same-epoch-2**70"],
)
def test_an_epoch_or_number_no_hello_announced_keeps_the_saved_position(
    tmp_path: Path, cleanup: list[Any], payload: bytes
) -> None:
    """With the stream at A 1, an event numbered -5 or 2**70 (in a new epoch, or in A) is
    refused: not applied, and the saved position stays A 1, so the real sender's next
    event (A 2) is still the next one and its resends are still duplicates."""
    attack = Attack(tmp_path, cleanup)
    attack.hello("A")
    attack.play((LINK, b'["A",1,"Movement",null]'), (LINK, payload))
    assert attack.arm.inbox() == [("arm", "Movement")]
    assert attack.arm.meta("link-in/line/arm") == "A 1"
    assert len(attack.refused()) == 1
    assert [event for event, _ in attack.arm.refused_steps()] == ["Movement"]


def test_link_data_nested_1000_deep_is_dropped_with_one_line(
    tmp_path: Path, cleanup: list[Any], capfd: pytest.CaptureFixture[str]
) -> None:
    """Link data (and a post's) nested 1,000 levels: dropped before it is decoded, one log
    line each, no RecursionError traceback anywhere."""
    attack = Attack(tmp_path, cleanup)
    attack.hello("A")
    out = attack.play(
        (LINK, b'["A",1,"Movement",' + DEEP + b"]"), (POST, b'{"ev":"Error","d":' + DEEP + b"}")
    )
    captured = capfd.readouterr()
    assert "Recursion" not in out + captured.out + captured.err
    assert "Traceback" not in out + captured.out + captured.err
    assert [line.split(": ", 2)[-1] for line in attack.refused()] == [
        f"payload nested deeper than {MAX_DEPTH}"
    ] * 2
    assert attack.arm.inbox() == []


@pytest.mark.parametrize(
    ("key", "payload", "reason"),
    [
        (LINK, b'["A",1,"Movement",{"amount":5}]', "data, which no link sends with it"),
        (POST, '{"ev":"Movement","d":{"x":"a\u202eb"}}'.encode(), "'a\\u202eb'"),
        (POST, b'{"ev":"Movement","d":["ok","\\n"]}', "'\\n'"),
    ],
    ids=["link-data-no-link-sends", "post-data-U+202E", "post-data-newline"],
)
def test_event_data_no_link_sends_or_not_printable_is_refused(
    tmp_path: Path, cleanup: list[Any], key: str, payload: bytes, reason: str
) -> None:
    """Data on a link event whose links send none, and text in posted data that is not
    printable (a trace prints it), are refused: one log line, nothing accepted."""
    attack = Attack(tmp_path, cleanup)
    attack.hello("A")
    attack.play((key, payload))
    assert len(attack.refused()) == 1 and reason in attack.refused()[0], attack.refused()
    assert attack.arm.inbox() == []


def test_a_zenoh_post_goes_through_the_systems_door(tmp_path: Path, cleanup: list[Any]) -> None:
    """`statectl node --config` with a commands: section granting zenoh Movement only: a
    post of Error over Zenoh is refused at the System's door and journalled as refused;
    Movement is taken."""
    config = tmp_path / "run.yaml"
    config.write_text("commands:\n  - {from: zenoh, send: [Movement]}\n")
    attack = Attack(tmp_path, cleanup, config)
    out = attack.play((POST, b'{"ev":"Error"}'), (POST, b'{"ev":"Movement"}'))
    assert "Error refused: zenoh (anonymous) may not send it" in out
    assert attack.arm.inbox() == [("arm", "Movement")]
    assert attack.arm.refused_steps() == [("Error", "refused: zenoh (anonymous)")]


@pytest.mark.parametrize("device", ["arm", "ghost"])
def test_a_state_put_for_this_nodes_device_or_none_of_the_cell_is_refused(
    tmp_path: Path, cleanup: list[Any], device: str
) -> None:
    """The arm's node mirrors other nodes' states (a guard reads the gripper): a state put
    from elsewhere for its own arm, or for a device the cell does not have, is refused."""
    attack = Attack(tmp_path, cleanup)
    attack.play((f"{ROOT}/state/{device}", b'{"a":[],"h":{},"p":null,"t":1e12}'))
    assert [line.split("refused on ")[1] for line in attack.refused()] == [
        f"{ROOT}/state/{device}: no other node runs this device"
    ]


@pytest.mark.parametrize(
    ("name", "shown_as"),
    [
        ("M" * 1_000_000, "bytes (at most"),  # 1 MB: the payload is too long to read
        ("X" * 300, "300 characters (at most 256)"),
        ("Move\nment", "'Move\\nment'"),
        ("Move\u202ement", "'Move\\u202ement'"),
        ("Stop\x1b[2J", "'Stop\\x1b[2J'"),
    ],
    ids=["1MB", "300-chars", "newline", "U+202E", "escape-sequence"],
)
def test_a_posted_name_too_long_or_not_printable_is_refused_and_printed_escaped(
    tmp_path: Path, cleanup: list[Any], name: str, shown_as: str
) -> None:
    """A post whose event name is 1 MB, 300 characters, or holds a newline, U+202E or an
    escape sequence is refused before the System sees it: one short log line with the name
    escaped, a journal note, nothing accepted."""
    attack = Attack(tmp_path, cleanup)
    out = attack.play((POST, json.dumps({"ev": name}).encode()))
    refused = attack.refused()
    assert len(refused) == 1 and shown_as in refused[0], refused
    assert all(len(line) < 600 for line in out.splitlines())
    assert "\u202e" not in out and "\x1b" not in out and "Move\nment" not in out
    assert attack.arm.inbox() == []
    assert attack.arm.meta("zenoh-refused") == "1"


# -- mutual TLS: only the cell's nodes connect, each puts only its own keys ---------------------


def _tls(certs: Path, who: str | None, ca: str = "ca") -> dict[str, Any]:
    tls: dict[str, Any] = {"root_ca_certificate": str(certs / f"{ca}.pem")}
    if who is not None:
        tls |= {
            "enable_mtls": True,  # a client shows its certificate only with mTLS on
            "connect_certificate": str(certs / f"{who}.pem"),
            "connect_private_key": str(certs / f"{who}-key.pem"),
        }
    return tls


def test_under_mutual_tls_only_the_cells_nodes_connect_and_each_puts_its_own_keys(
    tmp_path: Path, cleanup: list[Any]
) -> None:
    """With security: tls a peer without a certificate, or with one of another CA, cannot
    connect at all; the gripper's node (a valid certificate) cannot put on the line's
    link to the arm nor post to the arm (posts: arm: [line, operator]); the line's node
    can, so the arm moves once, on its event only. Keys are written owner-only."""
    from statectl.channels.distributed.certs import ensure_certificates

    cell, ports = example_cell(tmp_path, "cell-nodes-tls.yaml", 7461)
    arm = InProcess(cell, "arm", tmp_path / "arm.db")
    cleanup.append(arm)
    certs = tmp_path / "certs"
    assert "security mutual TLS" in arm.out.getvalue()
    assert (certs / "arm-key.pem").stat().st_mode & 0o077 == 0
    assert (certs / "ca-key.pem").stat().st_mode & 0o077 == 0
    ensure_certificates(tmp_path / "other", {"intruder": ()})  # a CA of someone else's
    endpoint = f"tls/127.0.0.1:{ports['arm']}"
    with pytest.raises(zenoh.ZError):
        session(endpoint, _tls(certs, None), refused=True)  # no client certificate
    with pytest.raises(zenoh.ZError):
        session(
            endpoint,
            {**_tls(tmp_path / "other", "intruder"), "root_ca_certificate": str(certs / "ca.pem")},
            refused=True,
        )
    gripper = session(endpoint, _tls(certs, "gripper"))
    cleanup.append(gripper)
    gripper.put(f"{ROOT}/hello/line/arm", json.dumps({"e": "G"}))
    gripper.put(LINK, b'["G",1,"Movement",null]')
    gripper.put(POST, json.dumps({"ev": "Error"}))
    synced(gripper, ROOT, "gripper", "arm", "G")  # its own stream: the puts above are past
    line = session(endpoint, _tls(certs, "line"))
    cleanup.append(line)
    synced(line, ROOT, "line", "arm", "L")
    line.put(LINK, b'["L",1,"Movement",null]')
    arm.wait_for("enter    Moving")
    synced(line, ROOT, "line", "arm", "L")
    assert arm.close() == 0
    assert arm.inbox() == [("arm", "Movement")]
    assert arm.meta("link-in/line/arm") == "L 1"


def test_an_operator_station_under_tls_needs_its_name_and_sees_the_arm(
    tmp_path: Path, cleanup: list[Any]
) -> None:
    """A station of a TLS cell opens with its own certificate (``--as operator``), sees the
    arm's state and may post to it (posts: arm: [line, operator]); unnamed, it is refused
    before anything opens."""
    from statectl.channels.distributed.view import CellView
    from statectl.kernel.errors import StatectlError

    cell_path, ports = example_cell(tmp_path, "cell-nodes-tls.yaml", 7461)
    arm = InProcess(cell_path, "arm", tmp_path / "arm.db")
    cleanup.append(arm)
    cell, _ = load_cell(cell_path)
    assert cell is not None
    with pytest.raises(StatectlError, match="--as NAME, one of security: stations: operator"):
        CellView(cell)
    view = CellView(cell, [f"tls/127.0.0.1:{ports['arm']}"], station="operator").open()
    cleanup.append(view)
    assert view.wait_for(lambda active: active.get("arm") == frozenset({"Blocked"}), WAIT)
    view.post("arm", "Movement")
    assert view.wait_for(lambda active: active.get("arm") == frozenset({"Moving"}), WAIT)


def test_user_password_authentication_keeps_out_who_has_no_login(
    tmp_path: Path, cleanup: list[Any]
) -> None:
    """security: {users: FILE} on a loopback cell: a peer without a login, or with a wrong
    password, cannot connect; one logged in as the gripper cannot put on the line's
    stream; logged in as the line it can, and the arm moves on its event only."""
    (tmp_path / "users.txt").write_text("line:l-secret\narm:a-secret\ngripper:g-secret\n")
    cell, ports = example_cell(tmp_path, "cell-nodes.yaml", 7451, "security: {users: users.txt}\n")
    arm = InProcess(cell, "arm", tmp_path / "arm.db")
    cleanup.append(arm)
    assert "security user/password" in arm.out.getvalue()
    endpoint = f"tcp/127.0.0.1:{ports['arm']}"

    def login(user: str | None, password: str = "", *, refused: bool = False) -> Any:
        c = {} if user is None else {"user": user, "password": password}
        return session(endpoint, auth=c, refused=refused)

    with pytest.raises(zenoh.ZError):
        login(None, refused=True)
    with pytest.raises(zenoh.ZError):
        login("line", "guess", refused=True)
    gripper = login("gripper", "g-secret")
    cleanup.append(gripper)
    gripper.put(f"{ROOT}/hello/line/arm", json.dumps({"e": "G"}))
    gripper.put(LINK, b'["G",1,"Movement",null]')
    synced(gripper, ROOT, "gripper", "arm", "G")
    line = login("line", "l-secret")
    cleanup.append(line)
    synced(line, ROOT, "line", "arm", "L")
    line.put(LINK, b'["L",1,"Movement",null]')
    arm.wait_for("enter    Moving")
    assert arm.close() == 0
    assert arm.inbox() == [("arm", "Movement")]
    assert arm.meta("link-in/line/arm") == "L 1"


def test_a_tls_cell_runs_end_to_end_on_two_node_processes(tmp_path: Path) -> None:
    """The example TLS cell on two `statectl node` processes (certificates made by the
    first, under a lock): the line's belt brings a part, the link to the arm fires over
    mutual TLS and the arm moves."""
    cell, _ = example_cell(tmp_path, "cell-nodes-tls.yaml", 7461)
    procs: dict[str, subprocess.Popen[str]] = {}
    command = [sys.executable, "-m", "statectl", "node", str(cell), "--driver", "none"]
    logs = {n: tmp_path / f"{n}.log" for n in ("line", "arm")}
    try:
        for node in ("line", "arm"):
            procs[node] = subprocess.Popen(
                [*command, "--node", node],
                stdin=subprocess.PIPE,
                stdout=logs[node].open("w"),
                stderr=subprocess.STDOUT,
                text=True,
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        _wait_log(logs["line"], "peer arm up")
        _wait_log(logs["arm"], "peer line up")
        stdin = procs["line"].stdin
        assert stdin is not None
        stdin.write("conveyor: Start\nsensor: Part in\n")
        stdin.flush()
        _wait_log(logs["arm"], "enter    Moving")
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGTERM)
        for proc in procs.values():
            try:
                proc.wait(WAIT)
            except subprocess.TimeoutExpired:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(WAIT)
    arm_log = logs["arm"].read_text()
    assert "security mutual TLS" in arm_log
    assert "refused" not in arm_log + logs["line"].read_text()


def _wait_log(path: Path, text: str) -> None:
    deadline = time.monotonic() + WAIT
    while text not in path.read_text():
        assert time.monotonic() < deadline, f"no {text!r} in {path.name}:\n{path.read_text()}"
        time.sleep(0.05)


# -- the cell file: TLS or loopback, and who may publish what -----------------------------------


def _cell(tmp: Path, endpoint: str, security: str = "") -> tuple[Any, list[str]]:
    text = (
        f"cell: C\ndevices: {{arm: {EXAMPLE / 'arm.yaml'}, gripper: {EXAMPLE / 'gripper.yaml'}}}\n"
        f"nodes:\n  a: {{devices: [arm], listen: ['{endpoint}']}}\n"
        f"  b: {{devices: [gripper], connect: ['{endpoint}']}}\n"
        "links:\n  - {from: gripper, enters: Closed, to: arm, send: Initialization}\n" + security
    )
    path = tmp / "c.yaml"
    path.write_text(text)
    cell, diags = load_cell(path)
    return cell, [f"{d.code} {d.message}" for d in diags]


@pytest.mark.parametrize(
    ("endpoint", "security", "code"),
    [
        ("tcp/127.0.0.1:7000", "", None),  # loopback: may stay open
        ("tcp/[::1]:7000", "", None),
        ("tcp/localhost:7000", "", None),
        ("tcp/10.0.0.5:7000", "", "V827"),  # reachable from the network without TLS
        ("tcp/0.0.0.0:7000", "", "V827"),  # every interface
        ("tcp/10.0.0.5:7000", "security: {insecure: true}\n", None),  # said so
        ("tls/10.0.0.5:7000", "security: {tls: certs}\n", None),
        ("tcp/127.0.0.1:7000", "security: {tls: certs}\n", "V828"),  # a plain door beside TLS
        ("tls/127.0.0.1:7000", "security: {tls: certs, posts: {arm: [nobody]}}\n", "V828"),
        ("tls/127.0.0.1:7000", "security: {tls: certs, posts: {belt: [a]}}\n", "V828"),
        ("tls/127.0.0.1:7000", "security: {tls: certs, posts: {arm: [a]}}\n", None),
        ("tcp/127.0.0.1:7000", "security: {posts: {arm: [a]}}\n", "V828"),  # nobody proves it
        ("tcp/127.0.0.1:7000", "security: {stations: [a]}\n", "V828"),  # a node's name
        ("tcp/127.0.0.1:7000", "security: {users: missing.txt}\n", "V828"),
        ("tcp/127.0.0.1:7000", "security: {tls: {ca: missing.pem, certificates: {}}}\n", "V828"),
        ("tcp/127.0.0.1:7000", "security: {insecure: maybe}\n", "V804"),
    ],
)
def test_a_cell_is_refused_at_load_when_a_node_is_reachable_without_tls(
    tmp_path: Path, endpoint: str, security: str, code: str | None
) -> None:
    """A non-loopback endpoint without TLS is V827 unless the cell says insecure: true; a
    security: section that cannot hold (a tcp endpoint beside TLS, posts naming no node
    or device, a missing file) is V828."""
    cell, diags = _cell(tmp_path, endpoint, security)
    if code is None:
        assert cell is not None, diags
    else:
        assert cell is None and any(d.startswith(code) for d in diags), diags


def test_node_refuses_a_cell_reachable_from_the_network_without_tls(tmp_path: Path) -> None:
    """`statectl node` on such a cell says V827 and exits 1 before anything opens."""
    from statectl.channels.cli.node import node_main

    _cell(tmp_path, "tcp/10.0.0.5:7000")
    err = io.StringIO()
    code = node_main(str(tmp_path / "c.yaml"), node="a", out=io.StringIO(), err=err)
    assert code == 1
    assert "V827" in err.getvalue() and "insecure: true" in err.getvalue()


def test_a_certificate_directory_that_cannot_be_made_is_said_not_raised(tmp_path: Path) -> None:
    """tls: DIR where DIR cannot be a directory (under a file): `statectl node` says so and
    exits 1, with no traceback and nothing opened."""
    from statectl.channels.cli.node import node_main

    _cell(tmp_path, "tls/127.0.0.1:7000", "security: {tls: c.yaml/certs}\n")
    err = io.StringIO()
    code = node_main(str(tmp_path / "c.yaml"), node="a", out=io.StringIO(), err=err)
    assert code == 1
    assert "cannot create the certificate directory" in err.getvalue(), err.getvalue()
    assert "Traceback" not in err.getvalue()


def test_the_example_tls_cell_loads_with_its_stations_and_posts() -> None:
    """examples/pick-and-place/cell-nodes-tls.yaml: TLS, a station, posts limited."""
    cell, diags = load_cell(EXAMPLE / "cell-nodes-tls.yaml")
    assert cell is not None and cell.nodes is not None, diags
    sec = cell.nodes.security
    assert sec.tls is not None and sec.tls.directory == EXAMPLE / "certs"
    assert sec.stations == ("operator",)
    assert sec.posters("arm", ("line", "arm", "gripper", "operator")) == ("line", "operator")
    assert sec.posters("conveyor", ("line", "arm")) == ("line", "arm")


def test_certificates_made_elsewhere_are_taken_as_given(tmp_path: Path) -> None:
    """tls: {ca, certificates}: each node's session uses the files the cell names, and
    nothing is made; a node the mapping leaves out is V828."""
    from statectl.channels.distributed.certs import ensure_certificates, tls_files

    ensure_certificates(tmp_path / "pki", {"a": ("127.0.0.1",), "b": ()})
    made = sorted(p.name for p in (tmp_path / "pki").iterdir())
    given = (
        "security:\n  tls:\n    ca: pki/ca.pem\n    certificates:\n"
        "      a: {certificate: pki/a.pem, key: pki/a-key.pem}\n"
        "      b: {certificate: pki/b.pem, key: pki/b-key.pem}\n"
    )
    cell, diags = _cell(tmp_path, "tls/127.0.0.1:7000", given)
    assert cell is not None, diags
    assert tls_files(cell, "a") == tuple(
        tmp_path / "pki" / f for f in ("ca.pem", "a.pem", "a-key.pem")
    )
    assert sorted(p.name for p in (tmp_path / "pki").iterdir()) == made
    cell, diags = _cell(tmp_path, "tls/127.0.0.1:7000", given.rsplit("      b:", 1)[0])
    assert cell is None and any("no certificate for b" in d for d in diags), diags


def test_a_station_connects_off_loopback_only_over_tls(tmp_path: Path) -> None:
    """statectl dashboard --connect tcp/10.0.0.5:... on a cell without TLS: exit 1 with
    V827's advice, before anything opens."""
    from statectl.channels.cli.node import dashboard_main

    _cell(tmp_path, "tcp/127.0.0.1:7000")
    err = io.StringIO()
    code = dashboard_main(
        str(tmp_path / "c.yaml"), connect=["tcp/10.0.0.5:7000"], out=io.StringIO(), err=err
    )
    assert code == 1 and "off loopback without TLS" in err.getvalue()


def test_access_control_lets_each_node_put_only_its_own_keys() -> None:
    """The access control made from the example TLS cell: the line's node may put its link
    streams, hellos and its devices' acks and states, posts where posts: lets it."""
    cell, _ = load_cell(EXAMPLE / "cell-nodes-tls.yaml")
    assert cell is not None
    acl = access_control(cell)
    rules = {r["id"]: r for r in acl["rules"]}
    assert acl["default_permission"] == "deny"
    assert set(rules["put-line"]["key_exprs"]) == {
        f"{ROOT}/post/arm",
        f"{ROOT}/post/conveyor",
        f"{ROOT}/post/sensor",
        f"{ROOT}/link/line/*",
        f"{ROOT}/hello/line/*",
        *(f"{ROOT}/{k}/{d}" for k in ("ack/*", "state") for d in ("conveyor", "sensor")),
    }
    assert f"{ROOT}/post/arm" not in rules["put-gripper"]["key_exprs"]
    assert rules["put-operator"]["key_exprs"] == [
        f"{ROOT}/post/{d}" for d in ("conveyor", "arm", "gripper", "sensor")
    ]
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects["is-line"] == {"id": "is-line", "cert_common_names": ["line"]}


class _Sample:
    """What a Zenoh callback reads of a sample: its key and payload."""

    def __init__(self, key: str, data: bytes) -> None:
        self.key_expr = key
        self.payload = self
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data

    def to_string(self) -> str:
        return self._data.decode()


@pytest.mark.parametrize(("n", "kept"), [(5, 2), (-1, 2), (1, 1), (2, 0)])
def test_an_acknowledgement_of_what_was_never_sent_forgets_nothing(n: int, kept: int) -> None:
    """The line's node has sent two link events to the arm: an ack of 5 (never sent) or
    -1 forgets none of them (an ack of 5 used to drop both, unsent); 1 and 2 as before."""
    from statectl.channels.distributed import NodeSystem, Wire
    from statectl.run.runner.cells import cell_setups
    from statectl.run.runtime import SimClock

    cell, _ = load_cell(EXAMPLE / "cell-nodes.yaml")
    assert cell is not None and cell.nodes is not None
    mine = cell.nodes.node("line").devices
    setups = tuple(s for s in cell_setups(cell, journalled=False) if s.name in mine)
    wire = Wire(cell, "line", NodeSystem(setups, SimClock(), None, cell), out=io.StringIO())
    stream = wire.outbound["arm"]
    stream.add("Movement", None)
    stream.add("Movement", None)
    ack = json.dumps({"e": stream.epoch, "n": n, "r": False}).encode()
    wire._on_ack(_Sample(f"{ROOT}/ack/line/arm", ack))
    assert len(stream.unacked) == kept


# -- bounds and escaping, without a session -----------------------------------------------------


@pytest.mark.parametrize(
    ("payload", "problem"),
    [
        (b'["e",1,"Movement",null]', None),
        (b"[" * MAX_DEPTH + b"]" * MAX_DEPTH, None),
        (b"[" * (MAX_DEPTH + 1) + b"]" * (MAX_DEPTH + 1), "nested deeper"),
        (b'["' + b"[" * 100 + b'"]', None),  # brackets inside a string are text
        (b'["\\"' + b"[" * 100 + b'"]', None),  # after an escaped quote, still text
        (DEEP, "nested deeper"),
        (b"x" * (64 * 1024 + 1), "bytes"),
    ],
)
def test_a_payload_is_bounded_before_it_is_decoded(payload: bytes, problem: str | None) -> None:
    """Size and nesting are read from the bytes, before any decoder recurses."""
    got = payload_problem(payload)
    assert got is None if problem is None else (got is not None and problem in got)


@pytest.mark.parametrize("reader", [parse_snapshot, read_post], ids=["state", "post"])
def test_a_deep_message_is_unreadable_not_a_recursion_error(reader: Any) -> None:
    """1,000 levels of nesting in a state or a post: Unreadable, never RecursionError."""
    with pytest.raises(Unreadable, match="nested deeper"):
        reader(b'{"ev":"x","a":' + DEEP + b"}")


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("Movement", "'Movement'"),
        ("Move\nment", "'Move\\nment'"),
        ("Move\u202ement", "'Move\\u202ement'"),
        ("A\x00B\x1b[2J", "'A\\x00B\\x1b[2J'"),
    ],
)
def test_names_are_printed_escaped(name: str, expected: str) -> None:
    """A name from the wire cannot end a log line, reorder it or drive the terminal."""
    assert shown(name) == expected
    assert printable(f"event {name} refused") == f"event {expected[1:-1]} refused"


def test_a_long_name_is_cut_when_printed() -> None:
    """A 1 MB name prints as its first 80 characters and its length."""
    assert re.fullmatch(r"'M{80}'\.\.\. \(1000000 characters\)", shown("M" * 1_000_000))
    assert len(printable("x" * 1_000_000)) < 500
