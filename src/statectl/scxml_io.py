"""SCXML in and out of device tables: ``statectl scxml import`` and ``statectl scxml export``.

Rules:
1. Export: a device file in any table format is built and written as SCXML; the
   device facts SCXML has no word for travel in the ``statectl`` namespace, so the
   document reads back to the same chart.
2. Import: an SCXML document becomes device tables when its chart fits the table
   form (:func:`statectl.build.chart_to_tables`: no executable content beyond
   notifications, one event and one target per transition, safe guards, literal
   data) and the tables build the very same chart. Otherwise it stays SCXML and
   the info diagnostics say why; nothing is written then.
3. A document with errors raises :class:`~statectl.errors.DiagnosticError`
   carrying every diagnostic, as :func:`statectl.build.load_chart` does.

This module sits above both :mod:`statectl.scxml` and :mod:`statectl.build`, which
must not import each other.
"""

from __future__ import annotations

import os
from pathlib import Path

from statectl.build import chart_to_tables, load_chart
from statectl.errors import Diagnostic, DiagnosticError, Location, Severity, has_errors
from statectl.model import Chart
from statectl.scxml import read_scxml, write_scxml
from statectl.tables import DeviceTables, save

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
    tables, why = chart_to_tables(chart)
    return tables, chart, [*diagnostics, *why]


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
        content = source.read_bytes()  # decoded by the reader, as the prolog declares
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
    return write_scxml(load_chart(path))
