"""What ``statectl verify CELL`` builds on: explore a cell, write its failing traces.

The command itself (options, printing, exit codes: rules in
:mod:`statectl.channels.cli.verify`) is in the CLI; these functions return values and
write only the files they are asked to.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

from statectl.cell.explore.diagrams import to_mermaid, to_plantuml
from statectl.cell.explore.report import Report
from statectl.cell.explore.search import Progress, explore
from statectl.cell.model import load_cell
from statectl.front.tables import write_files
from statectl.front.tables.rows import diag
from statectl.kernel.errors import Diagnostic, DiagnosticError, Location

__all__ = ["verify_cell", "write_traces"]


def verify_cell(
    path: str | os.PathLike[str],
    *,
    max_states: int | None = None,
    progress: Callable[[Progress], None] | None = None,
    por: bool = True,
    symmetry: bool = True,
) -> tuple[Report | None, list[Diagnostic]]:
    """Load and explore a cell file (``por=False``: without partial-order reduction,
    ``symmetry=False``: without symmetry reduction); ``None`` and the diagnostics when
    it does not load."""
    cell, diags = load_cell(path)
    if cell is None:
        return None, diags
    report = explore(cell, max_states=max_states, progress=progress, por=por, symmetry=symmetry)
    return report, diags


#: Longest part of a trace file name taken from a property's name: file systems
#: refuse names over 255 bytes, and the file's number keeps shortened names apart.
MAX_SLUG = 60


def _slug(text: str) -> str:
    slug = "".join(c if c.isalnum() or c in "-_" else "-" for c in text).strip("-")
    return slug[:MAX_SLUG].rstrip("-") or "trace"


def write_traces(report: Report, directory: str | os.PathLike[str]) -> list[Path]:
    """Per failing finding: ``.trace.json`` (replayable), ``.mmd`` and ``.puml`` diagrams.

    All or nothing: a folder this call creates is removed again if a file fails."""
    folder = Path(directory)
    if folder.exists() and not folder.is_dir():
        raise DiagnosticError(
            [diag("T110", Location(str(folder)), "cannot write: it is a file, not a directory")]
        )
    contents: dict[Path, str | bytes] = {}
    for i, f in enumerate(report.failures, 1):
        if f.trace is None:
            continue
        stem = folder / f"{i:02d}-{_slug(f.kind.value)}-{_slug(f.name)}"
        title = f"{f.kind.value} {f.name}"
        doc = {"cell": report.path, "finding": title, **f.trace.to_json()}
        for suffix, text in (
            (".trace.json", json.dumps(doc, indent=2) + "\n"),
            (".mmd", to_mermaid(f.trace, title)),
            (".puml", to_plantuml(f.trace, title)),
        ):
            contents[stem.with_name(stem.name + suffix)] = text
    if not contents:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DiagnosticError(
                [diag("T110", Location(str(folder)), f"cannot write: {exc.strerror or exc}")]
            ) from None
    write_files(contents, make_dirs=True)  # all or nothing; T110 if it cannot be written
    return list(contents)
