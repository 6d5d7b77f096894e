"""A cell on several `statectl node` processes, links over Zenoh on loopback only.

Every node is a real process started and stopped (by PID) by the tests; multicast
scouting is off and each node listens on a port the OS gave out, so nothing
outside 127.0.0.1 is touched. See docs/distributed.md.
"""

from __future__ import annotations

import io
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import pytest

from statectl.cell.model import load_cell
from statectl.cell.nodes import PeerDown
from statectl.channels.distributed.streams import Inbound, Outbound, Verdict

zenoh = pytest.importorskip("zenoh")

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "pick-and-place"
DEVICES = {n: str(EXAMPLE / f"{n}.yaml") for n in ("conveyor", "arm", "gripper", "sensor")}
LINKS = """\
links:
  - {from: sensor, enters: Detected, to: conveyor, send: Arrive}
  - {from: conveyor, enters: Arrived, to: arm, send: Movement%(movement)s}
  - {from: arm, raises: Movement completion, to: gripper, send: Grip}
  - {from: gripper, enters: Closed, to: arm, send: Initialization}
  - {from: gripper, enters: Closed, to: sensor, send: Part out}
  - {from: arm, raises: Initialization completion, to: gripper, send: Release,
     guard: "In('gripper.Closed')"}
  - {from: gripper, raises: Release completion, to: conveyor, send: Resume}
"""
WAIT = 20.0  # seconds a step of the cell may take on this shared machine, at most


