"""One rule for every output path a command is given (``--out``, ``-o``, ``--journal``).

Rules:
1. Missing parent directories are created: ``--out build/motor/motor.svg`` works on a
   fresh checkout, for every command alike.
2. A path that ends in a slash, or names a directory that exists, is a directory: the
   command writes its file(s) into it under their usual name. (A run's journal is read
   back by ``--resume`` too, so there only the slash says it: an existing directory
   given as a journal file is refused, as a journal it cannot be.)
3. Nothing is left half-written: the files themselves are written atomically
   (:func:`statectl.front.tables.write_files`, T110 if they cannot be), and a directory
   this rule created that is still empty when the command ends is removed again.
4. Every file written is said on one line, ``wrote PATH``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TextIO

__all__ = ["output", "wrote"]


def is_directory(arg: str, existing: bool = True) -> bool:
    """Rule 2: ``arg`` ends in a slash or (``existing``) names an existing directory."""
    return arg.endswith(("/", os.sep)) or (existing and os.path.isdir(arg))


@contextmanager
def output(
    arg: str, name: str | None = None, *, directory: bool = False, existing: bool = True
) -> Iterator[Path]:
    """The path to write for ``arg`` (rules 1-3), its parents made for the ``with`` body.

    ``name`` is the file's usual name, used when ``arg`` is a directory (rule 2);
    without one, a directory ``arg`` is given back as it is (the writer names the
    files, as the CSV pair does). ``directory`` says the command writes a directory
    (``codegen``, ``testgen``): then ``arg`` itself is made too. ``existing=False``: only
    a trailing slash makes ``arg`` a directory (a journal, rule 2).
    """
    path = Path(arg)
    into = is_directory(arg, existing)
    folder = path if directory or (name is None and into) else path.parent
    if name is not None and not directory and into:
        path, folder = path / name, path
    made = _make_dirs(folder)
    try:
        yield path
    finally:
        for each in reversed(made):  # innermost first; rmdir leaves a non-empty one alone
            try:
                each.rmdir()
            except OSError:
                break


def _make_dirs(folder: Path) -> list[Path]:
    """``mkdir -p folder``; the folders it created, outermost first.

    One that cannot be made (no permission) raises its OSError, with the folders made
    so far removed again; a file in the way is left for the writer to report (T110).
    """
    missing: list[Path] = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    if not folder.is_dir():  # a file in the way: the writer says so (T110)
        return []
    made: list[Path] = []
    try:
        for each in reversed(missing):
            each.mkdir()
            made.append(each)
    except OSError:
        for each in reversed(made):
            each.rmdir()
        raise
    return made


def wrote(stream: TextIO, path: str | os.PathLike[str], detail: str = "") -> None:
    """Rule 4: ``wrote PATH`` (and ``: detail``) on ``stream``."""
    stream.write(f"wrote {os.fspath(path)}{': ' + detail if detail else ''}\n")
