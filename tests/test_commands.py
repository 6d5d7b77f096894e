"""The commands policy (run/commands.py) and the System's door that asks it (system.py rule 8)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from statectl.channels.cli.demo import motor_chart
from statectl.channels.runconfig import load_run_config
from statectl.kernel.errors import DiagnosticError, StatectlError
from statectl.run.commands import (
    ANYONE,
    AUTHENTICATED,
    CommandRefused,
    Commands,
    Grant,
    Origin,
)
from statectl.run.journal import REFUSED, Journal, JournalReader, replay
from statectl.run.runtime import SimClock
from statectl.run.system import DeviceSetup, System

MOVES = frozenset({"Movement"})
MOTOR = frozenset({"Motor"})

#: (grants given, origin, device, event, allowed)
CASES = [
    # the defaults: what each channel allowed before there was a policy
    ((), Origin("stdin", "operator"), "Motor", "Movement", True),
    ((), Origin("stdin"), "Motor", "Movement", True),
    ((), Origin("dashboard", "token"), "Motor", "Error", True),
    ((), Origin("opcua", "operator"), "Motor", "Movement", True),
    ((), Origin("opcua"), "Motor", "Movement", False),  # an anonymous session
    ((), Origin("zenoh", "arm"), "Motor", "Error", True),
    ((), Origin("link", "line"), "Motor", "Movement", True),
    # a named principal, one device, one event
    ((Grant("opcua", "operator", MOTOR, MOVES),), Origin("opcua", "operator"), "Motor",
     "Movement", True),
    ((Grant("opcua", "operator", MOTOR, MOVES),), Origin("opcua", "operator"), "Motor",
     "Initialization", False),
    ((Grant("opcua", "operator", MOTOR, MOVES),), Origin("opcua", "operator"), "Arm",
     "Movement", False),
    ((Grant("opcua", "operator", MOTOR, MOVES),), Origin("opcua", "guest"), "Motor",
     "Movement", False),
    ((Grant("opcua", "operator", MOTOR, MOVES),), Origin("opcua"), "Motor", "Movement", False),
    # any authenticated principal; anyone, anonymous included (an explicit choice)
    ((Grant("opcua", AUTHENTICATED),), Origin("opcua", "guest"), "Arm", "Stop", True),
    ((Grant("opcua", AUTHENTICATED),), Origin("opcua"), "Arm", "Stop", False),
    ((Grant("opcua", ANYONE),), Origin("opcua"), "Arm", "Stop", True),
    # a section that names a channel replaces its default; the others keep theirs
    ((Grant("dashboard", ANYONE, None, MOVES),), Origin("dashboard", "token"), "Motor",
     "Error", False),
    ((Grant("dashboard", ANYONE, None, MOVES),), Origin("stdin", "operator"), "Motor",
     "Error", True),
    ((Grant("dashboard", ANYONE, None, MOVES),), Origin("opcua"), "Motor", "Movement", False),
    # two grants of a channel: either covers
    ((Grant("zenoh", "arm", None, MOVES), Grant("zenoh", "cell", MOTOR, None)),
     Origin("zenoh", "cell"), "Motor", "Error", True),
    ((Grant("zenoh", "arm", None, MOVES), Grant("zenoh", "cell", MOTOR, None)),
     Origin("zenoh", "arm"), "Motor", "Error", False),
]  # fmt: skip


@pytest.mark.parametrize(("grants", "origin", "device", "event", "allowed"), CASES)
def test_the_policy_allows_what_a_grant_of_the_channel_covers(
    grants: tuple[Grant, ...], origin: Origin, device: str, event: str, allowed: bool
) -> None:
    """A command is allowed when a grant of its channel covers its principal, device and
    event; a channel the grants do not name keeps its default."""
    policy = Commands(grants)
    assert policy.allows(origin, device, event) is allowed
    if allowed:
        policy.check(origin, device, event)
    else:
        with pytest.raises(CommandRefused, match=f"{device}: {event} refused: {origin.channel}"):
            policy.check(origin, device, event)


def test_a_refusal_says_who_what_is_granted_and_what_to_do() -> None:
    """The message names the origin (escaped), the grants in force and the section."""
    policy = Commands([Grant("opcua", "operator", MOTOR, MOVES, "run.yaml:3")])
    text = str(policy.refusal(Origin("opcua", "evil\nname"), "Motor", "Error"))
    assert text == (
        "Motor: Error refused: opcua 'evil\\nname' may not send it (commands policy: "
        "opcua/operator may send Movement to Motor (run.yaml:3)); grant it in the run "
        "config's commands: section, or send it as someone who may"
    )
    assert "opcua (anonymous)" in str(Commands().refusal(Origin("opcua"), "Motor", "Error"))
    coded = Commands([Grant("opcua", "operator", MOTOR, MOVES)])  # granted in code, not a file
    assert str(coded.refusal(Origin("opcua"), "Motor", "Error")).endswith(
        "(commands policy: opcua/operator may send Movement to Motor); grant it in the run "
        "config's commands: section, or send it as someone who may"
    )


def test_an_origin_names_a_known_channel() -> None:
    """A misspelt channel is misuse, said at once."""
    with pytest.raises(StatectlError, match="unknown command channel 'opc'"):
        Origin("opc", "operator")


def _config(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "run.yaml"
    path.write_text(f"# run config\n{text}", encoding="utf-8")
    return path


def test_a_commands_section_reads_into_grants(tmp_path: Path) -> None:
    """from CHANNEL, CHANNEL/* or CHANNEL/NAME; to and send one name, a list or '*'."""
    path = _config(
        tmp_path,
        "commands:\n"
        "  - {from: opcua/operator, to: Motor, send: [Movement, Initialization]}\n"
        "  - {from: opcua/*, send: Error}\n"
        "  - {from: dashboard, to: '*'}\n",
    )
    policy = load_run_config(path).commands
    assert policy.configured
    assert [str(g) for g in policy.grants("opcua")] == [
        f"opcua/operator may send Initialization, Movement to Motor ({path}:3)",
        f"opcua/* may send Error to any device ({path}:4)",
    ]
    assert [str(g) for g in policy.grants("dashboard")] == [
        f"dashboard may send any event to any device ({path}:5)"
    ]
    assert [str(g) for g in policy.grants("stdin")] == [
        "stdin may send any event to any device (the defaults)"
    ]
    assert not load_run_config(_config(tmp_path, "dashboard: {port: 0}\n")).commands.configured


def test_timer_and_monitor_are_channels_a_grant_names(tmp_path: Path) -> None:
    """A state's timeout and a monitor's fault come as ``timer`` and ``monitor`` with the
    device as principal; a section naming one replaces its default, the other stays open."""
    path = _config(tmp_path, "commands:\n  - {from: timer/Clamp, send: Close timeout}\n")
    policy = load_run_config(path).commands
    assert [str(g) for g in policy.grants("timer")] == [
        f"timer/Clamp may send Close timeout to any device ({path}:3)"
    ]
    assert policy.allows(Origin("timer", "Clamp"), "Clamp", "Close timeout")
    assert not policy.allows(Origin("timer", "Door"), "Door", "Jam")
    assert not policy.open_to_all("timer") and policy.open_to_all("monitor")
    assert Commands().open_to_all("timer") and Commands().open_to_all("monitor")


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ("commands: {from: stdin}", "'commands' must be a list of grants"),
        ("commands: [stdin]", "a grant must be a mapping"),
        ("commands: [{to: Motor}]", "a grant needs 'from'"),
        ("commands: [{from: telnet}]", "from must be CHANNEL, CHANNEL/* or CHANNEL/NAME"),
        ("commands: [{from: opcua/}]", "from must be CHANNEL"),
        ("commands: [{from: 5}]", "from must be CHANNEL"),
        ("commands: [{from: stdin, to: []}]", "to must name devices"),
        ("commands: [{from: stdin, send: [1]}]", "send must name events"),
        ("commands: [{from: stdin, colour: red}]", "unknown key 'colour'"),
    ],
)
def test_a_bad_commands_section_is_d540_with_its_line(
    tmp_path: Path, section: str, message: str
) -> None:
    """Each problem in the commands: section is a D540 error naming the file and line."""
    with pytest.raises(DiagnosticError) as caught:
        load_run_config(_config(tmp_path, f"{section}\n"))
    (diag,) = [d for d in caught.value.diagnostics if message in d.message]
    assert (diag.code, diag.where.line) == ("D540", 2)


def _system(
    grants: tuple[Grant, ...] = (), journal: Journal | None = None, name: str = "Motor"
) -> System:
    chart = motor_chart()
    system = System((DeviceSetup(name, chart),), SimClock(), journal, commands=Commands(grants))
    system.start()
    return system


@pytest.mark.parametrize(
    ("grant", "message"),
    [
        (Grant("opcua", "operator", frozenset({"Motr"}), None, "run.yaml:3"),
         "commands: run.yaml:3: no device 'Motr'; devices: Motor"),
        (Grant("opcua", "operator", None, frozenset({"Move"}), "run.yaml:4"),
         "commands: run.yaml:4: no device it names has an event 'Move'"),
        (Grant("opcua", "operator", frozenset({"Motr"})),  # granted in code: named by itself
         "commands: grant 'opcua/operator may send any event to Motr': no device 'Motr'"),
    ],
)  # fmt: skip
def test_a_grant_naming_what_the_run_lacks_is_refused_at_start(grant: Grant, message: str) -> None:
    """A misspelt device or event in a grant would refuse silently what it meant to allow."""
    with pytest.raises(StatectlError, match=message):
        _system((grant,))


def test_the_door_refuses_a_command_and_nothing_reaches_the_device() -> None:
    """post and send with an origin the policy refuses raise; the Motor stays Blocked."""
    system = _system((Grant("dashboard", ANYONE, None, frozenset({"Initialization"})),))
    try:
        dashboard = Origin("dashboard", "token")
        with pytest.raises(CommandRefused):
            system.post("Motor", "Movement", origin=dashboard)
        with pytest.raises(CommandRefused):
            asyncio.run(system.send("Motor", "Movement", origin=dashboard))
        with pytest.raises(CommandRefused):
            system.post("Motor", "Movement", origin=Origin("opcua"))  # the default: a user
        assert system.subjects["Motor"].queued == 0
        system.drain()
        assert system.subjects["Motor"].configuration == frozenset({"Blocked"})
        system.post("Motor", "Movement", origin=Origin("stdin", "operator"))  # its default
        system.post("Motor", "Initialization", origin=dashboard)
        system.drain()
        assert system.subjects["Motor"].configuration == frozenset({"Moving"})
    finally:
        system.close()


def test_an_event_without_an_origin_is_the_hosts_own() -> None:
    """The Python API's post carries no origin: the policy is not asked."""
    system = _system((Grant("stdin", "nobody", frozenset({"Motor"}), frozenset({"Error"})),))
    try:
        system.post("Motor", "Movement")
        system.drain()
        assert system.subjects["Motor"].configuration == frozenset({"Moving"})
    finally:
        system.close()


def test_a_refused_command_is_journalled_as_refused_and_replay_passes_over_it(
    tmp_path: Path,
) -> None:
    """With a journal the refusal is a step row that changes nothing, with the origin; the
    journal replays without a mismatch, and the accepted events around it are kept."""
    path = tmp_path / "j.db"
    system = _system((Grant("opcua", "operator", None, frozenset({"Initialization"})),),
                     Journal(path))  # fmt: skip
    try:
        system.post("Motor", "Movement", origin=Origin("stdin", "operator"))
        system.quiesce()
        with pytest.raises(CommandRefused):
            system.post("Motor", "Error", {"why": "test"}, origin=Origin("opcua", "operator"))
        with pytest.raises(CommandRefused):
            system.post("Motor", "Error", origin=Origin("opcua"))
        system.quiesce()
    finally:
        system.close()
    with JournalReader(path) as reader:
        rows = [(r.kind.value, r.event, r.data, r.outcome, sorted(r.snapshot.active))
                for r in reader.steps()]  # fmt: skip
        result = replay(reader, {"Motor": motor_chart()})
    assert rows == [
        ("start", None, None, "", ["Blocked"]),
        ("event", "Movement", None, "handled", ["Moving"]),
        ("event", "Error", {"why": "test"}, f"{REFUSED}: opcua operator", ["Moving"]),
        ("event", "Error", None, f"{REFUSED}: opcua (anonymous)", ["Moving"]),
    ]
    assert result.mismatches == ()
    assert result.final["Motor"].active == frozenset({"Moving"})


@pytest.mark.parametrize(
    ("section", "code", "says"),
    [
        ("commands: [{from: stdin, send: Initialization}]\n", 1,
         "line 1: Motor: Movement refused: stdin operator may not send it"),
        ("commands: [{from: stdin/someone-else}]\n", 1, "stdin operator may not send it"),
        ("commands: [{from: stdin, to: Motr}]\n", 1, "no device 'Motr'; devices: Motor"),
        ("commands: [{from: dashboard}]\n", 0, ""),  # stdin keeps its default
    ],
)  # fmt: skip
def test_statectl_run_asks_the_policy_for_each_event_line(
    tmp_path: Path, section: str, code: int, says: str
) -> None:
    """Event lines come from the operator at the console: the config's commands: section
    decides; a refused line is said with its number and the run exits 1."""
    import io

    from statectl.channels.cli.run import run as run_cli
    from support import MOTOR

    config = _config(tmp_path, section)
    out, err = io.StringIO(), io.StringIO()
    got = run_cli(str(MOTOR), config=str(config), events=io.StringIO("Movement\n"), out=out,
                  err=err)  # fmt: skip
    assert got == code, err.getvalue()
    assert says in err.getvalue()
    assert "Traceback" not in err.getvalue()