def free_ports(n: int) -> list[int]:
    """Ports the OS hands out now (held open together so they differ)."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def cell_text(
    ports: Mapping[str, int],
    *,
    peer_lost: bool = True,
    movement: str = "",
    extra_nodes: str = "",
) -> str:
    """The pick-and-place cell on three nodes (line, arm, gripper) listening on ``ports``."""
    ep = {n: f"tcp/127.0.0.1:{p}" for n, p in ports.items()}
    devices = "".join(f"  {n}: {p}\n" for n, p in DEVICES.items())
    line_lost = "    peer_lost: {conveyor: Stop}\n" if peer_lost else ""
    arm_lost = "    peer_lost: {arm: Error}\n" if peer_lost else ""
    return (
        f"cell: PickAndPlace\ndevices:\n{devices}nodes:\n"
        f"  line:\n    devices: [conveyor, sensor]\n    listen: [{ep['line']}]\n"
        f"    lease: 0.5\n{line_lost}"
        f"  arm:\n    devices: [arm]\n    listen: [{ep['arm']}]\n    connect: [{ep['line']}]\n"
        f"    lease: 0.5\n{arm_lost}"
        f"  gripper:\n    devices: [gripper]\n    listen: [{ep['gripper']}]\n"
        f"    connect: [{ep['line']}, {ep['arm']}]\n    lease: 0.5\n{extra_nodes}"
        + LINKS
        % {"movement": movement}
    )


CONFIG = "devices:\n" + "".join(
    f"  {n}: {{driver: sim-twin, options: {{delay: 0.1}}}}\n" for n in DEVICES
)


class Cluster:
    """The node processes of one test: started with pipes, stopped by PID at the end."""

    def __init__(self, tmp: Path, text: str) -> None:
        self.tmp = tmp
        self.cell = tmp / "cell.yaml"
        self.cell.write_text(text)
        self.config = tmp / "drivers.yaml"
        self.config.write_text(CONFIG)
        self.procs: dict[str, subprocess.Popen[str]] = {}
        self.logs: dict[str, Path] = {}
        self.view: object = None

    def start(self, node: str, *extra: str) -> subprocess.Popen[str]:
        log = self.tmp / f"{node}.log"
        self.logs[node] = log
        proc = subprocess.Popen(
            [
                *(sys.executable, "-m", "statectl", "node", str(self.cell), "--node", node),
                *("--config", str(self.config), *extra),
            ],
            stdin=subprocess.PIPE,
            stdout=log.open("a"),
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        self.procs[node] = proc
        return proc

    def send(self, node: str, line: str) -> None:
        stdin = self.procs[node].stdin
        assert stdin is not None
        stdin.write(line + "\n")
        stdin.flush()

    def kill(self, node: str) -> None:
        proc = self.procs.pop(node)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)

    def log(self, node: str) -> str:
        return self.logs[node].read_text()

    def stop(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGCONT)  # a test may have stopped it
                os.kill(proc.pid, signal.SIGTERM)
        for proc in self.procs.values():
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(10)
        self.procs.clear()


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[Callable[..., Cluster]]:
    made: list[Cluster] = []
    views: list[object] = []

    def make(**options: object) -> Cluster:
        ports = dict(zip(("line", "arm", "gripper"), free_ports(3), strict=True))
        c = Cluster(tmp_path, cell_text(ports, **options))  # type: ignore[arg-type]
        made.append(c)
        return c

    yield make
    for v in views:
        v.close()  # type: ignore[attr-defined]
    for c in made:
        if c.view is not None:
            c.view.close()  # type: ignore[attr-defined]
        c.stop()


def open_view(c: Cluster) -> object:
    from statectl.channels.distributed.view import CellView

    cell, diags = load_cell(c.cell)
    assert cell is not None, diags
    c.view = CellView(cell).open()
    return c.view


def states(view: object) -> dict[str, str]:
    return {d: ",".join(sorted(a)) for d, a in view.active().items()}  # type: ignore[attr-defined]


def wait_states(view: object, expected: Mapping[str, str], timeout: float = WAIT) -> None:
    def holds(active: Mapping[str, frozenset[str]]) -> bool:
        return all(",".join(sorted(active.get(d, ()))) == s for d, s in expected.items())

    ok = view.wait_for(holds, timeout)  # type: ignore[attr-defined]
    assert ok, f"expected {dict(expected)}, the cell shows {states(view)}"


def one_process(cell: Path, lines: list[str]) -> dict[str, str]:
    """The global state `statectl run CELL` reaches on ``lines`` (one process, batch)."""
    from statectl.channels.cli.run import run

    out = io.StringIO()
    code = run(str(cell), events=io.StringIO("\n".join(lines) + "\n"), out=out, err=io.StringIO())
    assert code == 0, out.getvalue()
    finals = {}
    for line in out.getvalue().splitlines():
        if line.startswith("final "):
            device, _, state = line.removeprefix("final ").partition(": ")
            finals[device] = state.replace(", ", ",")
    return finals


ONE_CELL = EXAMPLE / "cell.yaml"
NODE_OF = {"conveyor": "line", "sensor": "line", "arm": "arm", "gripper": "gripper"}


def start_all(c: Cluster, *extra: str) -> object:
    for node in ("line", "arm", "gripper"):
        c.start(node, *extra)
    view = open_view(c)
    ok = view.wait_for(lambda a: len(a) == 4, WAIT)  # type: ignore[attr-defined]
    assert ok, {n: c.log(n) for n in c.logs}
    for node in ("line", "arm", "gripper"):  # each node sees both others
        deadline = time.monotonic() + WAIT
        while "peers: " not in c.log(node) or not _sees_all(c.log(node)):
            assert time.monotonic() < deadline, c.log(node)
            time.sleep(0.1)
    return view


def _sees_all(log: str) -> bool:
    last = [line for line in log.splitlines() if "peers: " in line][-1]
    return len(last.split("peers: ")[1].split(", ")) == 2


# -- the nodes: section -----------------------------------------------------------------------


def _load(tmp_path: Path, text: str) -> tuple[object, list[str]]:
    p = tmp_path / "c.yaml"
    p.write_text(text)
    cell, diags = load_cell(p)
    return cell, [d.code for d in diags]


GOOD = {"line": 7451, "arm": 7452, "gripper": 7453}


@pytest.mark.parametrize(
    ("change", "codes"),
    [
        (lambda t: t, []),
        (lambda t: t.replace("devices: [arm]", "devices: [arm, conveyor]"), ["V820"]),
        (lambda t: t.replace("devices: [gripper]", "devices: []"), ["V820"]),
        (lambda t: t.replace("  arm:\n    devices", "  arm-1:\n    devices"), ["V821", "V820"]),
        (lambda t: t.replace("tcp/127.0.0.1:7452]", "localhost]", 1), ["V822"]),
        (lambda t: t.replace("tcp/127.0.0.1:7452]", "tcp/127.0.0.1:99999]", 1), ["V822"]),
        (lambda t: t.replace("tcp/127.0.0.1:7452]", "tcp/127.0.0.1:port]", 1), ["V822"]),
        (
            lambda t: t.replace("tcp/127.0.0.1:7452]", "tcp/127.0.0.1:" + "9" * 5000 + "]", 1),
            ["V822"],
        ),
        (lambda t: t.replace("7452]", "\uff17\uff14\uff15\uff12]", 1), ["V822"]),  # fullwidth
        (lambda t: t.replace("tcp/127.0.0.1:7452]", "tcp/127.0.0.1:0]", 1), []),  # any free port
        (lambda t: t.replace("tcp/127.0.0.1:7452]", "'tcp/[::1]:7452#iface=lo']", 1), []),
        (lambda t: t.replace("connect: [tcp/127.0.0.1:7451]", "connect: [udp/h:0]", 1), ["V822"]),
        (lambda t: t.replace("send: Movement}", "send: Movement, on_peer_down: lose}"), ["V823"]),
        (lambda t: t.replace("send: Movement}", "send: Movement, dropped: Stop}"), ["V824"]),
        (lambda t: t.replace("{conveyor: Stop}", "{arm: Stop}"), ["V825"]),
        (lambda t: t.replace("{conveyor: Stop}", "{conveyor: Halt}"), ["V809"]),
        (
            lambda t: t.replace("Movement}", "Movement, on_peer_down: drop, dropped: X}"),
            ["V809"],
        ),
        (lambda t: t.replace("lease: 0.5", "lease: 0", 1), ["V804"]),
    ],
)
def test_nodes_section_is_checked(
    tmp_path: Path, change: Callable[[str], str], codes: list[str]
) -> None:
    """Each mistake in nodes: or a link's delivery keys is its own V8xx with the line."""
    cell, found = _load(tmp_path, change(cell_text(GOOD)))
    assert found == codes
    assert (cell is None) == bool(codes)


