"""The paper's State and Event Definition tables (and the Recovery table): four formats.

Rules:
1. The format comes from the path: ``.yaml``/``.yml``, ``.csv`` (or a directory
   holding one CSV pair), ``.xlsx``, ``.md``/``.markdown``. A device's optional
   tables (data, recovery) sit in the same file, or for CSV in their own files
   ``NAME.data.csv`` and ``NAME.recovery.csv`` beside the pair.
2. :func:`load` never raises for bad input: it returns the tables (``None`` if
   there was any error) and every diagnostic found.
3. Conversion is lossless: ``load(save(t))`` equals ``t`` except for locations
   (compare with :func:`strip_locations`).
4. :func:`save` writes atomically: every file goes to a temporary name in its
   directory first and is renamed into place only when all were written, so a
   failed save leaves nothing half-written. It raises :class:`DiagnosticError`.
   Saving CSV tables without data or recovery rows removes a stale
   ``NAME.data.csv`` / ``NAME.recovery.csv`` after the renames, so that what was
   saved is what loads back.
"""

from __future__ import annotations

import contextlib
import enum
import os
import secrets
from collections.abc import Mapping
from pathlib import Path

from statectl.front.tables.csv_io import csv_paths, dump_csv, read_csv
from statectl.front.tables.inputs import read_input
from statectl.front.tables.md_io import dump_md, read_md
from statectl.front.tables.rows import (
    CODES,
    DeviceTables,
    EventRow,
    RecoveryRow,
    StateRow,
    diag,
    strip_locations,
)
from statectl.front.tables.schema import validate_for_writing
from statectl.front.tables.xlsx_io import dump_xlsx, read_xlsx
from statectl.front.tables.yaml_io import dump_yaml, read_yaml
from statectl.kernel.errors import Diagnostic, DiagnosticError, Location

__all__ = [
    "CODES",
    "DeviceTables",
    "EventRow",
    "Format",
    "RecoveryRow",
    "StateRow",
    "dump",
    "dump_csv",
    "format_of",
    "load",
    "save",
    "strip_locations",
    "write_files",
]


class Format(enum.Enum):
    YAML = "yaml"
    CSV = "csv"
    XLSX = "xlsx"
    MD = "md"


SUFFIXES = {
    ".yaml": Format.YAML,
    ".yml": Format.YAML,
    ".csv": Format.CSV,
    ".xlsx": Format.XLSX,
    ".md": Format.MD,
    ".markdown": Format.MD,
}


def format_of(path: str | os.PathLike[str]) -> Format | None:
    """The format a path names (a directory holds a CSV pair); ``None`` if unknown."""
    p = Path(path)
    if p.is_dir():
        return Format.CSV
    return SUFFIXES.get(p.suffix.lower())


def _format(fmt: str | Format | None, path: Path) -> Format:
    if isinstance(fmt, Format):
        return fmt
    if fmt is None:
        found = format_of(path)
        if found is None:
            raise DiagnosticError([_unknown_format(path)])
        return found
    try:
        return Format(fmt.lower())
    except ValueError:
        raise DiagnosticError([_unknown_format(path, fmt)]) from None


def _unknown_format(path: Path, fmt: str | None = None) -> Diagnostic:
    what = f"format {fmt!r}" if fmt else f"the file name {path.name!r}"
    hint = "use .yaml, .csv (a NAME.states.csv + NAME.events.csv pair), .xlsx or .md"
    if not fmt and path.suffix.lower() == ".scxml":  # a document, not tables: say where it goes
        hint = (
            f"an SCXML document: statectl scxml run {path} runs it, statectl scxml "
            f"import {path} writes it as device tables when it fits them"
        )
    return diag("T102", Location(str(path)), f"{what} names no device table format", hint)


