"""Which kind of file a path is, and a file given to a command for the other kind.

``check`` takes device files, ``verify`` cells; :func:`is_cell` tells them apart (by the
top-level keys, without loading a device file twice). Below the CLI so that
:func:`statectl.api.check` says what ``statectl check`` says.

Rules:
1. ``statectl check`` on a cell file (``devices:`` and no ``states:``) reports
   C415, "this is a cell: use statectl verify", instead of the device loader's
   T102; the other files given are checked as usual. A run config (every device
   entry names a ``driver``) gets C415 too, pointing at ``run --config``.
2. ``statectl verify`` on a device file (a YAML mapping with ``states:`` or
   ``events:``, or device tables in CSV, XLSX or Markdown) or an SCXML document
   reports C416, saying which command takes it, instead of a page of V802s.
3. Both are errors at the file's line that shows its kind: exit 1, as any
   problem in an input file.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from statectl.front.tables import safeyaml
from statectl.front.tables.inputs import read_input_text
from statectl.kernel.errors import Diagnostic, Location, Severity

__all__ = ["cell_given_to_check", "cell_instead", "device_given_to_verify", "is_cell"]

_TABLE_FORMATS = (".csv", ".xlsx", ".md", ".markdown")


def is_cell(path: str) -> bool:
    """A YAML file with a ``devices`` section and no ``states`` table is a cell file."""
    if Path(path).suffix.lower() not in (".yaml", ".yml"):
        return False
    try:
        keys = safeyaml.top_keys(read_input_text(path))  # no second full load of a device file
    except (OSError, UnicodeDecodeError):
        return False  # loaded as a device file, whose loader says what is wrong
    return keys is not None and "devices" in keys and "states" not in keys


def _line_of(path: str, key: str) -> int:
    """The line where the top-level ``key:`` starts (1 if it cannot be found)."""
    try:
        lines = read_input_text(path).splitlines()
    except (OSError, UnicodeDecodeError):
        return 1
    return next((n for n, text in enumerate(lines, 1) if text.startswith(f"{key}:")), 1)


def cell_given_to_check(path: str) -> Diagnostic | None:
    """Rule 1: C415 when ``path`` is a cell file, else None."""
    if not is_cell(path):
        return None
    if _is_run_config(path):
        return Diagnostic(
            "C415",
            Severity.ERROR,
            Location(path, _line_of(path, "devices")),
            "this is a run config (devices: naming drivers), not a device file: "
            f"use statectl run MODEL --config {path}",
            "a run config binds drivers to the devices of a model or cell; check the model",
        )
    return Diagnostic(
        "C415",
        Severity.ERROR,
        Location(path, _line_of(path, "devices")),
        "this is a cell file (devices:, no states:), not a device file: "
        f"use statectl verify {path}",
        "verify checks the cell and loads each device file, reporting its problems as V805",
    )


def _is_run_config(path: str) -> bool:
    """A ``devices:`` mapping whose every entry names a ``driver`` and no device ``file``."""
    try:
        data = safeyaml.load_value(read_input_text(path))
    except (OSError, UnicodeDecodeError, safeyaml.YamlRefused):
        return False
    devices = data.get("devices") if isinstance(data, dict) else None
    return (
        isinstance(devices, dict)
        and bool(devices)
        and all(isinstance(v, dict) and "driver" in v and "file" not in v for v in devices.values())
    )


def device_given_to_verify(path: str) -> Diagnostic | None:
    """Rule 2: C416 when ``path`` is a device file or an SCXML document, else None."""
    suffix = Path(path).suffix.lower()
    if suffix == ".scxml":
        return Diagnostic(
            "C416",
            Severity.ERROR,
            Location(path, 1),
            f"this is an SCXML document, not a cell file: use statectl scxml run {path}",
            "or statectl scxml import it to device tables, and name them in a cell's devices:",
        )
    line = 1
    if suffix in (".yaml", ".yml"):
        try:
            data = safeyaml.load_value(read_input_text(path))
        except (OSError, UnicodeDecodeError, safeyaml.YamlRefused):
            return None  # the cell loader says what is wrong (V801)
        if not isinstance(data, dict) or is_cell(path):
            return None
        key = next((k for k in ("states", "events") if k in data), None)
        if key is None:
            return None
        line = _line_of(path, key)
    elif suffix not in _TABLE_FORMATS:
        return None
    return Diagnostic(
        "C416",
        Severity.ERROR,
        Location(path, line),
        f"this is a device file, not a cell file: use statectl check {path} "
        f"(or statectl run {path})",
        "a cell names its device files under devices:, see docs/cells.md",
    )


def cell_instead(path: str, diags: Sequence[Diagnostic]) -> list[Diagnostic]:
    """``diags`` of a device file that did not load, or C415 alone when it is a cell file
    (a command that takes a device file says which command takes a cell, as check does)."""
    if any(d.severity is Severity.ERROR for d in diags):
        cell = cell_given_to_check(path)
        if cell is not None:
            return [cell]
    return list(diags)
