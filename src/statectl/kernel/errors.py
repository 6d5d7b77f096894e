"""One error root and the diagnostics that loading and checking report.

Rules:
1. Loading and checking never stop at the first problem: they collect
   :class:`Diagnostic` values, each with a stable code, where it was found,
   what was found and what to do.
2. A caller that needs a usable result from a load with errors gets a
   :class:`DiagnosticError` carrying every diagnostic, never a traceback.
3. Exceptions raised at run time (misuse of the API, an event the current state
   rejects under the ``error`` policy) derive from :class:`StatectlError`.
"""

from __future__ import annotations

import difflib
import enum
import importlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from types import ModuleType

__all__ = [
    "Diagnostic",
    "DiagnosticError",
    "Location",
    "MissingExtra",
    "Severity",
    "StatectlError",
    "UnhandledEventError",
    "did_you_mean",
    "has_errors",
    "require",
]


class StatectlError(Exception):
    """Root of every error statectl raises on purpose."""


class Severity(enum.Enum):
    ERROR = "error"
    WARNING = "warning"
    INFO = "info"


@dataclass(frozen=True, slots=True)
class Location:
    """Where an element came from: a file and a line, or a sheet and a row.

    ``line`` is 1-based in text files (YAML, CSV, SCXML); ``sheet``/``row``
    name a spreadsheet cell row (1-based, as the spreadsheet shows it).
    """

    file: str = "<memory>"
    line: int | None = None
    sheet: str | None = None
    column: str | None = None

    def __str__(self) -> str:
        text = self.file
        if self.sheet is not None:
            text += f"[{self.sheet}]"
        if self.line is not None:
            text += f":{self.line}"
        return text


@dataclass(frozen=True, slots=True)
class Diagnostic:
    """One problem: ``file:line: CODE severity: message (hint)``."""

    code: str
    severity: Severity
    where: Location
    message: str
    hint: str = ""

    def __str__(self) -> str:
        text = f"{self.where}: {self.code} {self.severity.value}: {self.message}"
        if self.hint:
            text += f" ({self.hint})"
        return text

    def to_json(self) -> dict[str, object]:
        return {
            "code": self.code,
            "severity": self.severity.value,
            "file": self.where.file,
            "line": self.where.line,
            "sheet": self.where.sheet,
            "message": self.message,
            "hint": self.hint,
        }


def did_you_mean(word: str, choices: Sequence[str]) -> str:
    """``"did you mean 'X'? "`` for the choice closest to a mistyped ``word``, else ``""``.

    The one suggestion every lookup by name makes (columns, kinds, profiles in ``check``;
    events, devices, nodes, drivers in ``run``, ``node`` and the dashboard).
    """
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f"did you mean {close[0]!r}? " if close else ""


def has_errors(diagnostics: Iterable[Diagnostic]) -> bool:
    return any(d.severity is Severity.ERROR for d in diagnostics)


class DiagnosticError(StatectlError):
    """A load or build that produced errors; carries all of them."""

    def __init__(self, diagnostics: Iterable[Diagnostic]) -> None:
        self.diagnostics: tuple[Diagnostic, ...] = tuple(diagnostics)
        super().__init__("\n".join(str(d) for d in self.diagnostics))


class UnhandledEventError(StatectlError):
    """An event the active configuration neither handles nor ignores (policy ``error``)."""


class MissingExtra(StatectlError):
    """A feature whose optional extra is not installed: a usage error (exit 2), in one line.

    The one wording of "install this" for every channel: what needed it, the module that
    is missing and the extra (pyproject.toml) that brings it.
    """

    def __init__(self, what: str, module: str, extra: str) -> None:
        self.what, self.module, self.extra = what, module, extra
        super().__init__(
            f"{what} needs {module}, which is not installed: pip install 'statectl[{extra}]' "
            "(or 'statectl[all]' for every extra)"
        )


def require(module: str, extra: str, what: str) -> ModuleType:
    """Import ``module`` for ``what``, or raise :class:`MissingExtra` naming ``extra``."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtra(what, module, extra) from None
