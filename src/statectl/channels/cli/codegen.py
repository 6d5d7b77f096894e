"""``statectl codegen FILE --target cpp --out DIR``: build, generate, print what was written.

The target choice, the messages and the exit code (0 written, 1 diagnostics,
2 usage); :func:`statectl.out.codegen.generate` writes the files."""

from __future__ import annotations

from typing import TextIO

from statectl.cell.explore.progress import CountProgress
from statectl.channels.cli.outputs import output, wrote
from statectl.kernel.errors import DiagnosticError, Severity
from statectl.kernel.exits import OK, PROBLEMS, USAGE
from statectl.out.codegen.cpp import generate


def run_codegen(
    path: str,
    out_dir: str,
    target: str,
    out: TextIO,
    err: TextIO,
    progress: bool | None = None,
    *,
    harness: bool = False,
) -> int:
    """``statectl codegen FILE --target cpp --out DIR``: 0 written, 1 diagnostics, 2 usage."""
    if target != "cpp":
        err.write(f"statectl codegen: unknown target {target!r} (available: cpp)\n")
        return USAGE
    from statectl.front.builder.build import (
        load_and_build,  # outer ring: codegen reads tables via build
    )

    try:
        chart, diags = load_and_build(path)
    except DiagnosticError as exc:
        chart, diags = None, list(exc.diagnostics)
    except OSError as exc:
        err.write(f"statectl codegen: cannot read {path}: {exc.strerror or exc}\n")
        return USAGE
    if chart is None:
        from statectl.front.kinds import cell_instead

        for d in cell_instead(path, diags):  # C415: a cell file given for a device file
            err.write(f"{d}\n")
        return PROBLEMS
    show = err.isatty() if progress is None else progress  # as verify --progress
    printer = CountProgress("codegen", "configurations stepped", err) if show else None
    with output(out_dir, directory=True) as folder:  # cli/outputs.py: the one output rule
        written, gen_diags = generate(chart, str(folder), printer, harness=harness)
    if printer is not None:
        printer.done()
    for d in (*diags, *gen_diags):
        if d.severity is not Severity.INFO:
            err.write(f"{d}\n")
    if not written:
        return PROBLEMS
    for p in written:
        wrote(out, p)
    return OK
