"""statectl: state control for industrial robot devices (Ha, Yoo and Lee's method)."""

from statectl.errors import Diagnostic, DiagnosticError, Location, Severity, StatectlError
from statectl.model import Chart, ControlKind, EventKind, State, StateKind, Transition

__version__ = "0.1.0"

__all__ = [
    "Chart",
    "ControlKind",
    "Diagnostic",
    "DiagnosticError",
    "EventKind",
    "Location",
    "Severity",
    "State",
    "StateKind",
    "StatectlError",
    "Transition",
    "__version__",
]