def test_delivery_keys_without_nodes_warn(tmp_path: Path) -> None:
    """on_peer_down in a one-process cell is accepted with warning V826 and changes nothing."""
    text = cell_text(GOOD, movement=", on_peer_down: drop")
    one = text[: text.index("nodes:")] + text[text.index("links:") :]
    cell, found = _load(tmp_path, one)
    assert found == ["V826"]
    assert cell is not None and cell.nodes is None  # type: ignore[attr-defined]


def test_nodes_section_values(tmp_path: Path) -> None:
    """The values say which node runs a device, its endpoints, lease, peer_lost and policies."""
    cell, found = _load(tmp_path, cell_text(GOOD, movement=", on_peer_down: drop, dropped: Stop"))
    assert found == []
    nodes = cell.nodes  # type: ignore[attr-defined]
    assert nodes.node_of("gripper") == "gripper"
    assert nodes.node("gripper").connect == ("tcp/127.0.0.1:7451", "tcp/127.0.0.1:7452")
    assert nodes.node("arm").peer_lost == (("arm", "Error"),)
    assert nodes.node("line").lease == 0.5
    assert nodes.delivery[1].on_peer_down is PeerDown.DROP
    assert nodes.delivery[1].dropped == "Stop"
    assert nodes.delivery[0].on_peer_down is PeerDown.QUEUE


# -- streams ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("offers", "verdicts"),
    [
        ([("e1", 1), ("e1", 2), ("e1", 3)], ["apply", "apply", "apply"]),
        ([("e1", 1), ("e1", 1), ("e1", 2)], ["apply", "duplicate", "apply"]),
        ([("e1", 1), ("e1", 3), ("e1", 2)], ["apply", "gap", "apply"]),
        ([("e1", 5), ("e1", 6), ("e1", 4)], ["apply", "apply", "duplicate"]),
        ([("e1", 1), ("e2", 1), ("e2", 2)], ["apply", "apply", "apply"]),
    ],
)
def test_inbound_applies_each_number_once_in_order(
    offers: list[tuple[str, int]], verdicts: list[str]
) -> None:
    """A stream applies the next number only; older ones are duplicates, newer ones a gap
    (each epoch announced by its sender's hello first)."""
    inbound = Inbound()
    got = []
    for e, n in offers:
        if inbound.announced.get(("line", "arm")) != e:
            inbound.announce("line", "arm", e)
        got.append(inbound.offer("line", "arm", e, n)[0].value)
    assert got == verdicts
    assert Verdict.APPLY.value == "apply"


