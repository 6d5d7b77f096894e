"""What verify assumes, a `statectl node` enforces: `when`, invariants and guards across nodes.

The PackML unit on one node process and its two axes on another, on loopback with
explicit endpoints (tests/test_distributed.py's Cluster): the unit's node judges a
Start by the axes' last published states, watches the invariant over them, and its
Reset row's `In('axis1.Standstill')` reads the axis on the other node.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from test_distributed import WAIT, Cluster, free_ports, open_view, wait_states

pytest.importorskip("zenoh")

PACKML = Path(__file__).resolve().parent.parent / "examples" / "packml"
CONFIG = "devices:\n" + "".join(
    f"  {n}: {{driver: sim-twin, options: {{delay: 0.1}}}}\n" for n in ("unit", "axis1", "axis2")
)


def packml_nodes(name: str, ports: list[int]) -> str:
    """``examples/packml/NAME`` with a nodes: section: the unit here, both axes there."""
    text = (PACKML / name).read_text()
    for device in ("unit", "axis"):
        text = text.replace(f" {device}.yaml", f" {PACKML / device}.yaml")
    nodes = (
        "nodes:\n"
        f"  cell:\n    devices: [unit]\n    listen: [tcp/127.0.0.1:{ports[0]}]\n"
        f"  axes:\n    devices: [axis1, axis2]\n    listen: [tcp/127.0.0.1:{ports[1]}]\n"
        f"    connect: [tcp/127.0.0.1:{ports[0]}]\n"
    )
    return text.replace("links:\n", nodes + "links:\n", 1)


@pytest.fixture
def packml(tmp_path: Path) -> Iterator[Cluster]:
    made: list[Cluster] = []

    def make(name: str) -> Cluster:
        c = Cluster(tmp_path, packml_nodes(name, free_ports(2)))
        c.config.write_text(CONFIG)
        made.append(c)
        return c

    yield make  # type: ignore[misc]
    for c in made:
        if c.view is not None:
            c.view.close()  # type: ignore[attr-defined]
        c.stop()


def start(c: Cluster) -> object:
    c.start("cell")
    c.start("axes")
    view = open_view(c)
    assert view.wait_for(lambda a: len(a) == 3, WAIT), {n: c.log(n) for n in c.logs}  # type: ignore[attr-defined]
    for node in ("cell", "axes"):
        _wait_log(c, node, "peer ")
    return view


def _wait_log(c: Cluster, node: str, text: str, count: int = 1) -> None:
    deadline = time.monotonic() + WAIT
    while c.log(node).count(text) < count:
        assert time.monotonic() < deadline, c.log(node)
        time.sleep(0.05)


def _stop(c: Cluster, node: str) -> int:
    """SIGTERM one node by PID; its exit code."""
    proc = c.procs.pop(node)
    os.kill(proc.pid, signal.SIGTERM)
    return proc.wait(WAIT)


def _settled_mirror() -> None:
    """The unit's node takes the axes' states in as the view does; give it as long again."""
    time.sleep(0.3)


def test_a_node_refuses_a_start_its_when_forbids_by_the_remote_axes(packml: object) -> None:
    """A Start with the axes (on the other node) disabled is refused by the unit's node,
    from its own stdin and when forwarded from the axes' node; with both axes powered it
    runs; the node exits 1 saying how many it refused."""
    c = packml("cell.yaml")  # type: ignore[operator]
    view = start(c)
    c.send("cell", "unit: Start")
    _wait_log(c, "cell", "unit: Start refused")
    c.send("axes", "unit: Start")  # forwarded to the unit's node, judged there
    _wait_log(c, "cell", "unit: Start refused", 2)
    assert "axis1=Disabled, axis2=Disabled" in c.log("cell")
    c.send("axes", "axis1: Power On")
    c.send("axes", "axis2: Power On")
    wait_states(view, {"axis1": "Standstill", "axis2": "Standstill"})
    _settled_mirror()
    c.send("cell", "unit: Start")
    wait_states(view, {"unit": "Execute"})
    assert _stop(c, "cell") == 1
    assert "2 environment command(s) refused" in c.log("cell")
    assert _stop(c, "axes") == 0


def test_a_node_sees_an_invariant_broken_on_another_node_and_reacts(packml: object) -> None:
    """Powering axis1 off (its node) while the unit executes (this node): the unit's node
    reports VIOLATED from the mirrored state, aborts the unit and exits 1; the axes' node
    does not watch that invariant. Reset then waits for both remote axes to stand still."""
    c = packml("cell-buggy.yaml")  # type: ignore[operator]
    view = start(c)
    c.send("axes", "axis1: Power On")
    c.send("axes", "axis2: Power On")
    wait_states(view, {"axis1": "Standstill", "axis2": "Standstill"})
    _settled_mirror()
    c.send("cell", "unit: Start")
    wait_states(view, {"unit": "Execute", "axis1": "Standstill", "axis2": "Standstill"})
    c.send("axes", "axis1: Power Off")
    wait_states(view, {"unit": "Aborted", "axis1": "Disabled"})
    log = c.log("cell")
    assert "VIOLATED invariant axes-powered-while-producing" in log
    assert "axis1=Disabled" in log and "sending unit: Abort" in log
    c.send("cell", "unit: Reset")  # the guard reads axis1 (Disabled) on the other node
    _wait_log(c, "cell", "Reset")
    time.sleep(0.5)
    wait_states(view, {"unit": "Aborted"})
    c.send("axes", "axis1: Power On")
    wait_states(view, {"axis1": "Standstill"})
    _settled_mirror()
    c.send("cell", "unit: Reset")
    wait_states(view, {"unit": "Idle"})
    assert _stop(c, "cell") == 1
    assert "1 invariant violation(s)" in c.log("cell")
    assert _stop(c, "axes") == 0
    assert "VIOLATED" not in c.log("axes")
