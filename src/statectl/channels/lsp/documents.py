"""The files an editor works on: what each is, its diagnostics and its names.

Rules:
1. A file's kind is decided as ``statectl check`` decides it
   (:mod:`statectl.front.kinds`): YAML with ``devices:`` and no
   ``states:`` is a cell, unless every device entry names a ``driver`` (a run
   config); a mapping of run-config sections only is a run config too;
   anything else, and every CSV or Markdown file, is device tables.
2. Diagnostics come from the loaders and rules the command line runs, fed the
   editor's text instead of the disk: a device file is what ``statectl check``
   reports (:func:`statectl.front.rules.check_paths`), a cell what ``statectl
   verify`` reports before it explores (:func:`statectl.cell.model.load_cell`), a
   run config what ``statectl run --config`` reports
   (:func:`statectl.channels.runconfig.load_run_config`). Only those placed in
   the file itself are kept (a CSV pair's other file has its own).
3. :class:`Project` holds the editor's open texts, read before the disk
   wherever a file is read (a CSV pair's other half, a cell's device files when
   the server indexes them), and finds the cells that use a device file: the
   YAML files under the workspace folders and beside the device.
"""

from __future__ import annotations

import enum
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from statectl.channels.lsp.grid import Grid, read_grid
from statectl.channels.lsp.index import (
    Symbol,
    cell_symbols,
    device_files,
    device_key,
    device_symbols,
)
from statectl.channels.runconfig import RUN_CONFIG_KEYS
from statectl.front.tables import safeyaml
from statectl.front.tables.csv_io import csv_paths
from statectl.front.tables.inputs import read_input_text
from statectl.kernel.errors import Diagnostic, DiagnosticError, Location

__all__ = ["Document", "FileKind", "Project", "diagnose", "kind_of"]

#: How many YAML files a search for the cells that use a device reads at most.
MAX_SCANNED = 2000


class FileKind(enum.Enum):
    DEVICE = "device"
    CELL = "cell"
    RUN_CONFIG = "run config"


def kind_of(path: str, text: str) -> FileKind:
    """Rule 1."""
    if Path(path).suffix.lower() not in (".yaml", ".yml"):
        return FileKind.DEVICE
    try:
        data = safeyaml.load_value(text)
    except safeyaml.YamlRefused:
        return FileKind.DEVICE
    if not isinstance(data, dict) or "states" in data or "events" in data:
        return FileKind.DEVICE
    devices = data.get("devices")
    if isinstance(devices, dict) and devices:
        drivers = all(
            isinstance(v, dict) and "driver" in v and "file" not in v for v in devices.values()
        )
        return FileKind.RUN_CONFIG if drivers else FileKind.CELL
    if data and set(data) <= set(RUN_CONFIG_KEYS):
        return FileKind.RUN_CONFIG
    return FileKind.CELL if "devices" in data else FileKind.DEVICE


@dataclass(frozen=True, slots=True)
class Document:
    """One file as the server sees it: its text, kind, cells and names."""

    path: str  # absolute
    text: str
    kind: FileKind
    grid: Grid
    symbols: tuple[Symbol, ...]
    devices: dict[str, str]  # a cell's instances -> device files (empty for others)

    @property
    def lines(self) -> list[str]:
        return self.text.split("\n")


def analyse(path: str, text: str, states: tuple[str, ...] = ()) -> Document:
    """Read ``text`` as the file at ``path``: its kind, grid and names (``states``: those of
    the other files of a CSV pair, which a guard may quote)."""
    kind = kind_of(path, text)
    grid = read_grid(path, text)
    lines = text.split("\n")
    if kind is FileKind.DEVICE:
        symbols = device_symbols(grid, lines, device_key(path), states)
        return Document(path, text, kind, grid, tuple(symbols), {})
    if kind is FileKind.CELL:
        files = device_files(grid, path)
        return Document(path, text, kind, grid, tuple(cell_symbols(grid, lines, files)), files)
    return Document(path, text, kind, grid, (), {})


