"""System.submit, the one front door (run/door.py, system.py rule 8).

Every channel hands its events to ``submit`` (or ``post``, submit without a handle), and
the run's own events (links, drivers' completions, timeouts, monitors' faults) pass the
same check on their way in: the handle resolves with the outcome of the device's step,
with and without a journal, from any thread and from asyncio; the door alone decides
whether the submitting thread runs the step; a refused command, whatever its channel,
changes nothing and is journalled as refused.
"""

from __future__ import annotations

import ast
import asyncio
import io
import logging
import threading
from pathlib import Path
from typing import Any

import pytest

import statectl
from statectl.cell.model import load_cell
from statectl.channels.cli.demo import motor_chart
from statectl.kernel.errors import StatectlError
from statectl.kernel.semantics import Outcome
from statectl.run.commands import ANYONE, CommandRefused, Commands, Grant, Origin
from statectl.run.devices import make_driver
from statectl.run.door import Submitted
from statectl.run.journal import REFUSED, Journal, JournalReader
from statectl.run.runner.cells import cell_setups
from statectl.run.runtime import SimClock
from statectl.run.system import DeviceSetup, System
from test_distributed_receive import PING, PONG

SRC = Path(statectl.__file__).parent


def _motor(journal: Journal | None = None, **kw: Any) -> System:
    system = System((DeviceSetup("Motor", motor_chart()),), SimClock(), journal, **kw)
    system.start()
    return system


def _journal(tmp_path: Path, guarantee: str) -> Journal:
    return Journal(tmp_path / "j.db", guarantee=guarantee)


def _rows(path: Path, device: str = "Motor") -> list[tuple[str | None, str]]:
    with JournalReader(path) as reader:
        return [(r.event, r.outcome) for r in reader.steps() if r.device == device]


# -- the handle --------------------------------------------------------------------------


@pytest.mark.parametrize("guarantee", [None, "prompt", "durable-first"])
def test_the_handle_resolves_with_the_steps_outcome(tmp_path: Path, guarantee: str | None) -> None:
    """Without an owner thread the door runs each step on the caller's thread: the handle
    is done when submit returns, with the kernel's Outcome; with a journal it carries the
    ticket, durable once committed (durable-first: before the step ran)."""
    journal = None if guarantee is None else _journal(tmp_path, guarantee)
    system = _motor(journal)
    try:
        outcomes = []
        for event in ("Initialization", "Movement", "Movement"):
            handle = system.submit("Motor", event, origin=None)
            assert isinstance(handle, Submitted)
            assert (handle.ticket is None) == (journal is None)
            if handle.ticket is not None:
                assert handle.ticket.wait(10)
            outcomes.append(handle.result(10))
        assert outcomes == [Outcome.DECLARED_IGNORED, Outcome.HANDLED, Outcome.DECLARED_IGNORED]
        assert system.subjects["Motor"].configuration == {"Moving"}
    finally:
        system.close()
    if journal is not None:
        assert _rows(tmp_path / "j.db")[-3:] == [
            ("Initialization", "declared ignored"),
            ("Movement", "handled"),
            ("Movement", "declared ignored"),
        ]


@pytest.mark.parametrize("guarantee", [None, "prompt", "durable-first"])
def test_a_handle_from_another_thread_resolves_once_the_owner_ran_it(
    tmp_path: Path, guarantee: str | None
) -> None:
    """While another thread owns the devices the door does not run the step here: it is
    queued, the owner is woken, and the handle resolves once the owner ran it."""
    journal = None if guarantee is None else _journal(tmp_path, guarantee)
    system = _motor(journal)
    ran_on: list[threading.Thread] = []
    system.subjects["Motor"].on_step(lambda e, d, o: ran_on.append(threading.current_thread()))
    handles: list[Submitted] = []
    with system.owner:  # this thread owns the devices: a submitter must leave the step to it
        poster = threading.Thread(
            target=lambda: handles.append(system.submit("Motor", "Movement", origin=None))
        )
        poster.start()
        poster.join(10)
        assert len(handles) == 1 and not handles[0].done()
    halt = system.start_owner(paced=False)
    try:
        assert handles[0].result(10) is Outcome.HANDLED
    finally:
        halt()
        system.close()
    assert ran_on and ran_on[-1] is not poster


