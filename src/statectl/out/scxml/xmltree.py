"""The XML layer under the SCXML reader: expat with limits, a tree with lines, and back to text.

Rule 7 of :mod:`statectl.out.scxml.reader` live here: depth (S620), encodings (S621)
and entity declarations (S622) are refused before any SCXML meaning is read, so
the reader above only ever sees a bounded tree of elements with their lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from statectl.kernel.errors import Diagnostic, Location, Severity

SCXML_NS = "http://www.w3.org/2005/07/scxml"
#: Device-table facts SCXML has no word for (controls, notifications) live here.
STATECTL_NS = "urn:statectl:scxml"
_SEP = "}"

#: Deepest element nesting a document may have (S620; docs/limits.md).
MAX_XML_DEPTH = 100
#: Largest file a ``src`` attribute may name, in bytes (S607).
MAX_SRC_BYTES = 1 << 20


class _Refused(Exception):
    """Raised inside an expat handler to stop parsing with a diagnostic."""

    def __init__(self, code: str, line: int, message: str, hint: str) -> None:
        super().__init__(message)
        self.code, self.line, self.message, self.hint = code, line, message, hint


def read_src_text(path: Path) -> str:
    """A ``src`` file's text, read with a bound: at most :data:`MAX_SRC_BYTES`, UTF-8.

    Raises ``OSError`` if it cannot be read and ``ValueError`` if it is not a regular
    file (``/dev/zero`` is refused unread), too large or not UTF-8.
    """
    if not path.is_file():
        raise ValueError("is not a regular file")
    with path.open("rb") as fh:
        data = fh.read(MAX_SRC_BYTES + 1)
    if len(data) > MAX_SRC_BYTES:
        raise ValueError(f"larger than {MAX_SRC_BYTES} bytes (see docs/limits.md)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"not UTF-8 (byte {exc.start})") from None


def _number(text: str | None) -> int | None:
    """A small non-negative number written in ASCII digits, else ``None``."""
    if text is None or not text.isascii() or not text.isdigit() or len(text) > 9:
        return None
    return int(text)


@dataclass(slots=True)
class _Node:
    """A parsed element: namespace, local name, attributes, children, text, line."""

    ns: str
    tag: str
    attrs: dict[str, str]
    line: int
    children: list[_Node] = field(default_factory=list)
    text: list[str] = field(default_factory=list)  # text chunks, including between children

    def get(self, name: str) -> str | None:
        return self.attrs.get(name)

    @property
    def content_text(self) -> str:
        return "".join(self.text)

    def scxml_children(self, *tags: str) -> list[_Node]:
        return [c for c in self.children if c.ns == SCXML_NS and (not tags or c.tag in tags)]


def _parse_xml(text: str | bytes, file: str) -> tuple[_Node | None, list[Diagnostic]]:
    """Parse text (its prolog's encoding ignored) or bytes (decoded as the prolog says)."""
    parser = expat.ParserCreate(
        "UTF-8" if isinstance(text, str) else None, namespace_separator=_SEP
    )
    stack: list[_Node] = []
    root: list[_Node] = []

    def split(name: str) -> tuple[str, str]:
        if _SEP in name:
            ns, local = name.split(_SEP, 1)
            return ns, local
        return "", name

    def start(name: str, attrs: dict[str, str]) -> None:
        if len(stack) >= MAX_XML_DEPTH:
            raise _Refused(
                "S620",
                parser.CurrentLineNumber,
                f"elements nested deeper than {MAX_XML_DEPTH} levels",
                "flatten the document; see docs/limits.md",
            )
        ns, local = split(name)
        plain = {split(k)[1]: v for k, v in attrs.items()}
        node = _Node(ns, local, plain, parser.CurrentLineNumber)
        if stack:
            stack[-1].children.append(node)
        else:
            root.append(node)
        stack.append(node)

    def end(name: str) -> None:
        stack.pop()

    def chars(data: str) -> None:
        if stack:
            stack[-1].text.append(data)

    def entity(name: str, *_: object) -> None:
        raise _Refused(
            "S622",
            parser.CurrentLineNumber,
            f"the DTD declares the entity {name!r}: entity declarations are refused",
            "remove the <!ENTITY> declarations; SCXML needs no DTD",
        )

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.EntityDeclHandler = entity
    parser.UnparsedEntityDeclHandler = entity
    try:
        data = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text
        parser.Parse(data, True)
    except _Refused as exc:
        return None, [
            Diagnostic(exc.code, Severity.ERROR, Location(file, exc.line), exc.message, exc.hint)
        ]
    except (LookupError, UnicodeError, ValueError) as exc:  # the prolog's encoding
        return None, [
            Diagnostic(
                "S621",
                Severity.ERROR,
                Location(file, parser.CurrentLineNumber or 1),
                f"the document's encoding cannot be read: {exc}",
                'save the document as UTF-8 and declare encoding="UTF-8" (or nothing)',
            )
        ]
    except expat.ExpatError as exc:
        where = Location(file, exc.lineno)
        return None, [
            Diagnostic(
                "S601",
                Severity.ERROR,
                where,
                f"the document is not well-formed XML: {expat.errors.messages[exc.code]}",
                "fix the XML syntax at that line (unclosed tag, stray '<' or '&')",
            )
        ]
    return root[0], []


def serialise(node: _Node, parent_ns: str | None = None) -> str:
    """Write a parsed element back as XML text (for inline ``<content>``)."""
    from xml.sax.saxutils import escape, quoteattr

    attrs = "".join(f" {k}={quoteattr(v)}" for k, v in node.attrs.items())
    if node.ns != parent_ns and node.ns:
        attrs = f" xmlns={quoteattr(node.ns)}" + attrs
    inner = escape("".join(node.text)) + "".join(serialise(c, node.ns) for c in node.children)
    return f"<{node.tag}{attrs}>{inner}</{node.tag}>"
