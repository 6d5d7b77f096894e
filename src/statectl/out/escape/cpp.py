"""Text into generated C++ (statectl codegen's headers): three places, one function each.

1. :func:`string` -- a narrow string literal: ``\\``, ``"`` and ``?`` (so no ``??/``
   trigraph forms, whatever the compiler's mode) are escaped; printable text, letters
   of any script included, is kept as UTF-8; every other character is written as the
   octal escapes of its UTF-8 bytes (three digits each, so no following character can
   extend one; surrogates pass through as their bytes).
2. :func:`comment` -- the text of a ``//`` or ``/* */`` comment: non-printable characters
   (a newline would end the comment and start code) and the backslash become ``\\xNN``
   / ``\\uNNNN`` escapes, so the text never ends with a ``\\`` (a line splice) nor
   holds one; a ``?`` after ``?``, a ``/`` after ``*`` and a ``*`` after ``/`` are
   escaped too, so no trigraph, ``*/`` or nested ``/*`` (``-Wcomment``) can form.
3. :func:`identifier_words` -- the words a C++ identifier is made of
   (:func:`statectl.out.codegen.cpp_names.identifiers` joins them, avoids keywords and
   makes them distinct): ASCII letters and digits only, everything else separates
   words, so no compiler mode (``-std=c++17 -Wpedantic``) sees an extended character.
"""

from __future__ import annotations

from statectl.kernel.text import escape_char

__all__ = ["comment", "identifier_words", "string"]

_STRING = {"\\": "\\\\", '"': '\\"', "?": "\\?"}


def string(text: str) -> str:
    """``text`` as a C++ narrow string literal, quotes included (rule 1)."""
    out: list[str] = []
    for c in text:
        if c in _STRING:
            out.append(_STRING[c])
        elif c.isprintable():
            out.append(c)
        else:
            out.extend(f"\\{b:03o}" for b in c.encode("utf-8", "surrogatepass"))
    return '"' + "".join(out) + '"'


def comment(text: str) -> str:
    """``text`` safe in a C++ comment, on one line (rule 2)."""
    if text.isprintable() and not any(s in text for s in ("\\", "??", "*/", "/*")):
        return text
    out: list[str] = []
    prev = ""
    for c in text:
        if (
            c == "\\"
            or not c.isprintable()
            or (c == "?" and prev == "?")
            or (c == "/" and prev == "*")
            or (c == "*" and prev == "/")
        ):
            out.append(escape_char(c))
        else:
            out.append(c)
        prev = c
    return "".join(out)


def identifier_words(name: str) -> list[str]:
    """The words of ``name`` a C++ identifier is made of (rule 3)."""
    return "".join(c if c.isascii() and c.isalnum() else " " for c in name).split()