@pytest.mark.parametrize("guarantee", [None, "prompt", "durable-first"])
def test_await_submit_and_send_give_the_outcome(tmp_path: Path, guarantee: str | None) -> None:
    """From asyncio, ``await system.submit(...)`` and ``await system.send(...)`` return the
    outcome, with or without a journal (send used to refuse a journalled System)."""
    journal = None if guarantee is None else _journal(tmp_path, guarantee)
    system = _motor(journal)
    halt = system.start_owner(paced=False)

    async def main() -> list[str]:
        return [
            await system.submit("Motor", "Movement", origin=None),
            await system.send("Motor", "Movement"),
            await system.submit("Motor", "Bogus", origin=None),
        ]

    try:
        outcomes = asyncio.run(asyncio.wait_for(main(), 10))
    finally:
        halt()
        system.close()
    assert outcomes == [Outcome.HANDLED, Outcome.DECLARED_IGNORED, Outcome.UNKNOWN_EVENT]


def test_a_handle_waited_for_with_nobody_owning_the_devices_times_out() -> None:
    """result(timeout) says what is missing instead of hanging: the System is not started,
    so the door may not run the step, and nothing owns the devices."""
    system = System((DeviceSetup("Motor", motor_chart()),), SimClock())
    handle = system.submit("Motor", "Movement", origin=None)
    with pytest.raises(TimeoutError, match="owning the devices"):
        handle.result(0)
    system.start()  # runs what was queued before the start
    assert handle.result(0) is Outcome.HANDLED
    system.close()


def test_a_submit_from_a_step_is_left_to_the_drain_that_runs_it() -> None:
    """An observer that submits during a step (the owner mid-drain) must not start a second
    drain on the same thread: its event runs after the step, in the same drain."""
    system = _motor()
    handles: list[Submitted] = []

    class Completes:
        def update(self, notification: object) -> None:
            handles.append(system.submit("Motor", "Movement completion", origin=None))

    system.subjects["Motor"].attach(Completes())
    try:
        assert system.submit("Motor", "Movement", origin=None).result(0) is Outcome.HANDLED
        assert handles[0].result(0) is Outcome.HANDLED
        assert system.subjects["Motor"].configuration == {"Blocked"}
    finally:
        system.close()


def test_a_callback_that_raises_does_not_stop_the_owner(caplog: pytest.LogCaptureFixture) -> None:
    """A done-callback runs on the owner; one that raises is logged, and the device's next
    event still runs and resolves its own handle."""
    system = _motor()
    try:
        with system.owner:  # hold the devices so the callback is added before the step
            first = system.submit("Motor", "Movement", origin=None)
            first.add_done_callback(lambda h: 1 / 0)
        with caplog.at_level(logging.ERROR, logger="statectl.run.system"):
            system.drain()
            second = system.submit("Motor", "Movement completion", origin=None)
        assert (first.result(0), second.result(0)) == (Outcome.HANDLED, Outcome.HANDLED)
        assert any("callback" in r.getMessage() for r in caplog.records)
    finally:
        system.close()


def test_an_event_for_another_nodes_device_fails_its_handle() -> None:
    """A handle that will never hear an outcome says so when asked, never hangs."""
    handle = Submitted("arm", "Movement")
    handle.fail(StatectlError("arm runs on another node; Movement was forwarded"))
    assert handle.done()
    with pytest.raises(StatectlError, match="another node"):
        handle.result(0)

    async def wait() -> object:
        return await handle

    with pytest.raises(StatectlError, match="another node"):
        asyncio.run(wait())


# -- refusals through each channel ---------------------------------------------------------


def test_a_refused_submit_changes_nothing_and_is_journalled(tmp_path: Path) -> None:
    """The door raises CommandRefused before any handle exists; the device stays and the
    journal has a refused step with the origin."""
    journal = _journal(tmp_path, "prompt")
    system = _motor(journal, commands=Commands((Grant("stdin", "nobody"),)))
    try:
        with pytest.raises(CommandRefused):
            system.submit("Motor", "Movement", origin=Origin("stdin", "operator"))
        system.quiesce()
        assert system.subjects["Motor"].configuration == {"Blocked"}
    finally:
        system.close()
    assert _rows(tmp_path / "j.db")[-1] == ("Movement", f"{REFUSED}: stdin operator")


