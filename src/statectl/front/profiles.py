"""The standard device profiles shipped in the package, to start a device file from.

Rules:
1. A profile is a device file in ``statectl/data/profiles/`` (YAML, with comments
   that say where each row comes from) and one :class:`Profile` entry here: its
   name, the standard, a one-line summary. The file declares ``profile: NAME``.
2. Every shipped profile builds and passes ``statectl check`` with no error and
   no warning (tests/test_profiles.py), and carries the standard's state numbers
   in the ``number`` column where the standard has them.
3. :func:`new_device` is what ``statectl new`` writes: the profile under another
   device name. For YAML the shipped text is kept, comments and all, with only
   the ``device:`` line changed; the other formats are written from the tables.
   Either way the result is read back and must give the same tables (never a
   half-right file).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from importlib import resources

from statectl.front.tables import DeviceTables, Format, dump, dump_csv, strip_locations
from statectl.front.tables.yaml_io import read_yaml
from statectl.kernel.errors import Diagnostic, DiagnosticError, Location, Severity

__all__ = ["PROFILES", "Profile", "find", "new_device", "profile_tables", "profile_text"]


@dataclass(frozen=True, slots=True)
class Profile:
    """One shipped profile: ``statectl new NAME --profile <name>`` starts from it."""

    name: str
    standard: str
    summary: str

    @property
    def file(self) -> str:
        return f"{self.name}.yaml"


PROFILES: tuple[Profile, ...] = (
    Profile(
        "cia402",
        "CiA 402 (IEC 61800-7-201)",
        "drive power state machine, transitions 0-16 by controlword",
    ),
    Profile(
        "packml",
        "PackML (ISA-TR88.00.02, OPC 30050)",
        "packaging unit: operator commands, state-complete events",
    ),
    Profile(
        "plcopen-axis",
        "PLCopen Motion Control Part 1",
        "single axis: function-block events, error from any state",
    ),
    Profile(
        "motor",
        "Ha, Yoo and Lee (2016)",
        "the paper's Motor: Blocked, Moving, Returning",
    ),
)

_DEVICE_LINE = re.compile(r"^device:[^\n]*$", re.MULTILINE)


def find(name: str) -> Profile | None:
    """The profile called ``name`` (case and ``_``/``-`` do not matter), or ``None``."""
    key = name.strip().lower().replace("_", "-")
    return next((p for p in PROFILES if p.name == key), None)


def profile_text(profile: Profile) -> str:
    """The shipped YAML file's text."""
    return (
        resources.files("statectl")
        .joinpath("data", "profiles", profile.file)
        .read_text(encoding="utf-8")
    )


def profile_tables(profile: Profile) -> DeviceTables:
    """The profile's tables; a shipped file that does not load is a packaging bug."""
    tables, diags = read_yaml(profile_text(profile), f"<profile {profile.name}>")
    if tables is None or any(d.severity is Severity.ERROR for d in diags):
        raise DiagnosticError(diags)
    return tables


def new_device(profile: Profile, device: str, fmt: Format) -> dict[str, str | bytes]:
    """The files of a new device ``device`` started from ``profile`` (rule 3).

    Returns file name -> content: ``NAME.yaml``, ``NAME.md``, ``NAME.xlsx``, or the
    CSV pair (and ``NAME.data.csv`` when the profile has data). Raises
    :class:`DiagnosticError` when the name cannot be written in that format.
    """
    tables = replace(profile_tables(profile), device=device)
    if fmt is Format.YAML:
        text = _DEVICE_LINE.sub(lambda _m: "device: " + _scalar(device), profile_text(profile), 1)
        back, diags = read_yaml(text, f"{device}.yaml")
        if back is None or strip_locations(back) != strip_locations(tables):
            raise DiagnosticError(
                [
                    *[d for d in diags if d.severity is Severity.ERROR],
                    Diagnostic(
                        "T104",
                        Severity.ERROR,
                        Location(f"{device}.yaml"),
                        f"device name {device!r} cannot be written as YAML",
                        "use letters, digits, spaces, '-' and '_'",
                    ),
                ]
            )
        return {f"{device}.yaml": text}
    if fmt is Format.CSV:
        states, events, data, recovery = dump_csv(tables)
        files: dict[str, str | bytes] = {
            f"{device}.states.csv": states,
            f"{device}.events.csv": events,
        }
        if data is not None:
            files[f"{device}.data.csv"] = data
        if recovery is not None:
            files[f"{device}.recovery.csv"] = recovery
        return files
    return {f"{device}.{fmt.value}": dump(tables, fmt)}


def _scalar(text: str) -> str:
    """``text`` as a YAML scalar on one line (quoted when plain YAML would change it)."""
    plain = re.fullmatch(r"[A-Za-z][A-Za-z0-9 _.-]*", text) and text == text.strip()
    if plain and text.lower() not in ("yes", "no", "on", "off", "true", "false", "null"):
        return text
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'
