"""``statectl schema`` and ``statectl lsp``: what an editor needs to help write the files.

``schema`` prints (or writes) the JSON Schema of a device file, cell file or run
config (:mod:`statectl.out.schema`); ``lsp`` serves the language server on stdin and
stdout (:mod:`statectl.channels.lsp`), which needs the ``lsp`` extra (pygls).
"""

from __future__ import annotations

import argparse
import importlib.util
from typing import Any, TextIO

from statectl.channels.cli.commands import _emit
from statectl.kernel.exits import OK, USAGE

__all__ = ["SCHEMA_KINDS", "register"]

#: The files ``statectl schema`` describes, :data:`statectl.out.schema.KINDS` written out
#: (a test holds them equal): importing the schemas, and every reader they are made
#: from, was the largest part of the start of every command, ``statectl check`` included.
SCHEMA_KINDS = ("device", "cell", "run-config")


def register(sub: Any) -> None:
    """Add ``schema`` and ``lsp`` to the parser's subcommands."""
    s = sub.add_parser("schema", help="the JSON Schema of device, cell or run-config YAML")
    s.add_argument("kind", choices=SCHEMA_KINDS, help="which file's schema")
    s.add_argument("--out", help="write to this file instead of standard output")
    s.set_defaults(func=cmd_schema)
    s = sub.add_parser(
        "lsp", help="serve the language server on stdin/stdout (for editors; docs/editors.md)"
    )
    s.add_argument("--stdio", action="store_true", help="accepted for editors that pass it")
    s.set_defaults(func=cmd_lsp)


def cmd_schema(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.out.schema import schema_text

    _emit(schema_text(args.kind), args.out, out, f"{args.kind}.schema.json")
    return OK


def cmd_lsp(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    if importlib.util.find_spec("pygls") is None:
        err.write("statectl lsp: the language server needs pygls: pip install 'statectl[lsp]'\n")
        return USAGE
    from statectl.channels.lsp.server import serve

    serve()
    return OK
