"""``statectl verify CELL``: explore a cell (or export it as Promela) and print the report.

The printing, the checks of the options and the exit code; the search, the
report and the trace files are library code in :mod:`statectl.cell.explore`. Rules:

1. A cell that does not load prints every diagnostic and exits 1; a missing
   file or a bad option is a usage error (2).
2. Exit 0 only when every property holds over the complete state space.
3. The progress display goes to stderr, only when stderr is a terminal or the
   caller asks for it; ``--json`` writes one JSON document to stdout."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TextIO

from statectl.cell.explore.compose import Composed
from statectl.cell.explore.diagrams import to_mermaid, to_plantuml
from statectl.cell.explore.promela import export_promela
from statectl.cell.explore.search import DEFAULT_MAX_STATES, explore
from statectl.cell.explore.verify import write_traces
from statectl.cell.model import Cell, load_cell
from statectl.channels.cli import outputs
from statectl.channels.cli.progress import ProgressPrinter
from statectl.front.tables import write_files
from statectl.kernel.errors import Severity
from statectl.kernel.exits import OK, PROBLEMS, USAGE


def verify_main(
    cell: str,
    *,
    as_json: bool = False,
    max_states: int | None = None,
    symmetry: bool = True,
    export: str | None = None,
    output: str | None = None,
    traces: str | None = None,
    diagrams: str | None = None,
    progress: bool | None = None,
    por: bool = True,
    out: TextIO,
    err: TextIO,
) -> int:
    """The whole ``statectl verify`` command; returns the exit code.

    ``export="promela"`` writes the composed model (to ``output`` or stdout) instead
    of exploring; ``traces`` names a folder for the failing traces and diagrams;
    ``diagrams`` ("mermaid" or "plantuml") prints each failing trace's diagram.
    ``max_states`` bounds the search (``None``: :data:`DEFAULT_MAX_STATES`; 0: no bound);
    ``por=False`` (``--no-por``) turns partial-order reduction off, ``symmetry=False``
    (``--no-symmetry``) the symmetry reduction (every state stored, not one per orbit).
    """
    if not Path(cell).is_file():
        err.write(f"statectl verify: {cell}: no such file\n")
        return USAGE
    if export not in (None, "promela") or diagrams not in (None, "mermaid", "plantuml"):
        err.write("statectl verify: --export takes promela; --diagrams mermaid or plantuml\n")
        return USAGE
    if max_states is not None and max_states < 0:
        err.write("statectl verify: --max-states must be 0 (no bound) or more\n")
        return USAGE
    bound = DEFAULT_MAX_STATES if max_states is None else (max_states or None)
    from statectl.front.kinds import device_given_to_verify

    other = device_given_to_verify(cell)  # C416: a device file, not a cell
    if other is not None:
        err.write(f"{other}\n")
        return PROBLEMS
    loaded, diags = load_cell(cell)
    for d in diags:
        if d.severity is not Severity.INFO and (loaded is None or d.severity is Severity.WARNING):
            err.write(f"{d}\n")
    if loaded is None:
        err.write(f"{cell}: not loaded\n")
        return PROBLEMS
    if export == "promela":
        return _export(loaded, output, out, f"{Path(cell).stem}.pml")
    show = err.isatty() if progress is None else progress
    printer = ProgressPrinter(err) if show else None
    report = explore(loaded, max_states=bound, progress=printer, por=por, symmetry=symmetry)
    if printer is not None:
        printer.done()
    if as_json:
        json.dump(report.to_json(), out, indent=2)
        out.write("\n")
    else:
        out.write(report.to_text())
        for f in report.failures if diagrams else ():
            if f.trace is not None:
                title = f"{f.kind.value} {f.name}"
                draw = to_mermaid if diagrams == "mermaid" else to_plantuml
                out.write(f"\n{draw(f.trace, title)}")
    if traces:
        with outputs.output(traces, directory=True) as folder:
            for p in write_traces(report, str(folder)):
                outputs.wrote(err, p)
    return OK if report.verdict == "holds" else PROBLEMS  # failed, or could not tell


def _export(cell: Cell, output: str | None, out: TextIO, name: str) -> int:
    text = export_promela(Composed(cell))
    if output:
        with outputs.output(output, name) as target:  # cli/outputs.py: the one output rule
            write_files({target: text})  # T110 (exit 1 in main()) if it cannot be written
        outputs.wrote(out, target)
    else:
        out.write(text)
    return OK
