"""Text into XML 1.0 (SCXML export): element text and attribute values.

1. :func:`text` escapes ``&``, ``<`` and ``>``; :func:`attribute` also quotes the value
   and writes tab, newline and carriage return as character references, so a parser
   gives back the very value (attribute normalisation would turn them into spaces).
2. XML 1.0 has no way at all to carry NUL, the other C0 controls, U+FFFE, U+FFFF and
   lone surrogates, not even as character references: a name holding one is refused
   with a :class:`~statectl.kernel.errors.StatectlError` naming the character, rather
   than written as a document no XML parser reads. Everything else, bidi controls
   included, is data and written as it is: the document is for machines, and reading
   it back must give the same names.
"""

from __future__ import annotations

import re
from xml.sax.saxutils import escape, quoteattr

from statectl.kernel.errors import StatectlError
from statectl.kernel.text import escape_char

__all__ = ["attribute", "text"]

_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff\ud800-\udfff]")


def _checked(value: str) -> str:
    bad = _NOT_XML.search(value)
    if bad is not None:
        shown = escape_char(bad.group())
        raise StatectlError(
            f"{value[:60]!r} holds {shown}, which XML 1.0 cannot carry: rename it "
            "to export SCXML (device tables, YAML or CSV, hold any name)"
        )
    return value


def text(value: str) -> str:
    """``value`` as XML element content (rules 1-2)."""
    return escape(_checked(value))


def attribute(value: str) -> str:
    """``value`` as a quoted XML attribute value, quotes included (rules 1-2)."""
    return quoteattr(_checked(value), {"\n": "&#10;", "\r": "&#13;", "\t": "&#9;"})
