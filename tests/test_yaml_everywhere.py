"""Every YAML statectl reads goes through the safe loader: run configs, event lines, traces.

Device and cell files were closed first (tests/test_limits.py); these are the other
places a user hands statectl YAML, each refusing an alias bomb or a deep nesting
with a message, in bounded time, never a traceback.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from statectl.cell.explore.replay import load_replay
from statectl.channels.runconfig import load_run_config
from statectl.kernel.errors import DiagnosticError, StatectlError
from statectl.run.runner import is_cell, parse_event_line

#: A small alias bomb: nine references per level, seven levels (4.7 million leaves).
BOMB = (
    "[&a [x,x,x,x,x,x,x,x,x]"
    + "".join(
        f", &{b} [{', '.join(['*' + a] * 9)}]" for a, b in zip("abcdef", "bcdefg", strict=True)
    )
    + "]"
)
DEEP = "[" * 5000 + "]" * 5000


@pytest.mark.parametrize(("name", "body"), [("bomb", BOMB), ("deep", DEEP)])
def test_a_run_config_is_refused_with_d502_at_its_line(
    tmp_path: Path, name: str, body: str
) -> None:
    """A hostile --config file is D502 with a line, not an expansion or a RecursionError."""
    path = tmp_path / "run.yaml"
    path.write_text(f"devices:\n  Motor: {{driver: sim-motor, options: {{x: {body}}}}}\n")
    with pytest.raises(DiagnosticError) as caught:
        load_run_config(path)
    codes = [(d.code, d.where.line) for d in caught.value.diagnostics]
    assert codes == [("D502", 2)], codes


@pytest.mark.parametrize("body", [BOMB, DEEP])
def test_event_data_on_a_line_is_refused(body: str) -> None:
    """An event line whose data is hostile YAML is a StatectlError the run reports per line."""
    with pytest.raises(StatectlError, match="event data is not YAML flow style"):
        parse_event_line(f"Motor: Movement {body}")


@pytest.mark.parametrize("body", [BOMB, DEEP])
def test_a_trace_file_is_refused_at_its_line(tmp_path: Path, body: str) -> None:
    """A replay trace with hostile YAML names the file, the line and the code."""
    path = tmp_path / "trace.yaml"
    path.write_text(f"steps:\n  - {body}\n")
    with pytest.raises(StatectlError, match=r"trace\.yaml:2: T11[56]"):
        load_replay(path)


def test_a_hostile_file_is_not_taken_for_a_cell(tmp_path: Path) -> None:
    """is_cell() says no (the device loader then reports the file) instead of expanding it."""
    path = tmp_path / "c.yaml"
    path.write_text(f"devices: {BOMB}\n")
    assert is_cell(str(path)) is False


#: Plain scalars and what they read as: exponent floats as YAML 1.2 reads them (PyYAML's
#: YAML 1.1 resolver made them text), everything else as before.
EXPONENTS = [
    ("1e3", 1000.0),
    ("2.5e-3", 0.0025),
    ("-1E+6", -1000000.0),
    (".5e2", 50.0),
    ("1_000e3", 1000000.0),
    ("1.0e+3", 1000.0),  # YAML 1.1's own form: unchanged
    ("10", 10),
    ("0x1e3", 0x1E3),  # hex, not an exponent
    ("1e", "1e"),
    ("e3", "e3"),
    ("1e3x", "1e3x"),
    ("'1e3'", "1e3"),  # quoted: text
]


@pytest.mark.parametrize(("text", "value"), EXPONENTS, ids=[t for t, _ in EXPONENTS])
@pytest.mark.parametrize("c_parser", [False, True], ids=["python", "libyaml"])
def test_a_number_with_an_exponent_is_a_float(text: str, value: object, c_parser: bool) -> None:
    """`1e3` in any YAML statectl reads is the float 1000.0 with either parser, and
    texts that only look like it stay what they were."""
    from statectl.front.tables import safeyaml

    loader = safeyaml._Loader if c_parser else safeyaml._PyLoader
    got = safeyaml.load_value(f"{{x: {text}}}", loader)
    assert got == {"x": value} and type(got["x"]) is type(value)  # type: ignore[index]


def test_a_driver_option_written_1e3_is_a_number(tmp_path: Path) -> None:
    """`speed: 1e3` in a run config is the number 1000: it was the text '1e3' and refused
    with 'speed must be a number'."""
    path = tmp_path / "run.yaml"
    path.write_text("devices:\n  Motor: {driver: sim-motor, options: {speed: 1e3}}\n")
    config = load_run_config(path)
    assert config.drivers == {"Motor": ("sim-motor", {"speed": 1000.0})}


def test_event_data_written_1e2_is_a_number() -> None:
    """`Movement {amount: 1e2}` sends the number 100.0, as `{amount: 100.0}` does."""
    assert parse_event_line("Movement {amount: 1e2}") == parse_event_line(
        "Movement {amount: 100.0}"
    )
