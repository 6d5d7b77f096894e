"""The run configuration file: drivers per device and the dashboard's host, port and token."""

from __future__ import annotations

import http.client
import io
import json
import socket
import threading
from pathlib import Path
from typing import Any

import pytest

from statectl.channels.cli.run import run
from statectl.channels.cli.run_setup import TOKEN_VARIABLE
from statectl.channels.opcua.config import OpcuaConfig
from statectl.channels.runconfig import load_driver_config, load_run_config, run_config
from statectl.channels.web.config import DashboardConfig
from statectl.kernel.errors import DiagnosticError
from statectl.run.runner import System

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
SECRET = "config-token-0123456789"
WAIT = 10.0  # a bound on start-up, not a measurement


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "run.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_both_sections_are_read(tmp_path: Path) -> None:
    """A file with devices and dashboard gives both; the drivers loader still reads it."""
    text = (
        "devices:\n  Motor: {driver: sim-motor}\n"
        f"dashboard: {{host: 127.0.0.1, port: 8765, token: {SECRET}}}\n"
    )
    path = write(tmp_path, text)
    config = load_run_config(path)
    assert config.drivers == {"Motor": ("sim-motor", {})}
    assert config.dashboard == DashboardConfig("127.0.0.1", 8765, SECRET)
    assert load_driver_config(path) == {"Motor": ("sim-motor", {})}


def test_without_a_config_a_run_has_no_sections(tmp_path: Path) -> None:
    """run_config(None), what run, node and dashboard take without --config: no section set;
    with a path it is the file's."""
    empty = run_config(None)
    assert (empty.drivers, empty.dashboard, empty.opcua, empty.ship) == (
        None,
        DashboardConfig(),
        OpcuaConfig(),
        None,
    )
    path = write(tmp_path, "dashboard: {port: 8765}\n")
    assert run_config(path).dashboard == load_run_config(path).dashboard
    assert run_config(path).dashboard != empty.dashboard


@pytest.mark.parametrize(
    ("driver", "options", "says"),
    [
        ("sim-motor", "{speed: {}}", "speed must be a number of units/s > 0 (got {})"),
        ("sim-motor", "{speed: .inf}", "speed must be a number of units/s > 0 (got inf)"),
        ("sim-motor", "{position: [1]}", "position must be a number of units (got [1])"),
        ("sim-motor", "{position: '3'}", "position must be a number of units (got '3')"),
        ("sim-stepper", "{steps_per_unit: 1.5}", "steps_per_unit must be an int > 0 (got 1.5)"),
        (
            "sim-stepper",
            "{pulse_rate: [1]}",
            "pulse_rate must be a number of steps/s > 0 (got [1])",
        ),
        ("sim-stepper", "{step: x}", "step must be an int, a step count (got 'x')"),
        ("sim-stepper", "{step: true}", "step must be an int, a step count (got True)"),
    ],
)
def test_a_simulated_drive_option_of_the_wrong_type_is_d509(
    tmp_path: Path, driver: str, options: str, says: str
) -> None:
    """sim-motor and sim-stepper options of the wrong type are D509 at their line, not a
    TypeError when the run creates the driver."""
    path = write(tmp_path, f"devices:\n  Motor:\n    driver: {driver}\n    options: {options}\n")
    with pytest.raises(DiagnosticError) as caught:
        load_run_config(path)
    found = [(d.code, d.where.line) for d in caught.value.diagnostics]
    assert found == [("D509", 4)], found
    assert says in caught.value.diagnostics[0].message


def test_a_dashboard_only_file_leaves_the_drivers_open(tmp_path: Path) -> None:
    """Without 'devices' the drivers are None (the run's --driver or twins); the drivers loader
    refuses such a file with D503."""
    path = write(tmp_path, f"dashboard:\n  token: {SECRET}\n")
    assert load_run_config(path).drivers is None
    with pytest.raises(DiagnosticError) as caught:
        load_driver_config(path)
    assert [d.code for d in caught.value.diagnostics] == ["D503"]


@pytest.mark.parametrize(
    ("section", "line", "words"),
    [
        ("dashboard: 3\n", 1, "must be a mapping"),
        ("dashboard:\n  colour: red\n", 2, "unknown key 'colour'"),
        ("dashboard:\n  port: 70000\n", 2, "0-65535"),
        ("dashboard:\n  port: yes\n", 2, "0-65535"),
        ("dashboard:\n  host: ''\n", 2, "host must be an address"),
        ("dashboard:\n  token: hunter2\n", 2, "16 characters or more"),
        ("dashboard:\n  token: 12345678901234567890\n", 2, "16 characters or more"),
        ("dashboard:\n  streams: 0\n", 2, "streams must be a number 1-100000"),
        ("dashboard:\n  streams: many\n", 2, "streams must be a number 1-100000"),
    ],
)
def test_a_bad_dashboard_section_is_d510_with_its_line(
    tmp_path: Path, section: str, line: int, words: str
) -> None:
    """Each problem of the section is one D510 error at its line; a token is never echoed."""
    path = write(tmp_path, section)
    with pytest.raises(DiagnosticError) as caught:
        load_run_config(path)
    [d] = caught.value.diagnostics
    assert (d.code, d.where.line) == ("D510", line)
    assert words in d.message
    assert "hunter2" not in str(d)


def test_an_unknown_top_level_key_names_both_sections(tmp_path: Path) -> None:
    """D507 for a stray key says what a run config may hold."""
    path = write(tmp_path, "devices: {Motor: {driver: sim-motor}}\nweb: {}\n")
    with pytest.raises(DiagnosticError) as caught:
        load_run_config(path)
    [d] = caught.value.diagnostics
    assert d.code == "D507" and "'dashboard'" in d.hint


