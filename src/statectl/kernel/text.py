"""Names as people see them: every character a terminal or a page would act on, shown.

A name in a device file is the user's text and may hold anything YAML or CSV can carry:
a newline, a NUL, an ANSI escape, a right-to-left override (U+202E) that reorders what
follows it on screen. Printed raw, such a name forges a line of a journal listing or
hides part of itself. :func:`shown` is the one display escape: every character that
``str.isprintable`` refuses (controls, format characters such as the bidi controls,
line and paragraph separators, unassigned and surrogate code points) becomes a
Python-style escape (``\\n``, ``\\x00``, ``\\u202e``), and everything else, letters of
any script included, is kept. Printable text comes back unchanged (one C-level test).
"""

from __future__ import annotations

__all__ = ["escape_char", "shown"]

_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def escape_char(c: str) -> str:
    """One character as a Python-style escape: ``\\n``, ``\\x1b``, ``\\u202e``, ``\\U000e0001``."""
    if c in _NAMED:
        return _NAMED[c]
    n = ord(c)
    if n < 0x100:
        return f"\\x{n:02x}"
    return f"\\u{n:04x}" if n < 0x10000 else f"\\U{n:08x}"


def shown(text: str) -> str:
    """``text`` with every non-printable character written as its escape (module rule)."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else escape_char(c) for c in text)
