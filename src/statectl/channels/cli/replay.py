"""``statectl run CELL --replay TRACE | --walk N``: a cell run, checked against the explorer.

Only the command: its missing files, its messages and its exit code (1 when
the run diverged from the explorer); :func:`statectl.cell.explore.replay.run_cell`
does the run."""

from __future__ import annotations

from pathlib import Path
from typing import TextIO

from statectl.cell.explore.replay import load_replay, run_cell
from statectl.cell.model import load_cell
from statectl.kernel.errors import Severity, StatectlError
from statectl.kernel.exits import OK, PROBLEMS, USAGE


def run_main(
    cell: str, *, replay: str | None = None, walk: int = 20, seed: int = 0, out: TextIO, err: TextIO
) -> int:
    """The whole ``statectl run CELL [--replay TRACE]`` command; returns the exit code."""
    if not Path(cell).is_file():
        err.write(f"statectl run: {cell}: no such file\n")
        return USAGE
    if replay is not None and not Path(replay).is_file():
        err.write(f"statectl run: {replay}: no such trace file\n")
        return USAGE
    loaded, diags = load_cell(cell)
    if loaded is None:
        for d in diags:
            if d.severity is not Severity.INFO:
                err.write(f"{d}\n")
        return PROBLEMS
    try:
        steps = load_replay(replay) if replay is not None else None
    except StatectlError as exc:  # a trace that is there but wrong is bad input: exit 1
        err.write(f"statectl run: {exc}\n")
        return PROBLEMS
    result = run_cell(loaded, out.write, replay=steps, walk=walk, seed=seed)
    return PROBLEMS if result.divergences else OK