def test_outbound_keeps_until_acknowledged() -> None:
    """Acknowledgements are cumulative: everything up to n is forgotten, the rest kept in order."""
    out = Outbound("arm", "arm", "e1")
    for event in ("A", "B", "C"):
        out.add(event, None)
    out.ack(2)
    assert [(n, e) for n, e, _ in out.unacked] == [(3, "C")]
    out.ack(1)
    assert out.acked == 2 and len(out.unacked) == 1


# -- real processes ---------------------------------------------------------------------------

SCRIPT = ["conveyor: Start", "sensor: Part in", "conveyor: Stop"]


def test_three_nodes_reach_the_global_states_of_one_process(
    cluster: Callable[..., Cluster],
) -> None:
    """Three node processes reach, after each event line, the states `statectl run` reaches.

    Every line goes to the gripper's node, which forwards it to the device's node.
    """
    c = cluster()
    view = start_all(c)
    for i, line in enumerate(SCRIPT, 1):
        expected = one_process(ONE_CELL, SCRIPT[:i])
        assert NODE_OF[line.split(":")[0]] != "gripper"
        c.send("gripper", line)
        wait_states(view, expected)
    assert "peers: arm, gripper" in c.log("line")


def test_sigkill_gives_linked_devices_their_declared_event(
    cluster: Callable[..., Cluster],
) -> None:
    """A node killed with SIGKILL: a device linked with it takes its peer_lost event in bound."""
    c = cluster()
    view = start_all(c)
    c.send("line", "conveyor: Start")
    wait_states(view, {"conveyor": "Running"})
    killed = time.monotonic()
    c.kill("arm")
    wait_states(view, {"conveyor": "Stopped"})
    took = time.monotonic() - killed
    assert took < 0.5 + 2.5, f"conveyor stopped {took:.2f} s after the kill (lease 0.5 s)"
    assert "peer arm lost" in c.log("line")
    deadline = time.monotonic() + 2.5  # the gripper's node notices it by itself
    while "peer arm lost" not in c.log("gripper"):
        assert time.monotonic() < deadline, c.log("gripper")
        time.sleep(0.05)


def test_cut_off_node_is_lost_within_its_lease_and_comes_back(
    cluster: Callable[..., Cluster],
) -> None:
    """A node that stops answering (SIGSTOP) is lost within its lease; SIGCONT brings it back."""
    c = cluster()
    view = start_all(c)
    c.send("line", "conveyor: Start")
    wait_states(view, {"conveyor": "Running"})
    arm = c.procs["arm"]
    stopped = time.monotonic()
    os.kill(arm.pid, signal.SIGSTOP)
    try:
        wait_states(view, {"conveyor": "Stopped"})
        took = time.monotonic() - stopped
        assert 0.2 < took < 0.5 + 1.5, f"noticed {took:.2f} s after the cut (lease 0.5 s)"
    finally:
        os.kill(arm.pid, signal.SIGCONT)
    deadline = time.monotonic() + WAIT
    while c.log("line").count("peer arm up") < 2:
        assert time.monotonic() < deadline, "\n".join(c.log(n) for n in ("line", "arm", "gripper"))
        time.sleep(0.05)


def _count(db: Path, device: str, event: str) -> tuple[int, int]:
    """(accepted link events, steps that processed one) for ``device`` in ``db``."""
    con = sqlite3.connect(db)
    try:
        inbox = con.execute(
            "SELECT count(*) FROM inbox WHERE device = ? AND event = ?", (device, event)
        ).fetchone()[0]
        steps = con.execute(
            "SELECT count(*) FROM steps WHERE device = ? AND event = ? AND inbox IS NOT NULL",
            (device, event),
        ).fetchone()[0]
        return int(inbox), int(steps)
    finally:
        con.close()


