"""Fixtures shared by the test modules: the paper's Motor, loaded once."""

from __future__ import annotations

import pytest

from statectl.build import load_chart
from statectl.model import Chart
from support import MOTOR


@pytest.fixture(scope="session")
def motor() -> Chart:
    """The Motor of examples/motor/motor.yaml (the paper's Tables 3 and 4)."""
    return load_chart(MOTOR)