def test_opcua_methods_refuse_at_the_door_with_bad_user_access_denied(tmp_path: Path) -> None:
    """An OPC UA call goes through submit: allowed, it answers once the step ran (journal or
    not); refused by the policy, BadUserAccessDenied, journalled, and the Motor stays."""
    pytest.importorskip("asyncua")
    from asyncua import ua

    from statectl.channels.opcua.access import _CALLER
    from statectl.channels.opcua.methods import Calls

    journal = _journal(tmp_path, "prompt")
    grants = (Grant("opcua", "operator", None, frozenset({"Initialization"})),)
    system = _motor(journal, commands=Commands(grants))
    calls = Calls(system)
    holder = object()

    async def call(user: str, event: str) -> Any:
        _CALLER.set(user)
        return await calls.event("Motor", event, holder)(holder)

    try:
        refused = asyncio.run(call("operator", "Movement"))
        allowed = asyncio.run(call("operator", "Initialization"))
    finally:
        system.close()
    assert refused.StatusCode.value == ua.StatusCodes.BadUserAccessDenied
    assert [v.Value for v in allowed] == [False, "declared ignored"]  # ran: guard false
    assert _rows(tmp_path / "j.db")[-2:] == [
        ("Movement", f"{REFUSED}: opcua operator"),
        ("Initialization", "declared ignored"),
    ]


CELL = """cell: Door
devices: {ping: ping.yaml, pong: pong.yaml}
links:
  - {from: ping, raises: Go, to: pong, send: Hit}
"""


def _cell(tmp_path: Path, grants: tuple[Grant, ...], journalled: bool) -> System:
    (tmp_path / "ping.yaml").write_text(PING)
    (tmp_path / "pong.yaml").write_text(PONG)
    (tmp_path / "cell.yaml").write_text(CELL)
    cell, diags = load_cell(tmp_path / "cell.yaml")
    assert cell is not None, diags
    journal = _journal(tmp_path, "prompt") if journalled else None
    setups = cell_setups(cell, journalled=journalled)
    system = System(setups, SimClock(), journal, cell, commands=Commands(grants))
    system.start()
    return system


@pytest.mark.parametrize("journalled", [False, True])
@pytest.mark.parametrize(
    ("grants", "moves"),
    [
        ((), True),  # the default: every link event enters
        ((Grant("link", "ping"),), True),  # the link's principal is its source device
        ((Grant("link", "ping2"),), False),
        ((Grant("link", ANYONE, None, frozenset({"Go"})),), False),
    ],
)  # fmt: skip
def test_a_cell_link_event_passes_the_door(
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    journalled: bool,
    grants: tuple[Grant, ...],
    moves: bool,
) -> None:
    """A link's event is checked as origin ``link``/its source; refused, it is dropped with
    one log line and (journalled) a refused step of its target, and the target stays."""
    system = _cell(tmp_path, grants, journalled)
    try:
        with caplog.at_level(logging.WARNING, logger="statectl.run.system"):
            system.post("ping", "Go")
            system.quiesce()
        assert system.subjects["ping"].configuration == {"Busy"}
        assert system.subjects["pong"].configuration == ({"Down"} if moves else {"Up"})
    finally:
        system.close()
    dropped = [r for r in caplog.records if "link event dropped" in r.getMessage()]
    assert len(dropped) == (0 if moves else 1)
    if journalled and not moves:
        assert _rows(tmp_path / "j.db", "pong")[-1] == ("Hit", f"{REFUSED}: link ping")


