"""SCXML in and out of device tables: ``statectl scxml import`` and ``statectl scxml export``.

Rules:
1. Export: a device file in any table format is built and written as SCXML; the
   device facts SCXML has no word for travel in the ``statectl`` namespace, so the
   document reads back to the same chart.
2. Import: an SCXML document becomes device tables when its chart fits the table
   form (:func:`statectl.front.builder.build.chart_to_tables`: no executable content beyond
   notifications, one event and one target per transition, safe guards, literal
   data) and the tables build the very same chart. Otherwise it stays SCXML and
   the info diagnostics say why; nothing is written then.
3. A document with errors raises :class:`~statectl.kernel.errors.DiagnosticError`
   carrying every diagnostic, as :func:`statectl.front.builder.build.load_chart` does.
4. The Recovery table is no part of the chart: export writes each row as a
   ``<statectl:recovery state event data/>`` (or ``redo="yes"``) element at the
   top of the document and import reads them back, checked as the table's rows
   are (S623 for a bad one), so a device file survives the round trip whole.

This module sits above both :mod:`statectl.out.scxml` and :mod:`statectl.front.builder.build`, which
must not import each other.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from statectl.front.builder.build import chart_to_tables, load_chart
from statectl.front.tables import DeviceTables, load, save
from statectl.front.tables.cells import recovery_row
from statectl.front.tables.inputs import read_input
from statectl.front.tables.literals import format_literal
from statectl.front.tables.rows import RECOVERY_COLUMNS, RawRow, RecoveryRow
from statectl.kernel.errors import Diagnostic, DiagnosticError, Location, Severity, has_errors
from statectl.kernel.model import Chart
from statectl.out.escape.xml import attribute as quoteattr
from statectl.out.scxml import read_scxml, write_scxml
from statectl.out.scxml.reader import statectl_elements

__all__ = ["export_file", "import_file", "import_text"]


def import_text(
    text: str | bytes, file: str = "<memory>", base: str | None = None
) -> tuple[DeviceTables | None, Chart, list[Diagnostic]]:
    """Read SCXML text (or a file's bytes); return the tables (``None`` if it stays SCXML),
    its chart and the diagnostics.

    Raises :class:`DiagnosticError` if the document has errors.
    """
    chart, diagnostics = read_scxml(text, file, base)
    if chart is None or has_errors(diagnostics):
        raise DiagnosticError(diagnostics)
    recovery, problems = _recovery_rows(text, file)
    if problems:
        raise DiagnosticError([*diagnostics, *problems])
    tables, why = chart_to_tables(chart)
    if tables is not None and recovery:
        tables = dataclasses.replace(tables, recovery=recovery)
    return tables, chart, [*diagnostics, *why]


def _recovery_rows(
    text: str | bytes, file: str
) -> tuple[tuple[RecoveryRow, ...], list[Diagnostic]]:
    """The Recovery table the document carries as ``<statectl:recovery>`` (rule 4)."""
    rows: list[RecoveryRow] = []
    problems: list[Diagnostic] = []
    for attrs, line in statectl_elements(text, "recovery"):
        where = Location(file, line)
        found: list[Diagnostic] = []
        unknown = sorted(set(attrs) - set(RECOVERY_COLUMNS))
        for name in unknown:
            found.append(
                Diagnostic(
                    "T103",
                    Severity.ERROR,
                    where,
                    f"unknown attribute {name!r}",
                    "known: " + ", ".join(RECOVERY_COLUMNS),
                )
            )
        cells = {k: (v, where) for k, v in attrs.items() if k in RECOVERY_COLUMNS}
        row = recovery_row(RawRow(where, cells), found)
        problems.extend(
            Diagnostic(
                "S623",
                Severity.ERROR,
                d.where,
                f"<statectl:recovery>: {d.message}",
                d.hint or 'write state= with event= (and data=) or redo="yes"',
            )
            for d in found
        )
        rows.append(row)
    return tuple(rows), problems


def _recovery_elements(tables: DeviceTables) -> list[str]:
    """The Recovery table as ``<statectl:recovery>`` elements (rule 4)."""
    out = []
    for r in tables.recovery:
        attrs = {"state": r.state}
        if r.redo:
            attrs["redo"] = "yes"
        else:
            attrs["event"] = r.event
        if r.data is not None:
            attrs["data"] = format_literal(r.data)
        shown = "".join(f" {k}={quoteattr(v)}" for k, v in attrs.items())
        out.append(f"  <statectl:recovery{shown}/>")
    return out


def import_file(
    path: str | os.PathLike[str], out: str | os.PathLike[str] | None = None
) -> tuple[list[Path] | str, list[Diagnostic]]:
    """Convert an SCXML file to a device file; or keep it, returning its text and why.

    ``out`` names the device file (any table format by its suffix; default: the
    document's name with ``.yaml``). Returns the files written, or, when the chart
    does not fit the tables, the document's text unchanged with info diagnostics.
    """
    source = Path(path)
    try:
        content = read_input(source)  # decoded by the reader, as the prolog declares
    except OSError as exc:
        raise DiagnosticError(
            [
                Diagnostic(
                    "S607",
                    Severity.ERROR,
                    Location(str(source)),
                    f"cannot read: {exc.strerror or exc}",
                    "check the path",
                )
            ]
        ) from exc
    tables, _, diagnostics = import_text(content, str(source), str(source.parent))
    if tables is None:
        return content.decode("utf-8", "replace"), diagnostics
    target = Path(out) if out is not None else source.with_suffix(".yaml")
    return save(tables, target), diagnostics


def export_file(path: str | os.PathLike[str]) -> str:
    """A device file (YAML, CSV, XLSX or Markdown) as SCXML text.

    Raises :class:`DiagnosticError` if the device file does not build.
    """
    chart = load_chart(path)
    spaced = [
        Diagnostic(
            "S624",
            Severity.ERROR,
            st.origin if st.origin.file else Location(str(path)),
            f"state {st.name!r} holds whitespace, which an SCXML state id cannot: "
            "the document would name another state, or none",
            "rename the state without spaces (for instance with '_') to export it",
        )
        for st in chart.states
        if any(c.isspace() for c in st.name)
    ]
    if spaced:
        raise DiagnosticError(spaced)
    text = write_scxml(chart)
    tables, _ = load(path)
    if tables is None or not tables.recovery:
        return text
    lines = text.split("\n")
    at = next(i for i, line in enumerate(lines) if line.startswith("<scxml")) + 1
    lines[at:at] = _recovery_elements(tables)
    return "\n".join(lines)
