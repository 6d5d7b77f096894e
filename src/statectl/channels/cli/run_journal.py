"""The journal of a run or a node: opened after checks, undone if the run never starts.

Shared by ``statectl run`` (cli/run.py) and ``statectl node`` (cli/node.py).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TextIO

from statectl.kernel.errors import StatectlError
from statectl.run.journal import Guarantee, Journal, JournalDamaged, JournalError, Sync, set_aside
from statectl.run.journal.check import journal_files

__all__ = ["JOURNAL_NAME", "new_journal", "open_journal", "undone_on_failure"]


#: The journal's file name when ``--journal`` names a directory (cli/outputs.py rule 2).
JOURNAL_NAME = "run.db"


def open_journal(
    path: str,
    sync: Sync,
    guarantee: Guarantee,
    *,
    resume: bool,
    fresh: bool,
    out: TextIO,
    inputs: Sequence[str | None] = (),
) -> Journal:
    """The run's journal, checked before anything starts; ``--fresh`` sets the old one aside.

    ``fresh`` without ``resume``: any existing journal is set aside. With
    ``resume``: only one that cannot be trusted (:class:`JournalDamaged`). Without
    ``fresh`` such a journal is refused, and the message says how to start over.
    A journal path that is one of the run's ``inputs`` (its device, cell or config
    file) is refused first: ``--fresh`` would move that file aside; so is a directory.
    """
    p = Path(path)
    if not p.parent.is_dir():
        raise StatectlError(
            f"--journal {path}: the directory {p.parent} does not exist; nothing was started: "
            "make it first, or give a journal path in a directory that exists"
        )
    if p.exists() and not p.is_file():  # --fresh would move a whole directory aside
        raise StatectlError(
            f"--journal {path} is a directory, not a journal file; nothing was started: "
            f"name a file, e.g. --journal {p / 'run.db'}"
        )
    for given in inputs:
        with contextlib.suppress(OSError):
            if given and p.exists() and os.path.samefile(p, given):
                raise StatectlError(
                    f"--journal {path} is the run's input file {given}, not a journal; "
                    "nothing was started: name another file, e.g. --journal run.db"
                )
    if resume and p.is_file() and p.stat().st_size == 0:  # a new journal has its schema
        damage: JournalDamaged | None = JournalDamaged(p, ["it is empty (0 bytes)"])
    else:
        damage = None
    if fresh and not resume and p.exists() and p.stat().st_size > 0:
        aside = set_aside(p)
        out.write(f"journal {p} set aside as {aside}; starting a new journal\n")
    try:
        if damage is not None:
            raise damage
        return Journal(p, sync=sync, guarantee=guarantee)
    except JournalDamaged as exc:
        if not fresh:
            raise JournalError(
                f"{exc}. Nothing was started. To start over with a new journal and keep this "
                f"one aside (renamed with a timestamp), run again with --fresh"
            ) from None
        aside = set_aside(p)
        out.write(f"{exc}\njournal {p} set aside as {aside}; starting a new journal\n")
        return Journal(p, sync=sync, guarantee=guarantee)


def new_journal(path: str, *, resume: bool, fresh: bool) -> bool:
    """Whether opening ``path`` makes a new journal file (none there, or ``--fresh``)."""
    return not Path(path).exists() or (fresh and not resume)


@contextlib.contextmanager
def undone_on_failure(store: Journal | None, made: str | None) -> Iterator[None]:
    """A run refused before it started (a driver that cannot drive its device, links a
    journal cannot hold) closes the journal it opened, and removes it if this run made
    it: nothing is left half-written (an unmerged ``-wal`` beside a new, empty file)."""
    try:
        yield
    except BaseException:
        if store is not None:
            with contextlib.suppress(StatectlError, OSError):
                store.close()
        if made is not None:
            for file in journal_files(made):
                with contextlib.suppress(OSError):
                    file.unlink(missing_ok=True)
        raise
