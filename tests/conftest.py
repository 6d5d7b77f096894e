"""Fixtures shared by the test modules (the paper's Motor, loaded once), and the summary's
note on the W3C conformance pack: a claim not tested is said so at the end of the run."""

from __future__ import annotations

import pytest

from statectl.front.builder.build import load_chart
from statectl.kernel.model import Chart
from support import MOTOR, W3C_PACK, W3C_SKIPPED, W3C_VARIABLE


@pytest.fixture(scope="session")
def motor() -> Chart:
    """The Motor of examples/motor/motor.yaml (the paper's Tables 3 and 4)."""
    return load_chart(MOTOR)


def w3c_note(reports: dict[str, list[object]]) -> str | None:
    """One line on the W3C pack's tests in this run: skipped (and how to run them), or None."""
    skipped = [
        r for r in reports.get("skipped", []) if W3C_SKIPPED in str(getattr(r, "longrepr", ""))
    ]
    if not skipped:
        return None
    return (
        f"W3C conformance pack NOT tested ({len(skipped)} test(s) skipped): no pack at "
        f"{W3C_PACK}; set {W3C_VARIABLE} to the pack's directory to run them"
    )


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """Say at the end of the run when the W3C conformance claim was not tested."""
    note = w3c_note(terminalreporter.stats)
    if note is not None:
        terminalreporter.write_sep("-", "W3C conformance", yellow=True)
        terminalreporter.write_line(note, yellow=True)
