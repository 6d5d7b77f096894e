"""The paper's step 2: build a device's statechart from its tables, and back.

:func:`build` (in :mod:`statectl.front.builder.chart`, whose docstring lists the rules) turns
:class:`~statectl.front.tables.DeviceTables` into a :class:`~statectl.kernel.model.Chart`, with the
state rows in :mod:`~statectl.front.builder.states` and the event rows in
:mod:`~statectl.front.builder.events`; :func:`chart_to_tables`
(:mod:`~statectl.front.builder.inverse`) goes back. This module loads a file and builds
it; every public name is importable from ``statectl.front.builder.build``.
"""

from __future__ import annotations

import os

from statectl.front.builder.chart import build, strip_origins
from statectl.front.builder.common import CODES, GUARD_NAMES, MAX_STATE_DEPTH
from statectl.front.builder.inverse import chart_to_tables
from statectl.front.tables import load
from statectl.front.tables.bulk import gc_paused
from statectl.kernel.errors import Diagnostic, DiagnosticError, has_errors
from statectl.kernel.model import Chart

__all__ = [
    "CODES",
    "GUARD_NAMES",
    "MAX_STATE_DEPTH",
    "build",
    "chart_to_tables",
    "load_and_build",
    "load_chart",
    "strip_origins",
]


def load_and_build(path: str | os.PathLike[str]) -> tuple[Chart | None, list[Diagnostic]]:
    """Load a device file in any table format and build it; every diagnostic of both steps.

    Tables that loaded with errors are still built, so one run reports the
    problems of both steps; their chart is not returned, since it is not the
    file's.
    """
    with gc_paused():  # a load makes many objects and no garbage (tables/bulk.py)
        tables, diags = load(path)
        if tables is None:
            return None, diags
        chart, more = build(tables)
    return (None if has_errors(diags) else chart), [*diags, *more]


def load_chart(path: str | os.PathLike[str]) -> Chart:
    """The chart of a device file; raises :class:`DiagnosticError` carrying every problem."""
    chart, diags = load_and_build(path)
    if chart is None or has_errors(diags):
        raise DiagnosticError(diags)
    return chart
