"""SVG through Graphviz: the DOT writer's output run through ``dot -Tsvg``.

Rules:
1. The layout is Graphviz's; this module only finds ``dot`` on ``PATH`` and runs it.
2. A missing ``dot`` or a failing run is a :class:`~statectl.kernel.errors.StatectlError` that
   says what to install or what ``dot`` printed, never a traceback from ``subprocess``.
"""

from __future__ import annotations

import shutil
import subprocess

from statectl.kernel.errors import StatectlError
from statectl.out.render import dot
from statectl.out.render.diagram import Diagram

__all__ = ["MISSING_DOT", "dot_to_svg", "write"]

MISSING_DOT = (
    "Graphviz 'dot' not found; install it with `apt-get install graphviz` (Debian/Ubuntu) "
    "or `brew install graphviz`"
)


def dot_to_svg(source: str) -> str:
    """Run ``dot -Tsvg`` on DOT ``source`` and return the SVG text."""
    exe = shutil.which("dot")
    if exe is None:
        raise StatectlError(MISSING_DOT)
    try:
        done = subprocess.run(
            [exe, "-Tsvg"], input=source, capture_output=True, text=True, check=False
        )
    except OSError as exc:
        raise StatectlError(f"could not run Graphviz 'dot' ({exe}): {exc}") from exc
    if done.returncode != 0:
        raise StatectlError(
            f"Graphviz 'dot' failed with exit code {done.returncode}: {done.stderr.strip()}"
        )
    return done.stdout


def write(d: Diagram) -> str:
    """The diagram as SVG, laid out by Graphviz."""
    return dot_to_svg(dot.write(d))