def _read_text(
    path: Path, diags: list[Diagnostic], texts: Mapping[str, str] | None = None
) -> str | None:
    if texts and (held := texts.get(os.path.abspath(path))) is not None:
        return held
    try:
        return read_input(path).decode("utf-8-sig")
    except FileNotFoundError:
        diags.append(diag("T110", Location(str(path)), "file not found"))
    except UnicodeDecodeError as exc:
        diags.append(diag("T101", Location(str(path)), f"not UTF-8 text: {exc.reason}"))
    except OSError as exc:
        diags.append(diag("T110", Location(str(path)), f"cannot read: {exc.strerror or exc}"))
    return None


def load(
    path: str | os.PathLike[str], texts: Mapping[str, str] | None = None
) -> tuple[DeviceTables | None, list[Diagnostic]]:
    """Read a device file in any format; all problems come back as diagnostics.

    ``texts`` holds the content of text files by absolute path, read instead of
    the disk (an editor's unsaved buffers: statectl.channels.lsp); a CSV pair
    takes either file from it.
    """
    p = Path(path)
    fmt = format_of(p)
    if fmt is None:
        if not p.exists():
            return None, [diag("T110", Location(str(p)), "file not found")]
        return None, [_unknown_format(p)]
    diags: list[Diagnostic] = []
    if fmt is Format.CSV:
        files = csv_paths(p)
        if files is None:
            return None, [
                diag(
                    "T110" if p.is_dir() else "T102",
                    Location(str(p)),
                    "the directory holds no single NAME.states.csv + NAME.events.csv pair",
                    "name the pair's file instead",
                )
            ]
        states = _read_text(files.states, diags, texts)
        events = _read_text(files.events, diags, texts)
        data = _read_text(files.data, diags, texts) if files.data.exists() else None
        recovery = _read_text(files.recovery, diags, texts) if files.recovery.exists() else None
        if states is None or events is None:
            return None, diags
        tables, more = read_csv(
            (states, str(files.states)),
            (events, str(files.events)),
            (data, str(files.data)) if data is not None else None,
            files.name,
            (recovery, str(files.recovery)) if recovery is not None else None,
        )
        return tables, [*diags, *more]
    if fmt is Format.XLSX:
        try:
            content = read_input(p)
        except FileNotFoundError:
            return None, [diag("T110", Location(str(p)), "file not found")]
        except OSError as exc:
            return None, [diag("T110", Location(str(p)), f"cannot read: {exc.strerror or exc}")]
        return read_xlsx(content, str(p), p.stem)
    text = _read_text(p, diags, texts)
    if text is None:
        return None, diags
    if fmt is Format.YAML:
        return read_yaml(text, str(p))
    return read_md(text, str(p), p.stem)


def dump(tables: DeviceTables, fmt: str | Format) -> str | bytes:
    """One file's content: text for YAML and Markdown, bytes for XLSX.

    A CSV device is two to four files: use :func:`dump_csv` for it.
    """
    f = fmt if isinstance(fmt, Format) else Format(fmt.lower())
    problems = validate_for_writing(tables, tables.source)
    if problems:
        raise DiagnosticError(problems)
    if f is Format.YAML:
        return dump_yaml(tables)
    if f is Format.MD:
        return dump_md(tables)
    if f is Format.XLSX:
        return dump_xlsx(tables)
    raise ValueError("a CSV device is several files: use dump_csv() or save()")


def _contents(
    tables: DeviceTables, fmt: Format, path: Path
) -> tuple[dict[Path, str | bytes], tuple[Path, ...]]:
    """The files to write, and the stale optional CSV files to remove after them."""
    if fmt is Format.CSV:
        files = csv_paths(path, tables.device if path.is_dir() else None)
        assert files is not None  # with a device name a directory always names a pair
        states, events, data, recovery = dump_csv(tables)
        out: dict[Path, str | bytes] = {files.states: states, files.events: events}
        for target, text in zip(files.optional, (data, recovery), strict=True):
            if text is not None:
                out[target] = text
        return out, tuple(p for p in files.optional if p not in out and p.exists())
    return {path: dump(tables, fmt)}, ()


