"""Test a device against its tables: generated pytest modules, a pytest plugin, coverage.

See docs/testing.md. :func:`generate` writes a module per criterion (rows,
transitions, states, pairs) whose tests use the plugin's fixtures
(:mod:`statectl.out.testgen.plugin`); :class:`DeviceUnderTest` is what they drive;
:func:`journal_coverage` says what a journalled run exercised. The names are
imported on first use, so the CLI registering its commands stays fast.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from statectl.out.testgen.adapters.runtime import Recorder
    from statectl.out.testgen.cases import CRITERIA, Case, Expect, Suite, Table, cases_for
    from statectl.out.testgen.cellgen import generate_cell
    from statectl.out.testgen.cellharness import CellUnderTest
    from statectl.out.testgen.coverage import Coverage, journal_coverage
    from statectl.out.testgen.generator import Generated, generate
    from statectl.out.testgen.harness import DeviceUnderTest
    from statectl.out.testgen.oracle import Specification
    from statectl.out.testgen.paths import Graph, explore

__all__ = [
    "CRITERIA",
    "Case",
    "CellUnderTest",
    "Coverage",
    "DeviceUnderTest",
    "Expect",
    "Generated",
    "Graph",
    "Recorder",
    "Specification",
    "Suite",
    "Table",
    "cases_for",
    "explore",
    "generate",
    "generate_cell",
    "journal_coverage",
]

_WHERE = {
    "CRITERIA": "cases",
    "Case": "cases",
    "Expect": "cases",
    "Suite": "cases",
    "Table": "cases",
    "cases_for": "cases",
    "CellUnderTest": "cellharness",
    "generate_cell": "cellgen",
    "Coverage": "coverage",
    "journal_coverage": "coverage",
    "Generated": "generator",
    "generate": "generator",
    "DeviceUnderTest": "harness",
    "Recorder": "adapters.runtime",
    "Specification": "oracle",
    "Graph": "paths",
    "explore": "paths",
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'statectl.out.testgen' has no attribute {name!r}")
    return getattr(importlib.import_module(f"statectl.out.testgen.{module}"), name)
