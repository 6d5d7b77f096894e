"""The seeded bug that shows only when a link is lost: found by verify, reproduced by killing
a node process (examples/pick-and-place/cell-lossy-nodes.yaml, docs/distributed.md).

`statectl verify` reports the shortest trace; the test plays it on three real
`statectl node` processes (loopback, explicit endpoints, the model alone: every
stimulus, completions too, is a line on the node's stdin), SIGKILLs the node on the
far side of each link event the trace loses just before the step that loses it, so
the `on_peer_down: drop` link drops it, and resumes that node from its journal after
the step. The cell reaches the trace's bad global state and the line's node reports
the invariant violated.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from test_distributed import WAIT, Cluster, free_ports, open_view, wait_states

pytest.importorskip("zenoh")

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "pick-and-place"
LOSSY = EXAMPLE / "cell-lossy-nodes.yaml"
PORTS = ("7461", "7462", "7463")
NODES = ("line", "arm", "gripper")
NODE_OF = {"conveyor": "line", "sensor": "line", "arm": "arm", "gripper": "gripper"}


def verify_json(cell: Path) -> dict[str, Any]:
    """`statectl verify CELL --json` as a user runs it."""
    done = subprocess.run(
        [sys.executable, "-m", "statectl", "verify", str(cell), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ},
    )
    assert done.returncode == 1, done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    return report


class _ModelOnly(Cluster):
    """Nodes with no driver (``--driver none``): every completion is a line on stdin."""

    def start(self, node: str, *extra: str) -> subprocess.Popen[str]:
        log = self.tmp / f"{node}.log"
        self.logs[node] = log
        proc = subprocess.Popen(
            [sys.executable, "-m", "statectl", "node", str(self.cell), "--node", node, *extra],
            stdin=subprocess.PIPE,
            stdout=log.open("a"),
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        self.procs[node] = proc
        return proc


@pytest.fixture
def lossy(tmp_path: Path) -> Iterator[Cluster]:
    text = LOSSY.read_text()
    for old, new in zip(PORTS, free_ports(3), strict=True):
        text = text.replace(f"127.0.0.1:{old}", f"127.0.0.1:{new}")
    for device in ("conveyor", "arm", "gripper", "sensor"):
        text = text.replace(f" {device}.yaml", f" {EXAMPLE / device}.yaml")
    c = _ModelOnly(tmp_path, text)
    yield c
    if c.view is not None:
        c.view.close()  # type: ignore[attr-defined]
    c.stop()


def _wait_log(c: Cluster, node: str, text: str, count: int = 1) -> None:
    deadline = time.monotonic() + WAIT
    while c.log(node).count(text) < count:
        assert time.monotonic() < deadline, c.log(node)
        time.sleep(0.05)


def test_verify_finds_the_lost_link_bug_and_killing_a_node_reproduces_it(lossy: Cluster) -> None:
    """The trace verify reports (a Part out lost) replayed on node processes, with the
    line's node SIGKILLed where the trace loses the link, ends in verify's bad state and
    the line's node reports the same invariant violated."""
    c = lossy
    report = verify_json(c.cell)
    finding = next(f for f in report["findings"] if f["kind"] == "invariant")
    assert finding["name"] == "no-part-left-on-a-running-belt"
    steps = finding["trace"]["steps"]
    assert any(d.get("fate") == "lost" for s in steps for d in s["deliveries"])
    db = c.tmp / "line.db"
    journal = {"line": ("--journal", str(db))}
    for node in NODES:
        c.start(node, "--driver", "none", *journal.get(node, ()))
    view = open_view(c)
    assert view.wait_for(lambda a: len(a) == 4, WAIT)  # type: ignore[attr-defined]
    for node in NODES:
        _wait_log(c, node, "peers: ")
    time.sleep(0.5)  # every node has every other's state and presence
    for step in steps:
        lost = [d for d in step["deliveries"] if d.get("fate") == "lost"]
        for d in lost:  # the far side of the link dies just before its event is sent
            far, near = NODE_OF[d["to"]], NODE_OF[d["from"]]
            time.sleep(0.3)  # the far node's journal has committed its steps
            c.kill(far)
            _wait_log(c, near, f"peer {far} lost")
        c.send(NODE_OF[step["to"]], f"{step['to']}: {step['event']}")
        down = {NODE_OF[d["to"]] for d in lost}
        wait_states(view, {k: v for k, v in step["state"].items() if NODE_OF[k] not in down})
        for far in down:  # back from its journal: the lost event is not there
            c.start(far, "--driver", "none", *journal[far], "--resume")
            _wait_log(c, far, "running")
    wait_states(view, steps[-1]["state"])
    assert steps[-1]["state"] == {
        "conveyor": "Running",
        "arm": "Blocked",
        "gripper": "Open",
        "sensor": "Detected",
    }
    log = c.log("line")
    assert "VIOLATED invariant no-part-left-on-a-running-belt" in log
    assert finding["message"].split(" is false in ")[1] in log