class Served:
    """``statectl run`` with a dashboard on a thread; stopped on exit."""

    def __init__(self, **kwargs: Any) -> None:
        self.out, self.err = io.StringIO(), io.StringIO()
        self.halt = threading.Event()
        self.up = threading.Event()
        self.url: str | None = None
        self.codes: list[int] = []
        self.kwargs = kwargs

    def __enter__(self) -> Served:
        def ready(system: System, url: str | None) -> None:
            self.url = url
            self.up.set()

        def serve() -> None:
            code = run(
                str(MOTOR),
                dashboard=True,
                out=self.out,
                err=self.err,
                stop=self.halt,
                ready=ready,
                **self.kwargs,
            )
            self.codes.append(code)
            self.up.set()

        self.thread = threading.Thread(target=serve, daemon=True)
        self.thread.start()
        assert self.up.wait(WAIT), self.err.getvalue()
        return self

    def __exit__(self, *exc: object) -> None:
        self.halt.set()
        self.thread.join(WAIT)

    def post(self, token: str) -> int:
        assert self.url is not None
        port = int(self.url.rsplit(":", 1)[1].strip("/"))
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
        try:
            conn.request(
                "POST",
                "/api/post",
                body=json.dumps({"device": "Motor", "event": "Movement"}).encode(),
                headers={"Content-Type": "application/json", "X-Statectl-Token": token},
            )
            reply = conn.getresponse()
            reply.read()
            return reply.status
        finally:
            conn.close()


def test_the_config_gives_port_and_token_and_the_token_is_not_printed(tmp_path: Path) -> None:
    """The dashboard listens on the config's port, takes its token, and never echoes it."""
    port = free_port()
    config = write(tmp_path, f"dashboard: {{port: {port}, token: {SECRET}}}\n")
    with Served(config=str(config)) as served:
        assert served.url is not None and served.url.rstrip("/").endswith(f":{port}")
        assert (served.post("wrong-token-0123456789"), served.post(SECRET)) == (401, 200)
    assert served.codes == [0], served.err.getvalue()
    assert f"token: (from {config})" in served.out.getvalue()
    assert SECRET not in served.out.getvalue()


def test_the_config_caps_the_event_streams(tmp_path: Path) -> None:
    """``streams: 1``: the run's dashboard serves one event stream and refuses a second (503)."""
    config = write(tmp_path, f"dashboard: {{token: {SECRET}, streams: 1}}\n")
    with Served(config=str(config)) as served:
        assert served.url is not None
        port = int(served.url.rsplit(":", 1)[1].strip("/"))
        first = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
        second = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
        try:
            first.request("GET", "/api/events")
            assert first.getresponse().status == 200
            second.request("GET", "/api/events")
            assert second.getresponse().status == 503
        finally:
            first.close()
            second.close()
    assert served.codes == [0], served.err.getvalue()


@pytest.mark.parametrize(
    ("flag", "env", "wins"),
    [
        (None, "env-token-0123456789", "env-token-0123456789"),
        ("flag-token-0123456789", "env-token-0123456789", "flag-token-0123456789"),
        (None, None, SECRET),
    ],
)
def test_the_flag_beats_the_environment_which_beats_the_config(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, flag: str | None, env: str | None, wins: str
) -> None:
    """Whichever source wins is the one token that may post."""
    if env is None:
        monkeypatch.delenv(TOKEN_VARIABLE, raising=False)
    else:
        monkeypatch.setenv(TOKEN_VARIABLE, env)
    config = write(tmp_path, f"dashboard: {{token: {SECRET}}}\n")
    losers = {SECRET, "env-token-0123456789", "flag-token-0123456789"} - {wins}
    with Served(config=str(config), token=flag) as served:
        assert [served.post(t) for t in sorted(losers)] == [401, 401]
        assert served.post(wins) == 200
    assert served.codes == [0], served.err.getvalue()


def test_a_short_token_is_refused_before_anything_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    """A guessable token from the flag or the environment stops the run with exit 1."""
    monkeypatch.setenv(TOKEN_VARIABLE, "short")
    out, err = io.StringIO(), io.StringIO()
    code = run(str(MOTOR), dashboard=True, out=out, err=err, stop=threading.Event())
    assert code == 1
    assert f"from {TOKEN_VARIABLE} is shorter than 16 characters" in err.getvalue()
    assert "short" not in out.getvalue()


@pytest.mark.parametrize(
    ("driver", "options", "says"),
    [
        ("sim-motor", "{speed: fast}", ["speed must be a number"]),
        ("sim-motor", "{speed: .inf, position: x}", ["speed must be", "position must be"]),
        ("sim-motor", "{speed: 0}", ["speed must be"]),
        ("sim-stepper", "{pulse_rate: x}", ["pulse_rate must be"]),
        ("sim-stepper", "{step: oops, steps_per_unit: yes}", ["steps_per_unit", "step must"]),
        ("sim-stepper", "{pulse_rate: .nan}", ["pulse_rate must be"]),
    ],
)
def test_bad_simulated_motor_options_are_d509_at_their_line(
    tmp_path: Path, driver: str, options: str, says: list[str]
) -> None:
    """A sim-motor or sim-stepper option of the wrong type or out of range is a D509 at the
    options' line, every one at once (a speed of 'fast' used to end in a TypeError traceback)."""
    path = write(tmp_path, f"devices:\n  Motor:\n    driver: {driver}\n    options: {options}\n")
    with pytest.raises(DiagnosticError) as info:
        load_driver_config(path)
    found = info.value.diagnostics
    assert [(d.code, d.where.line) for d in found] == [("D509", 4)] * len(says)
    assert [s in d.message for s, d in zip(says, found, strict=True)] == [True] * len(says)
