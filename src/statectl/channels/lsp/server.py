"""``statectl lsp``: the language server, on pygls 2 (stdin/stdout).

Rules:
1. Thin: each LSP request is one call into :mod:`~statectl.channels.lsp.navigate`,
   :mod:`~statectl.channels.lsp.complete` or :mod:`~statectl.channels.lsp.fixes`
   on a :class:`~statectl.channels.lsp.documents.Document` read from the editor's
   text, and a conversion of its answer to LSP types.
2. Diagnostics are published on open, on every change and on save, for the file
   itself, with the code, severity, message and hint of the command line (the
   message reads as ``statectl check`` prints it, ``message (hint)``; the hint
   is also in ``data``). Each is placed on its line, narrowed to the last name
   the message quotes that the line holds as a word (what was not found, in
   "X has no Y 'Z'"), else to the line's text.
3. A file that is not a device, cell or run config still gets the device
   loader's answer, as ``statectl check`` would give it; nothing here raises
   for bad input.
"""

from __future__ import annotations

import os
import re
from typing import Any

from lsprotocol import types as lsp
from pygls.exceptions import JsonRpcInvalidParams
from pygls.lsp.server import LanguageServer
from pygls.uris import from_fs_path, to_fs_path

from statectl.channels.lsp.complete import complete
from statectl.channels.lsp.documents import Document, Project, analyse, diagnose
from statectl.channels.lsp.fixes import Change, fixes
from statectl.channels.lsp.grid import Span
from statectl.channels.lsp.index import device_key
from statectl.channels.lsp.navigate import definition, hover, rename
from statectl.kernel.errors import Diagnostic, Severity

__all__ = ["make_server", "serve"]

SEVERITY = {
    Severity.ERROR: lsp.DiagnosticSeverity.Error,
    Severity.WARNING: lsp.DiagnosticSeverity.Warning,
    Severity.INFO: lsp.DiagnosticSeverity.Information,
}
KINDS = {
    "state": lsp.CompletionItemKind.EnumMember,
    "event": lsp.CompletionItemKind.Event,
    "device": lsp.CompletionItemKind.Module,
    "API": lsp.CompletionItemKind.Method,
    "section": lsp.CompletionItemKind.Module,
}
QUOTED = re.compile(r"'([^']+)'")


class StatectlServer(LanguageServer):
    """pygls' server with the open files as a :class:`Project`."""

    def __init__(self) -> None:
        from statectl import __version__

        super().__init__(
            "statectl", __version__, text_document_sync_kind=lsp.TextDocumentSyncKind.Full
        )
        self.project = Project()

    def doc(self, uri: str) -> Document:
        path = _path(uri)
        text = self.workspace.get_text_document(uri).source
        self.project.texts[path] = text
        return self.project.document(path) or analyse(path, text)

    def publish(self, uri: str) -> None:
        """Rule 2, for the file and, in a CSV pair, the pair's other open files (a state
        renamed in one is a problem in the other)."""
        doc = self.doc(uri)
        docs = [doc]
        if doc.grid.format == "csv":
            pair = self.project.device_documents(device_key(doc.path))
            docs += [d for d in pair if d.path != doc.path and d.path in self.project.texts]
        for each in docs:
            found = [_diagnostic(d, each.lines) for d in diagnose(each, self.project.texts)]
            self.text_document_publish_diagnostics(
                lsp.PublishDiagnosticsParams(uri=_uri(each.path), diagnostics=found)
            )


def _path(uri: str) -> str:
    return os.path.abspath(to_fs_path(uri) or uri)


def _uri(path: str) -> str:
    return from_fs_path(path) or path


def _range(span: Span) -> lsp.Range:
    return lsp.Range(lsp.Position(span.line, span.start), lsp.Position(span.line, span.end))


def _diagnostic(d: Diagnostic, lines: list[str]) -> lsp.Diagnostic:
    """Rule 2."""
    line = max((d.where.line or 1) - 1, 0)
    text = lines[line] if line < len(lines) else ""
    start = len(text) - len(text.lstrip())
    end = len(text.rstrip())
    for name in reversed(QUOTED.findall(d.message)):  # the last is what was not found
        m = re.search(rf"(?<!\w){re.escape(name)}(?!\w)", text)
        if m:
            start, end = m.span()
            break
    message = f"{d.message} ({d.hint})" if d.hint else d.message
    return lsp.Diagnostic(
        range=_range(Span(line, start, max(end, start))),
        message=message,
        severity=SEVERITY[d.severity],
        code=d.code,
        source="statectl",
        data={"message": d.message, "hint": d.hint},
    )


def _edits(changes: list[Change]) -> list[lsp.TextEdit]:
    return [
        lsp.TextEdit(lsp.Range(lsp.Position(a, b), lsp.Position(c, e)), text)
        for a, b, c, e, text in changes
    ]


