"""The device setups of a cell's instances with their recovery rules.

Which files are cells is :func:`statectl.front.kinds.is_cell`.

Library code under the run command (:mod:`statectl.channels.cli.run`) and the tests:
it returns setups and the warnings that apply, and prints nothing."""

from __future__ import annotations

from collections.abc import Collection, Iterable

from statectl.cell.model import Cell
from statectl.kernel.errors import Diagnostic, DiagnosticError
from statectl.run.journal import (
    load_device,
)
from statectl.run.system import DeviceSetup

#: Recovery warnings matter only when there is a journal to recover from.
JOURNAL_ONLY_WARNINGS = frozenset({"J606", "J608"})


def relevant_warnings(warnings: Iterable[Diagnostic], journalled: bool) -> list[Diagnostic]:
    """The warnings a run should show: recovery warnings only when it is journalled."""
    return [d for d in warnings if journalled or d.code not in JOURNAL_ONLY_WARNINGS]


def load_setups(
    cell: Cell, *, journalled: bool = True, only: Collection[str] | None = None
) -> tuple[tuple[DeviceSetup, ...], list[Diagnostic]]:
    """One setup per device instance of ``cell``, and the warnings that apply to the run.

    Raises one :class:`DiagnosticError` for every device file whose rules do not
    load; recovery warnings are kept only for a ``journalled`` run, and only for the
    devices named in ``only`` when given (a node's own: the others run elsewhere).
    """
    setups: list[DeviceSetup] = []
    problems: list[Diagnostic] = []
    warnings: list[Diagnostic] = []
    for ref in cell.devices:
        try:
            dev = load_device(ref.path)
        except DiagnosticError as exc:
            problems.extend(exc.diagnostics)
            continue
        if only is None or ref.name in only:
            warnings.extend(relevant_warnings(dev.warnings, journalled))
        setups.append(DeviceSetup(ref.name, ref.chart, dev.rules, ref.path))
    if problems:
        raise DiagnosticError(problems)
    return tuple(setups), warnings


def cell_setups(cell: Cell, *, journalled: bool = True) -> tuple[DeviceSetup, ...]:
    """One setup per device instance of ``cell`` (see :func:`load_setups`; warnings dropped)."""
    return load_setups(cell, journalled=journalled)[0]