@pytest.mark.parametrize("guarantee", ["prompt", "durable-first"])
def test_killed_receiver_resumes_and_gets_queued_link_once(
    cluster: Callable[..., Cluster], guarantee: str
) -> None:
    """A queue link's event sent while its target's node is dead arrives once after --resume."""
    c = cluster(peer_lost=False)
    dbs = {n: c.tmp / f"{n}.db" for n in ("line", "arm", "gripper")}
    for node in ("line", "arm", "gripper"):
        c.start(node, "--journal", str(dbs[node]), "--guarantee", guarantee)
    view = open_view(c)
    assert view.wait_for(lambda a: len(a) == 4, WAIT)  # type: ignore[attr-defined]
    c.send("line", "conveyor: Start")
    wait_states(view, {"conveyor": "Running"})
    c.kill("arm")
    deadline = time.monotonic() + WAIT
    while "peer arm lost" not in c.log("line"):
        assert time.monotonic() < deadline, c.log("line")
        time.sleep(0.05)
    c.send("line", "sensor: Part in")  # conveyor Arrived: Movement to the dead arm is queued
    wait_states(view, {"conveyor": "Arrived", "sensor": "Detected"})
    c.start("arm", "--journal", str(dbs["arm"]), "--resume", "--guarantee", guarantee)
    wait_states(view, one_process(ONE_CELL, SCRIPT[:2]))
    assert _count(dbs["arm"], "arm", "Movement") == (1, 1)
    assert _count(dbs["gripper"], "gripper", "Release") == (1, 1)


def test_killed_sender_resumes_and_nothing_is_applied_twice(
    cluster: Callable[..., Cluster],
) -> None:
    """A sender killed after its link events arrived resends from its journal; none twice."""
    c = cluster(peer_lost=False)
    dbs = {n: c.tmp / f"{n}.db" for n in ("line", "arm", "gripper")}
    for node in ("line", "arm", "gripper"):
        c.start(node, "--journal", str(dbs[node]))
    view = open_view(c)
    assert view.wait_for(lambda a: len(a) == 4, WAIT)  # type: ignore[attr-defined]
    c.send("line", "conveyor: Start")
    c.send("line", "sensor: Part in")
    wait_states(view, one_process(ONE_CELL, SCRIPT[:2]))
    c.kill("line")  # maybe before its last steps were committed: they come again
    c.start("line", "--journal", str(dbs["line"]), "--resume")
    deadline = time.monotonic() + WAIT
    while c.log("line").count("peer arm up") < 2:
        assert time.monotonic() < deadline, "\n".join(c.log(n) for n in ("line", "arm", "gripper"))
        time.sleep(0.05)
    time.sleep(1.5)  # hello, acknowledgement and any resend: RESEND_AFTER is 0.5 s
    wait_states(view, one_process(ONE_CELL, SCRIPT[:2]))
    assert _count(dbs["arm"], "arm", "Movement") == (1, 1)
    c.send("line", "conveyor: Stop")
    wait_states(view, one_process(ONE_CELL, SCRIPT))
    assert _count(dbs["arm"], "arm", "Movement") == (1, 1)


def test_drop_link_raises_its_declared_event_while_the_peer_is_down(
    cluster: Callable[..., Cluster],
) -> None:
    """A drop link to a dead node sends nothing and its dropped event reaches the source."""
    c = cluster(peer_lost=False, movement=", on_peer_down: drop, dropped: Stop")
    view = start_all(c)
    c.send("line", "conveyor: Start")
    wait_states(view, {"conveyor": "Running"})
    c.kill("arm")
    deadline = time.monotonic() + WAIT
    while "peer arm lost" not in c.log("line"):
        assert time.monotonic() < deadline, c.log("line")
        time.sleep(0.05)
    c.send("line", "sensor: Part in")  # Arrived -> Movement dropped -> Stop to the conveyor
    wait_states(view, {"conveyor": "Stopped", "sensor": "Detected"})
    c.start("arm")
    wait_states(view, {"arm": "Blocked"})
    time.sleep(1.0)  # nothing queued may arrive late
    assert states(view)["arm"] == "Blocked"


# -- the dashboard from Zenoh -----------------------------------------------------------------


