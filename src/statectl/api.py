"""The two verbs of the stable API that are not classes: ``load`` and ``check``.

Both take paths, as the command line does, and speak the project's diagnostics:
``load`` raises :class:`~statectl.kernel.errors.DiagnosticError` carrying every problem
(a missing file is T110 for a device file, S607 for an SCXML document), ``check``
returns them all (errors, warnings and info) and never raises for a broken file.
"""

from __future__ import annotations

import os
from pathlib import Path

from statectl.kernel.errors import Diagnostic
from statectl.kernel.model import Chart

__all__ = ["check", "load"]

_SCXML = (".scxml", ".xml")


def load(path: str | os.PathLike[str]) -> Chart:
    """The chart of a device file (YAML, CSV pair, XLSX, Markdown) or an SCXML document."""
    if Path(path).suffix.lower() in _SCXML:
        from statectl.out.scxml import read_scxml_file

        return read_scxml_file(os.fspath(path))
    from statectl.front.builder.build import load_chart

    return load_chart(path)


def check(*paths: str | os.PathLike[str]) -> list[Diagnostic]:
    """Every problem ``statectl check`` reports for these device files, in file order.

    A cell file or a run config is C415 (use verify, or run --config), as on the
    command line, not the device loader's T102.
    """
    from statectl.front.kinds import cell_given_to_check
    from statectl.front.rules import check_paths

    found: list[Diagnostic] = []
    for given in paths:
        p = os.fspath(given)
        cell = cell_given_to_check(p)
        found.extend([cell] if cell is not None else check_paths([p]))
    return found
