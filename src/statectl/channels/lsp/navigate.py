"""Hover, go to definition and rename: a state or event, wherever it is named.

Rules:
1. The name under the cursor is a :class:`~statectl.channels.lsp.index.Symbol` of
   the document: a definition or a use (index rules 1-3); elsewhere there is no
   answer.
2. Its definition is the row that defines it in its device's file(s), which
   for a use in a cell is another file.
3. Hover shows that row's cells, then every place the name is used: in the
   device's files and in the cells that use the device.
4. Rename changes every naming of it: the definition, the device's uses and the
   cells' (a name with a comma, or an empty one, is refused: a list cell could
   not hold it). Only names, never text that merely looks the same (a
   description, a condition) are changed.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from statectl.channels.lsp.documents import Document, FileKind, Project
from statectl.channels.lsp.grid import Row, Span
from statectl.channels.lsp.index import Kind, Symbol

__all__ = ["definition", "hover", "namings", "rename", "symbol_at"]

#: The most uses a hover lists.
MAX_SHOWN = 12


def symbol_at(doc: Document, line: int, character: int) -> Symbol | None:
    """Rule 1."""
    return next((s for s in doc.symbols if s.span.holds(line, character)), None)


def _device_docs(project: Project, doc: Document, symbol: Symbol) -> list[Document]:
    """The files of the device ``symbol`` belongs to (the open document among them as is)."""
    docs = project.device_documents(symbol.file)
    return [doc if d.path == doc.path else d for d in docs]


def definition(
    project: Project, doc: Document, line: int, character: int
) -> tuple[str, Symbol] | None:
    """Rule 2: the file and naming that define the name under the cursor."""
    symbol = symbol_at(doc, line, character)
    if symbol is None:
        return None
    return _defining(_device_docs(project, doc, symbol), symbol)


def _defining(docs: Iterable[Document], symbol: Symbol) -> tuple[str, Symbol] | None:
    return next(
        (
            (d.path, s)
            for d in docs
            for s in d.symbols
            if s.definition and s.kind is symbol.kind and s.name == symbol.name
        ),
        None,
    )


def namings(project: Project, doc: Document, symbol: Symbol) -> list[tuple[Document, Symbol]]:
    """Every naming of ``symbol``'s state or event: its device's files, then the cells'."""
    docs = _device_docs(project, doc, symbol)
    cells = list(project.cells_using(symbol.file))
    if doc.kind is FileKind.CELL and all(c.path != doc.path for c in cells):
        cells.append(doc)
    cells = [doc if c.path == doc.path else c for c in cells]
    found = []
    for d in (*docs, *cells):
        for s in d.symbols:
            if s.kind is symbol.kind and s.name == symbol.name and s.file == symbol.file:
                found.append((d, s))
    return found


def rename(
    project: Project, doc: Document, line: int, character: int, new_name: str
) -> dict[str, list[Span]] | str:
    """Rule 4: the spans to replace by file, or why the rename is refused."""
    symbol = symbol_at(doc, line, character)
    if symbol is None:
        return "no state or event is named here"
    clean = new_name.strip()
    if not clean or "," in clean or clean != new_name or "\n" in clean:
        return f"{new_name!r} cannot name a {symbol.kind.value}: no commas, no outer spaces"
    edits: dict[str, list[Span]] = {}
    for d, s in namings(project, doc, symbol):
        if s.span not in edits.setdefault(d.path, []):
            edits[d.path].append(s.span)
    return edits


def hover(project: Project, doc: Document, line: int, character: int) -> str | None:
    """Rule 3, as Markdown."""
    symbol = symbol_at(doc, line, character)
    if symbol is None:
        return None
    docs = _device_docs(project, doc, symbol)
    found = _defining(docs, symbol)
    defining = found[1] if found is not None else None
    device = Path(found[0] if found is not None else symbol.file).name
    parts = [f"**{symbol.kind.value} `{symbol.name}`** of {device}"]
    if defining is None or defining.row is None:
        parts.append(f"_not defined in {device}_")
    elif symbol.kind is Kind.STATE:
        parts.append(_cells(defining.row, ("component", "api", "control", "description")))
        parts[0] += f", line {defining.span.line + 1}"
    else:
        rows = [s.row for d in docs for s in d.symbols if _is_event_row(s, symbol)]
        parts.append("\n".join(_transition(r) for r in rows if r is not None))
        parts.append(_cells(defining.row, ("condition", "kind", "api")))
        parts[0] += f", line {defining.span.line + 1}"
    uses = [(d, s) for d, s in namings(project, doc, symbol) if not s.definition]
    uses = [(d, s) for d, s in uses if not (s.row is not None and _is_event_row(s, symbol))]
    if uses:
        shown = [f"- {Path(d.path).name}:{s.span.line + 1} {_where(s)}" for d, s in uses]
        more = len(shown) - MAX_SHOWN
        parts.append(
            "Used at:\n"
            + "\n".join(shown[:MAX_SHOWN])
            + (f"\n- and {more} more" if more > 0 else "")
        )
    else:
        parts.append("_Not used anywhere else._")
    return "\n\n".join(p for p in parts if p)


def _is_event_row(s: Symbol, symbol: Symbol) -> bool:
    return (
        s.kind is Kind.EVENT
        and s.name == symbol.name
        and s.row is not None
        and s.row.table == "events"
        and s.row.cells.get("event") is not None
        and s.row.cells["event"].span == s.span
    )


def _cells(row: Row, columns: Iterable[str]) -> str:
    return "\n".join(f"- {c}: {row.text(c)}" for c in columns if row.text(c))


def _transition(row: Row) -> str:
    guard = f" [{row.text('guard')}]" if row.text("guard") else ""
    return f"- `{row.text('old')} + {row.text('event')}{guard} = {row.text('new')}`"


def _where(s: Symbol) -> str:
    """Which cell of which row names it: ``(old of 'Error')``, ``(links: enters)``."""
    row = s.row
    if row is None:
        return ""
    column = next(
        (c for c, cell in row.cells.items() if cell.span.line == s.span.line
         and cell.span.start <= s.span.start <= cell.span.end),
        "",
    )  # fmt: skip
    owner = row.text("state") if row.table == "states" else row.text("event")
    if row.table in ("states", "events") and owner:
        return f"({column} of {owner!r})"
    return f"({row.table}: {column})"