def make_server() -> StatectlServer:
    """The server with every feature registered (rule 1)."""
    server = StatectlServer()

    @server.feature(lsp.INITIALIZED)
    def initialized(ls: StatectlServer, params: lsp.InitializedParams) -> None:
        folders = [_path(f.uri) for f in ls.workspace.folders.values()]
        root = ls.workspace.root_path
        ls.project.roots = tuple(dict.fromkeys([*folders, *([root] if root else [])]))

    @server.feature(lsp.TEXT_DOCUMENT_DID_OPEN)
    def did_open(ls: StatectlServer, params: lsp.DidOpenTextDocumentParams) -> None:
        ls.publish(params.text_document.uri)

    @server.feature(lsp.TEXT_DOCUMENT_DID_CHANGE)
    def did_change(ls: StatectlServer, params: lsp.DidChangeTextDocumentParams) -> None:
        ls.publish(params.text_document.uri)

    @server.feature(lsp.TEXT_DOCUMENT_DID_SAVE)
    def did_save(ls: StatectlServer, params: lsp.DidSaveTextDocumentParams) -> None:
        ls.publish(params.text_document.uri)

    @server.feature(lsp.TEXT_DOCUMENT_DID_CLOSE)
    def did_close(ls: StatectlServer, params: lsp.DidCloseTextDocumentParams) -> None:
        ls.project.texts.pop(_path(params.text_document.uri), None)

    _register_requests(server)
    return server


def _register_requests(server: StatectlServer) -> None:
    @server.feature(lsp.TEXT_DOCUMENT_HOVER)
    def on_hover(ls: StatectlServer, params: lsp.HoverParams) -> lsp.Hover | None:
        doc, at = ls.doc(params.text_document.uri), params.position
        text = hover(ls.project, doc, at.line, at.character)
        if text is None:
            return None
        return lsp.Hover(lsp.MarkupContent(lsp.MarkupKind.Markdown, text))

    @server.feature(lsp.TEXT_DOCUMENT_DEFINITION)
    def on_definition(ls: StatectlServer, params: lsp.DefinitionParams) -> lsp.Location | None:
        doc, at = ls.doc(params.text_document.uri), params.position
        found = definition(ls.project, doc, at.line, at.character)
        if found is None:
            return None
        path, symbol = found
        return lsp.Location(_uri(path), _range(symbol.span))

    @server.feature(
        lsp.TEXT_DOCUMENT_COMPLETION,
        lsp.CompletionOptions(trigger_characters=[":", ",", "|", "'", " "]),
    )
    def on_completion(ls: StatectlServer, params: lsp.CompletionParams) -> lsp.CompletionList:
        doc, at = ls.doc(params.text_document.uri), params.position
        items = [
            lsp.CompletionItem(
                label, kind=KINDS.get(what, lsp.CompletionItemKind.Field), detail=what
            )
            for label, what in complete(ls.project, doc, at.line, at.character)
        ]
        return lsp.CompletionList(is_incomplete=False, items=items)

    @server.feature(lsp.TEXT_DOCUMENT_RENAME)
    def on_rename(ls: StatectlServer, params: lsp.RenameParams) -> lsp.WorkspaceEdit:
        doc, at = ls.doc(params.text_document.uri), params.position
        found = rename(ls.project, doc, at.line, at.character, params.new_name)
        if isinstance(found, str):
            raise JsonRpcInvalidParams(found)
        changes = {
            _uri(path): [lsp.TextEdit(_range(s), params.new_name) for s in spans]
            for path, spans in found.items()
        }
        return lsp.WorkspaceEdit(changes=changes)

    @server.feature(
        lsp.TEXT_DOCUMENT_CODE_ACTION,
        lsp.CodeActionOptions(code_action_kinds=[lsp.CodeActionKind.QuickFix]),
    )
    def on_code_action(ls: StatectlServer, params: lsp.CodeActionParams) -> list[lsp.CodeAction]:
        uri = params.text_document.uri
        doc = ls.doc(uri)
        actions = []
        for d in params.context.diagnostics:
            data: Any = d.data if isinstance(d.data, dict) else {}
            message, hint = str(data.get("message", d.message)), str(data.get("hint", ""))
            start, end = d.range.start, d.range.end
            span = (
                Span(start.line, start.character, end.character) if start.line == end.line else None
            )
            for title, changes in fixes(doc, str(d.code or ""), message, start.line, hint, span):
                actions.append(
                    lsp.CodeAction(
                        title,
                        kind=lsp.CodeActionKind.QuickFix,
                        diagnostics=[d],
                        edit=lsp.WorkspaceEdit(changes={uri: _edits(changes)}),
                    )
                )
        return actions


def serve() -> None:
    """Serve on stdin/stdout until the editor says exit."""
    make_server().start_io()
