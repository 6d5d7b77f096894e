"""The paper's step 2: build a device's statechart from its tables, and back.

:func:`build` (in :mod:`statectl.builder.chart`, whose docstring lists the rules) turns
:class:`~statectl.tables.DeviceTables` into a :class:`~statectl.model.Chart`, with the
state rows in :mod:`~statectl.builder.states` and the event rows in
:mod:`~statectl.builder.events`; :func:`chart_to_tables` (:mod:`~statectl.builder.inverse`)
goes back. This module loads a file and builds it; every public name is importable from
``statectl.build`` as before the split.
"""

from __future__ import annotations

import os

from statectl.builder.chart import build, strip_origins
from statectl.builder.common import CODES, GUARD_NAMES, MAX_STATE_DEPTH
from statectl.builder.inverse import chart_to_tables
from statectl.errors import Diagnostic, DiagnosticError, has_errors
from statectl.model import Chart
from statectl.tables import load
from statectl.tables.bulk import gc_paused

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