def _http(url: str, body: dict[str, object] | None = None, token: str | None = None) -> object:
    import json
    import urllib.error
    import urllib.request

    headers = {"Content-Type": "application/json"}
    if token is not None:
        headers["X-Statectl-Token"] = token
    data = json.dumps(body).encode() if body is not None else None
    request = urllib.request.Request(url, data=data, headers=headers)
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return json.loads(response.read())
    except urllib.error.HTTPError as exc:
        return exc.code


def _shown(url: str) -> dict[str, str]:
    snapshot = _http(url + "api/state")
    assert isinstance(snapshot, dict)
    return {d["name"]: ",".join(d["active"]) for d in snapshot["devices"]}


def test_operator_station_shows_and_drives_the_whole_cell(
    cluster: Callable[..., Cluster],
) -> None:
    """`statectl dashboard CELL` shows every node's devices live; a post needs the token."""
    pytest.importorskip("aiohttp")
    import threading

    from statectl.channels.distributed.dashboard import station

    c = cluster()
    view = start_all(c)
    cell, _ = load_cell(c.cell)
    assert cell is not None
    stop = threading.Event()
    urls: list[str] = []
    token = "a-token-of-twenty-chars"
    thread = threading.Thread(
        target=station,
        args=(cell,),
        kwargs={
            "connect": None,
            "settings": ("127.0.0.1", 0, token),
            "token_from": "test",
            "out": io.StringIO(),
            "stop": stop,
            "ready": urls.append,
        },
        daemon=True,
    )
    thread.start()
    try:
        deadline = time.monotonic() + WAIT
        while not urls or len(_shown(urls[0])) < 4 or "" in _shown(urls[0]).values():
            assert time.monotonic() < deadline, urls and _shown(urls[0])
            time.sleep(0.1)
        url = urls[0]
        assert _shown(url) == one_process(ONE_CELL, [])
        refused = _http(url + "api/post", {"device": "conveyor", "event": "Start"})
        assert refused == 401
        accepted = _http(url + "api/post", {"device": "conveyor", "event": "Start"}, token)
        assert isinstance(accepted, dict) and accepted["accepted"] is True
        wait_states(view, {"conveyor": "Running"})
        deadline = time.monotonic() + WAIT
        while _shown(url)["conveyor"] != "Running":
            assert time.monotonic() < deadline, _shown(url)
            time.sleep(0.1)
    finally:
        stop.set()
        thread.join(10)


