"""Text into generated Python (statectl testgen's modules): four places, one function each.

1. :func:`string` -- a string literal: double quotes where the text allows (as ruff
   formats), else ``repr``, which escapes quotes, backslashes and every non-printable
   character, so the literal evaluates to the very text.
2. :func:`comment` -- the text of a ``#`` comment: non-printable characters (newlines
   first of all: they would end the comment and start code) become escapes; a comment
   ends at the line's end whatever it holds, a trailing backslash included.
3. :func:`docstring` -- text inside a ``\"\"\"`` docstring (or any triple-quoted, non-raw
   string): backslashes are doubled, non-printable characters become escapes, and a
   double quote that another follows or that ends the text is escaped, so no run of
   three quotes can close the string and the text ends on no bare quote.
4. :func:`identifier` -- a part of a Python identifier or file name (a test name, a
   module file) and :func:`class_name`: ASCII letters, digits and ``_`` only, bounded
   where a caller asks (a 1 MB name must not become a 1 MB file name).
"""

from __future__ import annotations

import re

from statectl.kernel.text import escape_char, shown

__all__ = ["NAME_LIMIT", "class_name", "comment", "docstring", "identifier", "string"]

_NOT_WORD = re.compile(r"[^0-9a-z]+")

#: Longest identifier part made from a name for a file or a module-level name.
NAME_LIMIT = 64


def string(text: str) -> str:
    """``text`` as a Python string literal (rule 1)."""
    if '"' not in text and "\\" not in text and text.isprintable():
        return f'"{text}"'
    return repr(text)


def comment(text: str) -> str:
    """``text`` safe after ``#`` on one line (rule 2)."""
    return shown(text)


def docstring(text: str) -> str:
    """``text`` safe inside a non-raw triple-quoted string (rule 3)."""
    if text.isprintable() and "\\" not in text and '"' not in text:
        return text
    out: list[str] = []
    last = len(text) - 1
    for i, c in enumerate(text):
        if c == "\\":
            out.append("\\\\")
        elif c == '"' and (i == last or text[i + 1] == '"'):
            out.append('\\"')
        elif not c.isprintable():
            out.append(escape_char(c))
        else:
            out.append(c)
    return "".join(out)


def identifier(text: str, default: str = "x", limit: int | None = None) -> str:
    """``text`` as an identifier part: ``Movement completion`` -> ``movement_completion`` (rule 4).

    Runs of anything but ASCII letters and digits become one ``_``; an empty result is
    ``default``; ``limit`` caps the length (a file name, a function name). The part may
    start with a digit: callers put it after a prefix (``test_``, a class name)."""
    slug = _NOT_WORD.sub("_", text.lower()).strip("_")
    if limit is not None:
        slug = slug[:limit].rstrip("_")
    return slug or default


def class_name(text: str, suffix: str, limit: int = 64) -> str:
    """``pick place`` -> ``PickPlace`` + suffix: a class name from a name (rule 4)."""
    words = identifier(text, "device", limit).split("_")
    name = "".join(w[:1].upper() + w[1:] for w in words)
    return (name if name[0].isalpha() else "D" + name) + suffix
