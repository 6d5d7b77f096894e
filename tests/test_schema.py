"""The JSON Schemas of device, cell and run-config YAML: shipped as generated, every example
valid, files the loaders refuse for their shape refused too."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

import statectl
from statectl.channels.cli import main
from statectl.out.schema import KINDS, schema, schema_text

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = Path(statectl.__file__).parent / "data" / "schema"


def kind_of(data: dict[str, Any]) -> str:
    """Which file a parsed example is (as statectl check/verify/run --config tell them)."""
    if "states" in data:
        return "device"
    devices = data.get("devices")
    if isinstance(devices, dict) and all(
        isinstance(v, dict) and "driver" in v for v in devices.values()
    ):
        return "run-config"
    return "cell"


def errors(kind: str, data: object) -> list[str]:
    validator = jsonschema.Draft202012Validator(schema(kind))
    return [e.message for e in validator.iter_errors(data)]


EXAMPLES = sorted(
    [
        *ROOT.glob("examples/**/*.yaml"),
        *(Path(statectl.__file__).parent / "data").glob("profiles/*.yaml"),
    ]
)


@pytest.mark.parametrize("kind", KINDS)
def test_shipped_schema_is_the_generated_one(kind: str) -> None:
    """The file in the package equals what the code generates, so the two cannot drift."""
    shipped = SHIPPED / f"{kind}.schema.json"
    assert shipped.read_text(encoding="utf-8") == schema_text(kind), (
        f"regenerate: statectl schema {kind} --out {shipped}"
    )
    jsonschema.Draft202012Validator.check_schema(schema(kind))


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_every_example_is_valid(path: Path) -> None:
    """Each example device, cell and run config, and each shipped profile, fits its schema."""
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert errors(kind_of(data), data) == []


def test_examples_cover_every_kind() -> None:
    """The examples hold files of all three kinds, so each schema is exercised."""
    kinds = {kind_of(yaml.safe_load(p.read_text(encoding="utf-8"))) for p in EXAMPLES}
    assert kinds == set(KINDS)


MOTOR = {
    "device": "M",
    "states": [{"state": "A", "control": "default"}],
    "events": [{"event": "Go", "old": "A", "new": "A"}],
}

REFUSED = [
    ("device", {**MOTOR, "state": []}, "'state' was unexpected"),
    ("device", {k: v for k, v in MOTOR.items() if k != "events"}, "'events' is a required"),
    ("device", {**MOTOR, "states": [{"state": "A", "colour": "red"}]}, "'colour' was unexpected"),
    ("device", {**MOTOR, "events": [{"event": "Go", "old": "A"}]}, "is not valid under any"),
    ("device", {**MOTOR, "events": [{**MOTOR["events"][0], "kind": "poke"}]}, "'poke'"),
    ("device", {**MOTOR, "states": [{"state": "A", "control": "sometimes"}]}, "'sometimes'"),
    ("cell", {"devices": {"a": "a.yaml"}, "links": [{"from": "a", "to": "a"}]}, "'send'"),
    (
        "cell",
        {"devices": {"a": "a.yaml"}, "links": [{"from": "a", "to": "a", "send": "E"}]},
        "is not valid under any of the given schemas",
    ),
    ("cell", {"devices": {"a": "a.yaml"}, "wires": []}, "'wires' was unexpected"),
    ("run-config", {"devices": {"M": {"options": {}}}}, "'driver' is a required"),
    ("run-config", {"dashboard": {"port": 70000}}, "70000"),
    ("run-config", {"dashboard": {"token": "short"}}, "'short' is too short"),
    ("run-config", {"ship": {"to": "mysql://x"}}, "does not match"),
    ("run-config", {"commands": [{"from": "telnet"}]}, "'telnet' does not match"),
    ("run-config", {"commands": [{"to": "Motor"}]}, "'from' is a required"),
    ("run-config", {"commands": [{"from": "stdin", "send": []}]}, "is not valid under any"),
]


@pytest.mark.parametrize(("kind", "data", "found"), REFUSED, ids=[r[2] for r in REFUSED])
def test_schema_refuses_bad_files(kind: str, data: object, found: str) -> None:
    """A misspelt key, a missing column, an unknown word: the schema says so."""
    problems = errors(kind, data)
    assert any(found in p for p in problems), problems


def test_schema_accepts_aliases_and_list_cells() -> None:
    """The paper's long column names and comma-separated list cells read as the loader reads."""
    data = {
        **MOTOR,
        "states": [{"state": "A", "required state control": ["default"], "ignore": "Go, Stop"}],
        "events": [{"event": "Go", "old_state": "A", "new state": "A", "kind": "fault"}],
    }
    assert errors("device", data) == []


def test_schema_command_prints_and_writes(tmp_path: Path) -> None:
    """statectl schema KIND prints the schema; --out writes it and says so."""
    out, err = io.StringIO(), io.StringIO()
    assert main(["schema", "cell"], out, err) == 0
    assert out.getvalue() == schema_text("cell")
    target = tmp_path / "device.schema.json"
    out = io.StringIO()
    assert main(["schema", "device", "--out", str(target)], out, err) == 0
    assert target.read_text(encoding="utf-8") == schema_text("device")
    assert out.getvalue() == f"wrote {target}\n"
    assert main(["schema", "scxml"], io.StringIO(), io.StringIO()) == 2


def test_schema_accepts_the_commands_section_the_loader_reads() -> None:
    """from CHANNEL, CHANNEL/* or CHANNEL/NAME; to and send a name or a list of names."""
    data = {
        "commands": [
            {"from": "opcua/operator", "to": "Motor", "send": ["Movement", "Initialization"]},
            {"from": "opcua/*", "send": "Error"},
            {"from": "dashboard"},
        ]
    }
    assert errors("run-config", data) == []
