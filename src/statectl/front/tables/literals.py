"""Data literals in cells: YAML literals read, normalised to hashable values, formatted
back, and recovery payloads kept as plain lists and dicts (schema rules 5 and 5a). Its
own module because every format reads and writes data through it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import yaml

from statectl.front.tables.rows import Bad, diag
from statectl.front.tables.safeyaml import YamlRefused, load_value
from statectl.kernel.errors import Diagnostic, Location

# --- data literals ----------------------------------------------------------------------


#: The largest whole number a data value may be: a hex literal has no digit limit, and
#: Python cannot write a number of more than 4300 decimal digits back (about 14,000 bits).
MAX_INT_BITS = 4096


def normalize_value(value: object) -> object | Bad:
    """A YAML literal as the tables keep it (lists become tuples), or what is wrong."""
    if isinstance(value, int) and value.bit_length() > MAX_INT_BITS:  # 0x999..., no repr
        return Bad(f"a whole number of more than {MAX_INT_BITS} bits")
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, list | tuple):
        items = [normalize_value(v) for v in value]
        for item in items:
            if isinstance(item, Bad):
                return item
        return tuple(items)
    if isinstance(value, dict):
        return Bad("a mapping")
    return Bad(f"a {type(value).__name__}")


def normalize_payload(value: object) -> object | Bad:
    """A recovery row's data as the tables keep it (plain lists and dicts), or what is wrong."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, list | tuple):
        items = [normalize_payload(v) for v in value]
        bad = next((i for i in items if isinstance(i, Bad)), None)
        return bad if bad is not None else items
    if isinstance(value, dict):
        out: dict[str, object] = {}
        for key, item in value.items():
            if not isinstance(key, str):
                return Bad(f"a mapping key {key!r} that is not text")
            got = normalize_payload(item)
            if isinstance(got, Bad):
                return got
            out[key] = got
        return out
    return Bad(f"a {type(value).__name__}")


def _plain(value: object) -> object:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def to_plain(value: object) -> object:
    """The value as YAML writes it (tuples become lists)."""
    return _plain(value)


def format_literal(value: object) -> str:
    """One value as a YAML flow literal, for a CSV, XLSX or Markdown cell."""
    text = yaml.safe_dump(
        [_plain(value)],
        default_flow_style=True,
        allow_unicode=True,
        width=math.inf,
        sort_keys=False,
    ).strip()
    return text[1:-1].strip()


#: What a data value may be, said where one is not.
LITERAL_HINT = (
    "write null, true or false, a number, text (quoted if it holds ':' '#' or brackets) "
    "or a list such as [1, 2]"
)
_REPORTED = Bad("malformed literal")  # a cell parse_literal reported already


def reported() -> Bad:
    """The value of a data cell whose problem its reader has already reported, so that
    :func:`make_data` does not report it again."""
    return _REPORTED


def parse_literal(
    text: str, where: Location, diags: list[Diagnostic], name: str = ""
) -> object | Bad:
    """Read a YAML literal from a cell (of data ``name``); an empty cell is null."""
    try:
        value = load_value(text)
    except YamlRefused as exc:
        code = exc.code if exc.code in ("T115", "T116") else "T108"
        shown = text if len(text) <= 60 else text[:57] + "..."
        of = f" of {name!r}" if name else ""
        message = f"data value{of} {shown!r} is not a YAML literal: {exc.message}"
        diags.append(diag(code, where, message, exc.hint or LITERAL_HINT))
        return Bad(_REPORTED.found, code)
    return normalize_value(value)


def parse_payload(text: str) -> object | Bad:
    """Read a recovery row's data cell (a YAML flow value); an empty cell is null."""
    try:
        value = load_value(text)
    except YamlRefused as exc:
        return Bad(exc.message, exc.code if exc.code in ("T115", "T116") else "T108")
    return normalize_payload(value)


def make_data(
    entries: Sequence[tuple[str, object, Location]], diags: list[Diagnostic]
) -> tuple[tuple[str, object], ...]:
    """Check data entries: identifier names, each once, literal values."""
    data: dict[str, object] = {}
    for name, value, where in entries:
        if not name.isidentifier() or name.startswith("_"):
            diags.append(
                diag(
                    "T112",
                    where,
                    f"data name {name!r} is not a usable name",
                    "use a name like speed or target_position (letters, digits, _; "
                    "not starting with _ or a digit)",
                )
            )
            continue
        if name in data:
            diags.append(diag("T112", where, f"data name {name!r} is given twice"))
            continue
        if isinstance(value, Bad) and value.found == _REPORTED.found:
            continue  # parse_literal has said why
        if isinstance(value, Bad):
            diags.append(
                diag(
                    value.code,
                    where,
                    f"data {name!r} must be a literal (got {value.found})",
                    "use null, true/false, a number, a string or a list of them",
                )
            )
            continue
        data[name] = value
    return tuple(data.items())
