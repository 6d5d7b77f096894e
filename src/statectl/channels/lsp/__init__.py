"""The language server: statectl's diagnostics, names and fixes in an editor (docs/editors.md).

``statectl lsp`` serves it on stdin/stdout (:mod:`~statectl.channels.lsp.server`, the only
module that needs pygls, the ``lsp`` extra). The rest reads text and answers questions:
:mod:`~statectl.channels.lsp.grid` (cells and where they are),
:mod:`~statectl.channels.lsp.index` (where each state and event is named),
:mod:`~statectl.channels.lsp.documents` (a file's kind and diagnostics, the open files),
:mod:`~statectl.channels.lsp.navigate` (hover, definition, rename),
:mod:`~statectl.channels.lsp.complete` and :mod:`~statectl.channels.lsp.fixes` (code actions).
"""