def test_a_drivers_completion_passes_the_door(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A driver reports through the door as origin ``driver``/its device: a completion the
    policy refuses is dropped, one log line, journalled; the Motor stays Moving."""
    chart = motor_chart()
    driver = make_driver("sim-motor", {}, chart=chart)
    grants = (Grant("driver", ANYONE, None, frozenset({"Initialization completion"})),)
    journal = _journal(tmp_path, "prompt")
    system = System(
        (DeviceSetup("Motor", chart, driver=driver),), SimClock(), journal,
        commands=Commands(grants),
    )  # fmt: skip
    system.start()
    try:
        with caplog.at_level(logging.WARNING, logger="statectl.run.system"):
            system.post("Motor", "Movement", {"amount": 10})
            system.quiesce()
        assert system.subjects["Motor"].configuration == {"Moving"}
    finally:
        system.close()
    assert sum("driver completion dropped" in r.getMessage() for r in caplog.records) == 1
    assert _rows(tmp_path / "j.db")[-1] == ("Movement completion", f"{REFUSED}: driver Motor")


def test_a_link_stream_event_the_policy_refuses_is_dropped(tmp_path: Path) -> None:
    """Over Zenoh a link event enters the receiving node's door as ``link``/the sending
    node: refused, it is one log line and nothing moves."""
    pytest.importorskip("zenoh")
    from statectl.channels.distributed import NodeSystem, Wire

    cell_text = """cell: Stream
devices: {ping: ping.yaml, pong: pong.yaml}
nodes:
  a: {devices: [ping], listen: [tcp/127.0.0.1:1]}
  b: {devices: [pong], listen: [tcp/127.0.0.1:2]}
links:
  - {from: ping, raises: Go, to: pong, send: Hit}
"""
    (tmp_path / "ping.yaml").write_text(PING)
    (tmp_path / "pong.yaml").write_text(PONG)
    (tmp_path / "cell.yaml").write_text(cell_text)
    cell, diags = load_cell(tmp_path / "cell.yaml")
    assert cell is not None, diags
    results = {}
    for name, grants in (("allowed", (Grant("link", "a"),)), ("refused", (Grant("link", "c"),))):
        setups = tuple(s for s in cell_setups(cell, journalled=False) if s.name == "pong")
        system = NodeSystem(setups, SimClock(), None, cell, commands=Commands(grants))
        out = io.StringIO()
        wire = Wire(cell, "b", system, out=out)
        system.start()
        wire.inbound.announce("a", "pong", "ep1")
        wire._receiver("a", "pong")(_Sample(b'["ep1",1,"Hit",null]'))
        results[name] = (sorted(system.subjects["pong"].configuration), out.getvalue())
        system.close()
    assert results["allowed"] == (["Down"], "")
    state, log = results["refused"]
    assert state == ["Up"]
    assert log.count("\n") == 1 and "link event 'Hit' from a to pong" in log and "refused" in log


CLAMP = Path(__file__).resolve().parents[1] / "examples" / "clamp" / "clamp.yaml"
#: A ``commands:`` policy whose timer and monitor grants go to another device: this one's
#: are refused. A policy that grants them to this device by name: each one is checked.
_NOT_MINE = (Grant("timer", "Other"), Grant("monitor", "Other"))
_MINE = (Grant("timer", "Clamp"), Grant("timer", "Motor"), Grant("monitor", "Motor"))


def _clamp(tmp_path: Path, grants: tuple[Grant, ...], journalled: bool) -> System:
    journal = _journal(tmp_path, "prompt") if journalled else None
    setup = DeviceSetup("Clamp", statectl.load(CLAMP))
    system = System((setup,), SimClock(), journal, commands=Commands(grants))
    system.start()
    return system


def _fault_run(tmp_path: Path, grants: tuple[Grant, ...]) -> tuple[System, list[str]]:
    """The Motor moving a long way with its sim driver, journalled; a fault injected, and
    time let pass for its monitor to poll. The events of the steps it ran, in order."""
    chart = motor_chart()
    driver = make_driver("sim-motor", {}, chart=chart)
    system = System(
        (DeviceSetup("Motor", chart, driver=driver),), SimClock(), _journal(tmp_path, "prompt"),
        commands=Commands(grants),
    )  # fmt: skip
    steps: list[str] = []
    system.subjects["Motor"].on_step(lambda event, _data, _outcome: steps.append(event))
    system.start()
    system.post("Motor", "Movement", {"amount": 1000})
    system.advance(0.25)
    driver.inject_fault("stall")
    system.advance(0.25)
    return system, steps


@pytest.mark.parametrize("journalled", [False, True])
@pytest.mark.parametrize(
    ("grants", "timed_out"),
    [((), True), (_MINE, True), (_NOT_MINE, False)],
    ids=["default", "granted", "refused"],
)
def test_a_timeout_passes_the_door(
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    journalled: bool,
    grants: tuple[Grant, ...],
    timed_out: bool,
) -> None:
    """A state's timeout enters as origin ``timer``/its device: let in (by the default or
    by a grant), the Clamp jams; refused, the timeout is dropped with one log line and
    (journalled) a refused row, and the Clamp stays Closing."""
    system = _clamp(tmp_path, grants, journalled)
    try:
        with caplog.at_level(logging.WARNING, logger="statectl.run.system"):
            system.post("Clamp", "Close")
            system.settle()
        assert system.subjects["Clamp"].configuration == ({"Jammed"} if timed_out else {"Closing"})
        assert system.work_pending() is False
    finally:
        system.close()
    dropped = [r.getMessage() for r in caplog.records if "timeout dropped" in r.getMessage()]
    assert len(dropped) == (0 if timed_out else 1)
    assert all("Close timeout refused: timer Clamp" in m for m in dropped)
    if journalled:
        last = (
            ("Close timeout", "handled")
            if timed_out
            else ("Close timeout", f"{REFUSED}: timer Clamp")
        )
        assert _rows(tmp_path / "j.db", "Clamp")[-1] == last


@pytest.mark.parametrize("journalled", [False, True])
@pytest.mark.parametrize("grants", [(), _MINE], ids=["default", "granted"])
def test_a_timeout_through_the_door_still_runs_at_its_point_of_the_queue(
    tmp_path: Path, journalled: bool, grants: tuple[Grant, ...]
) -> None:
    """The door only checks a timeout, then the device processes it at once (timers.py
    rule 2): an event queued behind the timer's firing meets the Jammed clamp, it does not
    leave Closing first and turn the timeout into an ignored event."""
    system = _clamp(tmp_path, grants, journalled)
    try:
        system.post("Clamp", "Close")
        system.drain()
        clock = system.clock
        assert isinstance(clock, SimClock)
        clock.advance(2.0)  # the timer fires: its firing is queued on the Clamp, not run
        system.post("Clamp", "Closed")  # behind the firing in the device's queue
        system.quiesce()
        assert system.subjects["Clamp"].configuration == {"Jammed"}
    finally:
        system.close()


@pytest.mark.parametrize(
    ("grants", "faulted"),
    [((), True), (_MINE, True), (_NOT_MINE, False)],
    ids=["default", "granted", "refused"],
)
def test_a_monitors_fault_passes_the_door(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, grants: tuple[Grant, ...], faulted: bool
) -> None:
    """A monitor's fault enters as origin ``monitor``/its device and is posted as before:
    let in, the Motor's next step is the fault (Error, to Returning); refused, it is
    dropped with one log line and a refused row, and the Motor stays Moving."""
    with caplog.at_level(logging.WARNING, logger="statectl.run.system"):
        system, steps = _fault_run(tmp_path, grants)
    try:
        state = system.subjects["Motor"].configuration
    finally:
        system.close()
    dropped = [r.getMessage() for r in caplog.records if "monitor fault dropped" in r.getMessage()]
    rows = _rows(tmp_path / "j.db")
    if faulted:
        assert steps[:2] == ["Movement", "Error"] and "Returning" in state
        assert dropped == [] and ("Error", "handled") in rows
    else:
        assert steps == ["Movement"] and state == {"Moving"}
        assert len(dropped) == 1 and "Error refused: monitor Motor" in dropped[0]
        assert rows[-1] == ("Error", f"{REFUSED}: monitor Motor")


def test_the_runs_own_channels_are_open_by_default_and_never_queue_full() -> None:
    """``timer`` and ``monitor`` are channels of the policy, open to all by default (no
    per-event check: the door hands back the Subject's own method), and the run's own:
    a full queue does not refuse them."""
    from statectl.run.commands import CHANNELS, INTERNAL

    policy = Commands()
    assert {"timer", "monitor"} <= set(CHANNELS) and {"timer", "monitor"} <= INTERNAL
    assert policy.open_to_all("timer") and policy.open_to_all("monitor")
    system = _motor(max_queue=1)
    try:
        subject = system.subjects["Motor"]
        assert system._reporter("Motor", "timer", subject.deliver) == subject.deliver
        assert system._reporter("Motor", "monitor") == subject.post
        with system.owner:  # nobody drains: the queue stays full
            system.post("Motor", "Movement")
            system.admit("Motor", "Error", None, Origin("monitor", "Motor"))
            system.admit("Motor", "Error", None, Origin("timer", "Motor"))
            with pytest.raises(StatectlError, match="max_queue"):
                system.admit("Motor", "Error", None, Origin("stdin", "operator"))
    finally:
        system.close()


class _Sample:
    """What a Zenoh subscriber callback reads of a sample: its payload."""

    def __init__(self, data: bytes) -> None:
        self.payload = self
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


# -- nothing goes around the door ----------------------------------------------------------

#: Calls that hand an event to a device, step one, drain or take the owner lock: the
#: door's business (run/door.py), never a channel's nor the run's own (timers, monitors,
#: drivers, links: they hand the door's reporter their events, Door._reporter).
_DOOR_CALLS = {"post", "dispatch", "deliver", "run_until_idle", "_drain", "drain", "acquire"}
#: Where a channel may call ``post``: the System (its post is the door), a cell view that
#: forwards over Zenoh to another node's door, a Zenoh key helper (a key, not an event).
_POST_RECEIVERS = {"system", "self.system", "view", "self.keys"}
#: Modules that may, and why: the door and what stands behind it, and hosts of bare
#: Subjects (no System, so no door to go around).
_MAY_GO_AROUND = {
    "run/door.py": "the door itself",
    "run/runtime/subject.py": "the Subject: post, dispatch and deliver are its own methods",
    "run/runtime/defer.py": "a deferred event goes back to its device: it entered by the "
    "door when it first came",
    "run/journal/device.py": "the journal hands its device what the door let in "
    "(Door._let_in: bound.post) and the link events the door admitted with the step",
    "run/journal/read.py": "journal replay steps a bare Subject through the rows",
    "cell/explore/replay.py": "a counterexample's replay runs bare Subjects",
    "out/testgen/adapters/runtime.py": "a generated test drives one bare Subject, and owns "
    "its System alone to restart it",
    "out/testgen/cellharness.py": "the cell harness's reference runs bare Subjects, and "
    "owns its System alone",
    "out/scxml/scheduler.py": "SCXML sessions: no Subject",
    "out/scxml/sending.py": "SCXML sessions: no Subject",
    "out/scxml/session.py": "SCXML sessions: no Subject",
    "channels/cli/demo.py": "the demo runs one bare Subject, no System (README's first run)",
    "channels/distributed/system.py": "NodeSystem is a System: its link sends, checked "
    "by Door._link_admitted first",
}
#: The System owns the devices (system.py rule 1): it drains them, and posts nothing.
_MAY_DRAIN = {"run/system.py": {"run_until_idle", "_drain", "drain"}}


def _calls_around_the_door(path: Path, owner: set[str] | None = None) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        func = node.func if isinstance(node, ast.Call) else None
        if isinstance(func, ast.Attribute) and func.attr in _DOOR_CALLS - (owner or set()):
            receiver = ast.unparse(func.value)
            if func.attr != "post" or receiver not in _POST_RECEIVERS:
                found.append(f"line {node.lineno}: {receiver}.{func.attr}(...)")
    return found


@pytest.mark.parametrize("path", sorted(SRC.rglob("*.py")), ids=lambda p: str(p.relative_to(SRC)))
def test_nothing_goes_around_the_door(path: Path) -> None:
    """A channel, a timer, a monitor, a driver or a cell link hands events to the System
    only (submit or post, or the reporter the door gave it): no module posts to a
    Subject, steps one, drains the System or takes its owner lock behind the door."""
    rel = str(path.relative_to(SRC))
    if rel in _MAY_GO_AROUND:
        return
    assert _calls_around_the_door(path, _MAY_DRAIN.get(rel)) == [], f"{rel} goes around it"


def test_only_the_door_decides_who_runs_a_step() -> None:
    """``owner.acquire(blocking=False)`` (run the step here if nobody owns the devices) is
    written once in the whole package: in Door._run_here."""
    found = {
        str(p.relative_to(SRC)): p.read_text(encoding="utf-8").count("acquire(blocking=False)")
        for p in SRC.rglob("*.py")
    }
    assert {k: n for k, n in found.items() if n} == {"run/door.py": 1}


def test_the_exceptions_still_need_their_exception() -> None:
    """Each module allowed around the door still does it (else remove it from the list),
    and the System still drains (its allowance is what it needs)."""
    for rel in _MAY_GO_AROUND:
        assert _calls_around_the_door(SRC / rel), rel
    for rel, calls in _MAY_DRAIN.items():
        found = _calls_around_the_door(SRC / rel)
        assert {f.removesuffix("(...)").rpartition(".")[2] for f in found} == calls, rel
