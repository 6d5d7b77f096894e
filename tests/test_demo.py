"""The Motor demo: the paper's step 3 running on a simulated clock."""

from __future__ import annotations

import io
import re
from pathlib import Path
from typing import Any

import pytest

import statectl
from statectl.channels.cli.demo import FAULT, run_demo
from statectl.run.runtime import Record, Subject, Taken
from support import record_keys

ROOT = Path(__file__).parent.parent
EXAMPLES = ROOT / "examples" / "motor"


def moved(event: str, source: str, target: str, label: str | None = None) -> tuple[Any, ...]:
    """The key of a microstep taking one transition from ``source`` to ``target``."""
    took = (Taken(source, (target,), label or event),)
    return ("MicrostepTaken", event, (source,), took, (target,))


#: The demo's records as (type, key fields), device and time left out.
EXPECTED: list[tuple[Any, ...]] = [
    ("Started",),
    ("MicrostepTaken", None, (), (), ("Blocked",)),
    # an external Movement request of 10
    ("EventReceived", "Movement", {"amount": 10}),
    moved("Movement", "Blocked", "Moving"),
    ("MonitorStarted", "Moving"),
    ("InvokeIssued", 0, "Moving", "Movement", "Movement"),
    ("ObserverCalled", "Movement", "SimMotor.move_to(10.0)"),
    ("EventReceived", "Movement completion", {"position": 10.0}),
    moved("Movement completion", "Moving", "Blocked"),
    ("MonitorStopped", "Moving"),
    # Initialization back: previous == 'Moving' holds
    ("EventReceived", "Initialization", None),
    moved("Initialization", "Blocked", "Returning", "Initialization [previous == 'Moving']"),
    ("InvokeIssued", 1, "Returning", "Initialization", "Initialization"),
    ("ObserverCalled", "Initialization", "SimMotor.return_to(0.0)"),
    ("EventReceived", "Initialization completion", {"position": 0.0}),
    moved("Initialization completion", "Returning", "Blocked"),
    # a new Movement; the motor faults half-way and the monitor raises Error
    ("EventReceived", "Movement", {"amount": 10}),
    moved("Movement", "Blocked", "Moving"),
    ("MonitorStarted", "Moving"),
    ("InvokeIssued", 0, "Moving", "Movement", "Movement"),
    ("ObserverCalled", "Movement", "SimMotor.move_to(10.0)"),
    ("FaultDetected", "Moving", "Error", FAULT),
    ("EventReceived", "Error", {"detail": FAULT}),
    moved("Error", "Moving", "Returning"),
    ("MonitorStopped", "Moving"),
    ("InvokeIssued", 2, "Error", "Error", "Error"),
    ("ObserverCalled", "Error", "SimMotor.stop()"),
    ("ObserverCalled", "Error", "SimMotor.return_to(0.0)"),
    ("EventReceived", "Error completion", {"position": 0.0}),
    moved("Error completion", "Returning", "Blocked"),
    ("Finished",),
]


keys = record_keys


def demo(**kw: Any) -> tuple[list[Record], str, Subject]:
    """Run the demo: (its records, its printed output, the finished subject)."""
    out = io.StringIO()
    records: list[Record] = []
    subject = run_demo(out, listeners=[records.append], **kw)
    return records, out.getvalue(), subject


def test_demo_records_the_papers_scenario() -> None:
    """The demo's records follow the scenario exactly, fault and recovery included."""
    records, _, _ = demo()
    assert keys(records) == EXPECTED


def test_demo_ends_blocked() -> None:
    """After the recovery the Motor is Blocked and the run finished."""
    _, text, subject = demo()
    assert subject.configuration == {"Blocked"} and subject.finished
    assert text.rstrip().endswith(
        "final state Blocked; 7 events processed; 4 invokes issued; 5 API calls"
    )


@pytest.mark.parametrize(
    "needle",
    [
        "#0 Moving -> observer Movement()",
        "#1 Returning -> observer Initialization()",
        "#2 Error -> observer Error()",
        "Movement() -> SimMotor.move_to(10.0)",
        "Error() -> SimMotor.return_to(0.0)",
        "monitor  Moving started",
        f"{FAULT!r} while Moving -> raises Error",
    ],
)
def test_demo_output_mentions_each_invoke_and_method(needle: str) -> None:
    """The printed trace names every invoke number and observer method."""
    _, text, _ = demo()
    assert needle in text


def test_demo_output_has_aligned_columns() -> None:
    """Every trace line has its kind column at the same place and no colour codes."""
    _, text, _ = demo()
    lines = [line for line in text.splitlines() if line.startswith("t=")]
    per_record = [
        len(k[2]) + len(k[3]) + len(k[4]) if k[0] == "MicrostepTaken" else 1 for k in EXPECTED
    ]
    assert len(lines) == sum(per_record)  # a microstep: a line per exit, transition, entry
    assert len({line.index("Motor") for line in lines}) == 1
    assert "\x1b" not in text


def test_demo_on_the_stepper_config_has_the_same_states() -> None:
    """With stepper.yaml the records differ only in the API calls."""

    def states(records: list[Record]) -> list[tuple[Any, ...]]:
        return [k for k in keys(records) if k[0] != "ObserverCalled"]

    motor, _, _ = demo()
    stepper, text, _ = demo(config=str(EXAMPLES / "stepper.yaml"))
    assert states(stepper) == states(motor)
    assert "SimStepper.step(2000, 1)" in text


def test_packaged_motor_model_is_the_example() -> None:
    """src/statectl/data/motor.yaml is a byte-identical copy of examples/motor/motor.yaml."""
    packaged = Path(statectl.__file__).parent / "data" / "motor.yaml"
    assert packaged.read_bytes() == (EXAMPLES / "motor.yaml").read_bytes()


def test_runtime_docs_example_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    """The Python example in docs/runtime.md runs as written, from the repository root."""
    monkeypatch.chdir(ROOT)
    text = (ROOT / "docs" / "runtime.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks
    for block in blocks:
        exec(compile(block, "docs/runtime.md", "exec"), {})