# -- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "code", "says"),
    [
        (["--node", "nowhere"], 2, "no node 'nowhere'"),
        (["--node", "line", "--resume"], 2, "--resume needs --journal"),
        (["--node", "line", "--guarantee", "maybe"], 2, "--guarantee"),
    ],
)
def test_node_usage_errors(
    tmp_path: Path, args: list[str], code: int, says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A wrong flag is a one-line message and exit 2; nothing starts."""
    from statectl.channels.cli import main

    cell = tmp_path / "cell.yaml"
    cell.write_text(cell_text(dict(zip(("line", "arm", "gripper"), free_ports(3), strict=True))))
    assert main(["node", str(cell), *args]) == code
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err


def test_node_of_a_cell_without_nodes_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    """`statectl node` on a one-process cell says it needs a nodes: section (exit 1)."""
    from statectl.channels.cli import main

    assert main(["node", str(ONE_CELL), "--node", "line"]) == 1
    assert "has no nodes: section" in capsys.readouterr().err


def test_node_whose_port_is_taken_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A listen endpoint another process holds is reported by Zenoh, exit 1, no traceback."""
    from statectl.channels.cli import main

    ports = dict(zip(("line", "arm", "gripper"), free_ports(3), strict=True))
    cell = tmp_path / "cell.yaml"
    cell.write_text(cell_text(ports))
    holder = socket.socket()
    holder.bind(("127.0.0.1", ports["line"]))
    holder.listen()
    try:
        code = main(["node", str(cell), "--node", "line", "--quiet"])
    finally:
        holder.close()
    err = capsys.readouterr().err
    assert code == 1 and "statectl node" in err and "Traceback" not in err


def test_node_warns_only_about_its_own_devices(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A journalled node prints the recovery warnings (J606/J608) of its own devices (the
    line's conveyor) and none of the devices that run on other nodes (arm, gripper). Its
    port is held, so it stops right after loading (exit 1) and nothing runs."""
    from statectl.channels.cli import main

    ports = dict(zip(("line", "arm", "gripper"), free_ports(3), strict=True))
    cell = tmp_path / "cell.yaml"
    cell.write_text(cell_text(ports))
    holder = socket.socket()
    holder.bind(("127.0.0.1", ports["line"]))
    holder.listen()
    try:
        journal = str(tmp_path / "line.db")
        code = main(["node", str(cell), "--node", "line", "--journal", journal, "--quiet"])
    finally:
        holder.close()
    err = capsys.readouterr().err
    assert code == 1
    warned = {line.split(":")[0] for line in err.splitlines() if " J60" in line}
    assert warned == {DEVICES["conveyor"]}


def test_node_dashboard_shows_the_devices_of_every_node(
    cluster: Callable[..., Cluster],
) -> None:
    """A node's --dashboard shows its own devices and the other nodes' live, one page."""
    pytest.importorskip("aiohttp")
    c = cluster()
    token = "another-token-of-twenty"
    c.start("line", "--dashboard", "--token", token)
    c.start("arm")
    c.start("gripper")
    view = open_view(c)
    assert view.wait_for(lambda a: len(a) == 4, WAIT)  # type: ignore[attr-defined]
    deadline = time.monotonic() + WAIT
    while "dashboard: " not in c.log("line"):
        assert time.monotonic() < deadline, c.log("line")
        time.sleep(0.05)
    url = c.log("line").split("dashboard: ")[1].split()[0]
    while _shown(url) != one_process(ONE_CELL, []):
        assert time.monotonic() < deadline, _shown(url)
        time.sleep(0.1)
    assert _http(url + "api/post", {"device": "gripper", "event": "Grip"}) == 401
    accepted = _http(url + "api/post", {"device": "conveyor", "event": "Start"}, token)
    assert isinstance(accepted, dict) and accepted["accepted"] is True
    wait_states(view, {"conveyor": "Running"})


class _Node:
    """One node's system and wire in this process (as `statectl node` makes them)."""

    def __init__(self, cell_path: Path, name: str) -> None:
        from statectl.channels.distributed.system import NodeSystem
        from statectl.channels.distributed.wire import Wire
        from statectl.run.runner.cells import load_setups
        from statectl.run.runtime import WallClock

        cell, _ = load_cell(str(cell_path))
        assert cell is not None and cell.nodes is not None
        setups, _ = load_setups(cell, journalled=False)
        mine = cell.nodes.node(name).devices
        self.out = io.StringIO()
        self.system = NodeSystem(
            tuple(s for s in setups if s.name in mine), WallClock(), None, cell
        )
        self.wire = Wire(cell, name, self.system, out=self.out)
        self.wire.open()
        self.system.start()
        self.wire.listen()

    def close(self) -> None:
        self.wire.close()
        self.system.close()


def test_a_lost_peer_is_asked_for_until_its_token_answers(tmp_path: Path) -> None:
    """A node asks for a lost peer's token once a lease: a peer Zenoh kept the session
    with but never declared again (a stalled process) is seen back, not lost for good."""
    ports = dict(zip(("line", "arm", "gripper"), free_ports(3), strict=True))
    path = tmp_path / "cell.yaml"
    path.write_text(cell_text(ports))
    line = _Node(path, "line")
    arm = _Node(path, "arm")
    try:
        deadline = time.monotonic() + WAIT
        while "arm" not in line.wire.up:
            assert time.monotonic() < deadline, line.out.getvalue()
            time.sleep(0.02)
        line.wire.up.discard("arm")  # what the stall left: lost here, its token never put again
        line.wire.lost_at["arm"] = time.monotonic()
        deadline = time.monotonic() + 5 * 0.5  # a few leases
        while "arm" not in line.wire.up:
            assert time.monotonic() < deadline, line.out.getvalue()
            time.sleep(0.02)
        assert line.out.getvalue().count("peer arm up") == 2, line.out.getvalue()
    finally:
        arm.close()
        line.close()
