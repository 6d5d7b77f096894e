"""Device tables as CSV: ``NAME.states.csv`` + ``NAME.events.csv`` (+ data, + recovery).

Rules:
1. Each file has a header row naming its columns (any order, any subset that
   holds the required ones); leading lines starting with ``#`` are comments, and
   ``# device: NAME`` among them names the device (else ``NAME`` from the file name).
2. List cells (``control``, ``ignore``) are comma-separated inside one cell.
3. The optional data file ``NAME.data.csv`` has columns ``name,value``; a value
   is a YAML literal. The optional recovery file ``NAME.recovery.csv`` has
   columns ``state,event,data`` (and ``redo``: yes, or empty); data is a YAML flow value.
4. Locations are the CSV line where a record starts (1-based, comments counted).
5. Quoting is strict: an unclosed quote is T101 at the line the parser reached.
6. Blank lines, the header, short rows and cells past the header follow the rules
   every flat format shares (:mod:`statectl.front.tables.grid`).
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from pathlib import Path

from statectl.front.tables.grid import FlatSource, Record, data_entries, read_grid
from statectl.front.tables.rows import DeviceTables, RawTable, diag
from statectl.front.tables.schema import flat_tables, make_tables
from statectl.kernel.errors import Diagnostic, Location

__all__ = ["CsvFiles", "csv_paths", "dump_csv", "input_exists", "read_csv"]

DEVICE_LINE = re.compile(r"^#\s*device\s*:\s*(.*)$", re.IGNORECASE)
PROFILE_LINE = re.compile(r"^#\s*profile\s*:\s*(.*)$", re.IGNORECASE)


def _profile(text: str) -> str:
    """The ``# profile: NAME`` comment among the states file's first comment lines."""
    for line in text.split("\n"):
        if not line.lstrip().startswith("#"):
            break
        m = PROFILE_LINE.match(line.strip())
        if m:
            return m.group(1).strip()
    return ""


SUFFIXES = (".states.csv", ".events.csv", ".data.csv", ".recovery.csv")


@dataclass(frozen=True, slots=True)
class CsvFiles:
    """Where one device's CSV files are (or go)."""

    name: str
    states: Path
    events: Path
    data: Path
    recovery: Path

    @property
    def optional(self) -> tuple[Path, ...]:
        """The files a device may do without (written only when their table has rows)."""
        return (self.data, self.recovery)


def file_stem(device: str) -> str:
    """A device name as a file name inside a directory: no separator, no leading dot, so a
    name such as ``../x`` cannot write outside the directory it is saved into."""
    stem = re.sub(r'[\\/:*?"<>|\x00-\x1f]', "_", device).strip().lstrip(".")
    return stem or "device"


def input_exists(path: Path) -> bool:
    """The file exists, or ``NAME.csv`` names a CSV pair whose states file exists.

    Every reader of a device file asks this one question (the CLI, the pytest
    plugin), so ``NAME.csv`` is a device file wherever a path is taken.
    """
    if path.exists():
        return True
    if path.suffix.lower() != ".csv":
        return False
    pair = csv_paths(path)
    return pair is not None and pair.states.exists()


def csv_paths(path: Path, device: str | None = None) -> CsvFiles | None:
    """The pair a path names: either file of it, ``NAME.csv``, or a directory.

    For a directory, ``device`` names the pair (when saving); without it the
    directory must hold exactly one ``*.states.csv`` (``None`` otherwise).
    """
    if path.is_dir():
        if device is not None:
            name = file_stem(device)
        else:
            found = sorted(path.glob("*.states.csv"))
            if len(found) != 1:
                return None
            name = found[0].name[: -len(".states.csv")]
        base = path
    else:
        base = path.parent
        name = path.name
        for suffix in (*SUFFIXES, ".csv"):
            if name.lower().endswith(suffix):
                name = name[: -len(suffix)]
                break
    return CsvFiles(
        name,
        base / f"{name}.states.csv",
        base / f"{name}.events.csv",
        base / f"{name}.data.csv",
        base / f"{name}.recovery.csv",
    )


def _records(text: str, file: str, diags: list[Diagnostic]) -> tuple[str | None, list[Record]]:
    """The device comment and each record with its starting line (blank ones too: what
    a record means is the flat formats' one answer, :mod:`statectl.front.tables.grid`)."""
    lines = text.split("\n")
    device: str | None = None
    skip = 0
    while skip < len(lines) and lines[skip].lstrip().startswith("#"):
        m = DEVICE_LINE.match(lines[skip].strip())
        if m and device is None:
            device = m.group(1).strip()
        skip += 1
    reader = csv.reader(io.StringIO("\n".join(lines[skip:])), strict=True)
    records: list[Record] = []
    last = 0
    try:
        for record in reader:
            records.append((last + 1 + skip, record))
            last = reader.line_num
    except csv.Error as exc:
        diags.append(diag("T101", Location(file, reader.line_num + skip), f"malformed CSV: {exc}"))
    return device, records


#: What to do about a cell with text past the header, in CSV's terms (grid rule 3).
FIX = "delete the stray cells or name their column in the header; quote a cell with a comma"


def _table(
    table: str, text: str, file: str, diags: list[Diagnostic]
) -> tuple[str | None, RawTable | None]:
    device, records = _records(text, file, diags)
    source = FlatSource(table, file, f"the {table} file", FIX)
    return device, read_grid(source, records, diags)


def read_csv(
    states: tuple[str, str],
    events: tuple[str, str],
    data: tuple[str, str] | None,
    name: str,
    recovery: tuple[str, str] | None = None,
) -> tuple[DeviceTables | None, list[Diagnostic]]:
    """Read the pair (and the data and recovery files), each given as (text, file name)."""
    diags: list[Diagnostic] = []
    dev_s, state_table = _table("states", states[0], states[1], diags)
    dev_e, event_table = _table("events", events[0], events[1], diags)
    if dev_s is not None and dev_e is not None and dev_s != dev_e:
        diags.append(
            diag(
                "T102",
                Location(events[1], 1),
                f"the events file names device {dev_e!r}, the states file {dev_s!r}",
            )
        )
    device = dev_s or dev_e or name
    entries: list[tuple[str, object, Location]] = []
    if data is not None:
        entries = data_entries(_table("data", data[0], data[1], diags)[1], diags)
    recovery_table = None
    if recovery is not None:
        _, recovery_table = _table("recovery", recovery[0], recovery[1], diags)
    result = make_tables(
        device,
        state_table,
        event_table,
        entries,
        Location(states[1], 1),
        diags,
        recovery_table,
        _profile(states[0]),
    )
    return result, diags


def _write(header: tuple[str, ...], rows: list[list[str]], device: str, profile: str = "") -> str:
    out = io.StringIO()
    out.write(f"# device: {device}\n")
    if profile:
        out.write(f"# profile: {profile}\n")
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return out.getvalue()


def dump_csv(tables: DeviceTables) -> tuple[str, str, str | None, str | None]:
    """The states, events, data and recovery files' text (``None``: that table is empty)."""
    text = {
        name: _write(header, rows, tables.device, tables.profile if name == "states" else "")
        for name, header, rows in flat_tables(tables)
    }
    return text["states"], text["events"], text.get("data"), text.get("recovery")
