"""Text into diagram sources (statectl render): each syntax's label, one function each.

Rule 0 (all of :func:`comment`): whitespace runs (newlines included) fold to one
space, except in DOT where a newline is a line break (``\\n``); then every character
left that is not printable (NUL, controls, bidi controls such as U+202E and U+2066,
separators) is shown as its escape (:func:`statectl.kernel.text.shown`), so a label can
neither break the source's syntax nor reorder how the drawing reads; a label longer
than :data:`LABEL_LIMIT` characters is cut there and says how long it was.

1. :func:`mermaid` -- a quoted Mermaid label, transition label or note: the characters
   Mermaid parses (``" # ; : < > { } %``) become its numeric entity codes (``#34;``).
2. :func:`dot` -- a DOT double-quoted string: ``\\`` and ``"`` escaped, newlines as
   ``\\n``; the SVG is Graphviz's rendering of it.
3. :func:`plantuml` -- a PlantUML quoted label: PlantUML has no escape for ``"``
   inside one, so it becomes ``'``.
4. :func:`markdown_cell` -- one Markdown table cell: ``\\`` and ``|`` escaped, and a
   ``<`` that would open raw HTML (``<script>``) written as ``&lt;``.
"""

from __future__ import annotations

import re

from statectl.kernel.text import shown

__all__ = ["LABEL_LIMIT", "comment", "dot", "markdown_cell", "mermaid", "plantuml"]

_MERMAID = {c: f"#{ord(c)};" for c in '"#;:<>{}%'}
#: A ``<`` that Markdown would open raw HTML with (a tag, a comment, a declaration).
_HTML_OPEN = re.compile(r"<(?=[A-Za-z/!?])")


#: Longest label drawn whole; a longer one is cut and says its length (Graphviz refuses
#: quoted strings over 16,384 characters, Mermaid texts over 50,000; nobody reads them).
LABEL_LIMIT = 1000


def _cut(text: str) -> str:
    if len(text) <= LABEL_LIMIT:
        return text
    return f"{text[:LABEL_LIMIT]}... ({len(text):,} characters)"


def _folded(text: str) -> str:
    return shown(_cut(" ".join(text.split())))


def comment(text: str) -> str:
    """``text`` as one line of a diagram source's comment (Mermaid ``%%``): rule 0 only."""
    return _folded(text)


def mermaid(text: str) -> str:
    """``text`` safe in a Mermaid label (rule 1)."""
    return "".join(_MERMAID.get(c, c) for c in _folded(text))


def dot(text: str) -> str:
    """``text`` as a DOT double-quoted string, quotes included (rule 2)."""
    lines = _cut(text.replace("\r\n", "\n").replace("\r", "\n")).split("\n")
    body = "\n".join(shown(line) for line in lines)
    body = body.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
    return f'"{body}"'


def plantuml(text: str) -> str:
    """``text`` safe in a PlantUML quoted label (rule 3)."""
    return _folded(text.replace('"', "'"))


def markdown_cell(text: str) -> str:
    """``text`` safe in one Markdown table cell (rule 4)."""
    cell = _folded(text).replace("\\", "\\\\").replace("|", "\\|")
    return _HTML_OPEN.sub("&lt;", cell)