def diagnose(doc: Document, texts: dict[str, str]) -> list[Diagnostic]:
    """Rule 2: what the command line reports for this file, placed in this file."""
    found: list[Diagnostic]
    if doc.kind is FileKind.DEVICE:
        from statectl.front.rules import check_paths

        found = check_paths([doc.path], {**texts, doc.path: doc.text})
    elif doc.kind is FileKind.CELL:
        from statectl.cell.model import load_cell

        found = load_cell(doc.path, doc.text)[1]
    else:
        from statectl.channels.runconfig import load_run_config

        try:
            load_run_config(doc.path, doc.text)
            found = []
        except DiagnosticError as exc:
            found = list(exc.diagnostics)
    return [d for d in found if _here(d.where, doc.path)]


def _here(where: Location, path: str) -> bool:
    return where.file == "<memory>" or os.path.abspath(where.file) == path


class Project:
    """The open texts by absolute path, and the workspace folders to search for cells."""

    def __init__(self, roots: tuple[str, ...] = ()) -> None:
        self.texts: dict[str, str] = {}
        self.roots = roots
        #: YAML and Markdown files read from disk, by path: (modified, size), the document
        self._read: dict[str, tuple[tuple[int, int], Document]] = {}

    def text(self, path: str) -> str | None:
        """The editor's text of ``path``, else the file's; ``None`` if neither reads."""
        if path in self.texts:
            return self.texts[path]
        try:
            return read_input_text(path)
        except (OSError, UnicodeDecodeError):
            return None

    def document(self, path: str) -> Document | None:
        """The file as the editor holds it, else as on disk (read again only when it changed:
        a search for cells reads many)."""
        stamp: tuple[int, int] | None = None
        if path not in self.texts and not path.lower().endswith(".csv"):
            try:
                info = os.stat(path)
            except OSError:
                return None
            stamp = (info.st_mtime_ns, info.st_size)
            cached = self._read.get(path)
            if cached is not None and cached[0] == stamp:
                return cached[1]
        text = self.text(path)
        if text is None:
            return None
        states: tuple[str, ...] = ()
        if path.lower().endswith(".csv") and (key := device_key(path)) != path:
            sibling = self.text(key)  # the pair's states file: the names a guard may quote
            if sibling is not None:
                states = tuple(r.text("state") for r in read_grid(key, sibling).table("states"))
        doc = analyse(path, text, states)
        if stamp is not None:
            self._read[path] = (stamp, doc)
        return doc

    def device_documents(self, key: str) -> list[Document]:
        """Every file of the device ``key`` names (:func:`device_key`): one, or a CSV pair's."""
        paths = [key]
        if key.lower().endswith(".csv"):
            files = csv_paths(Path(key))
            if files is not None:
                paths = [str(p) for p in (files.states, files.events, files.recovery)]
        docs = (self.document(p) for p in paths if p in self.texts or os.path.exists(p))
        return [d for d in docs if d is not None]

    def cells_using(self, device: str) -> Iterator[Document]:
        """The cells under the roots and beside ``device`` that name it (rule 3)."""
        for path in self._yaml_files((*self.roots, str(Path(device).parent))):
            doc = self.document(path)
            if doc is not None and doc.kind is FileKind.CELL and device in doc.devices.values():
                yield doc

    def _yaml_files(self, roots: tuple[str, ...]) -> list[str]:
        found: dict[str, None] = dict.fromkeys(p for p in self.texts if _is_yaml(p))
        for root in roots:
            for folder, dirs, files in os.walk(root):
                dirs[:] = [d for d in dirs if not d.startswith(".") and d != "node_modules"]
                found.update((os.path.join(folder, f), None) for f in files if _is_yaml(f))
                if len(found) > MAX_SCANNED:
                    return list(found)[:MAX_SCANNED]
        return list(found)


def _is_yaml(name: str) -> bool:
    return name.lower().endswith((".yaml", ".yml"))