def write_files(
    contents: dict[Path, str | bytes], stale: tuple[Path, ...] = (), *, make_dirs: bool = False
) -> None:
    """Write every file atomically (rule 4), the one way every command writes its output.

    Each file goes to a temporary name beside it and all are renamed into place
    once all were written; on any failure nothing is left behind and an existing
    file is untouched. ``make_dirs`` creates missing parent folders first (an
    output directory), else a missing folder is an error. Raises
    :class:`DiagnosticError` (T110) naming the file that could not be written and why.
    """
    target: Path | None = None
    made: list[Path] = []  # folders this call created, removed again on failure
    try:
        for target in contents:
            if target.is_dir():
                raise _NotWritable(target, "it is a directory; name a file in it")
            if make_dirs:
                _make_dirs(target.parent, made)
            elif target.parent.exists() and not target.parent.is_dir():
                raise _NotWritable(target, f"{target.parent} is a file, not a directory")
            elif not target.parent.is_dir():
                raise _NotWritable(target, f"no such directory {target.parent}; create it first")
        _write_all(contents, stale)
    except _NotWritable as exc:
        _remove_dirs(made)
        raise DiagnosticError([diag("T110", Location(str(exc.path)), exc.reason)]) from None
    except OSError as exc:
        _remove_dirs(made)
        where = str(target) if target is not None else str(exc.filename)
        raise DiagnosticError(
            [diag("T110", Location(where), f"cannot write: {exc.strerror or exc}")]
        ) from exc


def _make_dirs(folder: Path, made: list[Path]) -> None:
    """``mkdir -p folder``, noting in ``made`` each folder it created, outermost first."""
    missing: list[Path] = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    for each in reversed(missing):
        each.mkdir(exist_ok=True)
        made.append(each)


def _remove_dirs(made: list[Path]) -> None:
    """Remove the folders a failed write created, innermost first, if still empty."""
    for each in reversed(made):
        with contextlib.suppress(OSError):
            each.rmdir()


class _NotWritable(Exception):
    def __init__(self, path: Path, reason: str) -> None:
        super().__init__(reason)
        self.path, self.reason = path, reason


def _write_all(contents: dict[Path, str | bytes], stale: tuple[Path, ...] = ()) -> None:
    """Write every file to a temporary name, rename all into place, then drop ``stale``."""
    temps: list[tuple[str, Path]] = []
    try:
        for target, content in contents.items():
            temp = str(target.parent / f".{target.name}.{secrets.token_hex(6)}.tmp")
            # os.open with 0o666 honours the umask, as a plain open() would
            fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            temps.append((temp, target))
            with os.fdopen(fd, "wb") as fh:
                fh.write(content.encode("utf-8") if isinstance(content, str) else content)
        for temp, target in temps:
            os.replace(temp, target)
        for old in stale:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(old)
    finally:
        for temp, _ in temps:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(temp)


def save(
    tables: DeviceTables, path: str | os.PathLike[str], fmt: str | Format | None = None
) -> list[Path]:
    """Write the tables to ``path`` in ``fmt`` (default: from the path); return the files.

    Raises :class:`DiagnosticError` (T1xx) if the tables cannot be written as
    they are or a file cannot be created; nothing is written then.
    """
    p = Path(path)
    f = _format(fmt, p)
    problems = validate_for_writing(tables, Location(str(p)))
    if problems:
        raise DiagnosticError(problems)
    try:
        contents, stale = _contents(tables, f, p)
    except DiagnosticError:
        raise
    except Exception as exc:  # e.g. characters a workbook cannot hold
        raise DiagnosticError(
            [diag("T108", Location(str(p)), f"the tables cannot be written as {f.value}: {exc}")]
        ) from exc
    write_files(contents, stale)
    return list(contents)
