"""The exit statuses of ``statectl``, defined once: every command returns one of these names.

Rules:
1. ``OK`` (0): the command did what was asked (a check found no errors, files were written).
2. ``PROBLEMS`` (1): the input has problems (diagnostics), a check or a run failed, a file
   could not be read or written.
3. ``USAGE`` (2): the command line is wrong (argparse's own status for a usage error).
4. ``INTERRUPTED`` (130): Ctrl-C, 128 + SIGINT, what a shell reports for such a tool.
5. ``BROKEN_PIPE`` (141): our output's reader went away (``statectl journal show DB |
   head``), 128 + SIGPIPE, as if SIGPIPE had ended the command.

Beside ``errors.py`` and stdlib only, so a command in any ring (``out/testgen`` registers its
own) returns the same numbers; ``tests/test_cli_exits.py`` fails if a literal status is
written anywhere else in ``src/``.
"""

from __future__ import annotations

from typing import Final

__all__ = ["BROKEN_PIPE", "INTERRUPTED", "OK", "PROBLEMS", "USAGE"]

OK: Final = 0
PROBLEMS: Final = 1
USAGE: Final = 2
INTERRUPTED: Final = 130
BROKEN_PIPE: Final = 141
