"""Event data at run time: fields checked as an event arrives, assignments.

Rules:
1. An event that declares its data (the Event Definition table's ``data``
   column) is refused when it is posted with data that is not a mapping, with a
   field it does not declare (a typo: ``presure``), or with a value of the wrong
   type, by :class:`EventDataError` naming the declared fields. Events that
   declare nothing take any data, as before.
2. Assignments (the ``assign`` column, :class:`~statectl.kernel.model.Assign` on a
   transition) are evaluated over the data as it was before the step, with
   ``previous``, ``In()`` and ``_event``, all of them before anything is
   committed: one that raises refuses the whole step (no state change, no
   device call) with :class:`AssignError` naming the row's file:line; otherwise
   the data takes the new values, then the step is performed.
3. A guard that raised (:class:`~statectl.kernel.semantics.eventview.GuardFailure`) is
   recorded as ``EventRejected`` with reason ``guard error`` whatever the policy,
   and raised as :class:`~statectl.kernel.semantics.eventview.GuardError` (the engine's
   refusal, runtime/engine.py rule 3).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from statectl.kernel.errors import StatectlError, UnhandledEventError
from statectl.kernel.expr import Expression, compile_expression
from statectl.kernel.model import Assign, Chart, field_accepts
from statectl.kernel.semantics import Step
from statectl.kernel.semantics.eventview import EventView

if TYPE_CHECKING:
    from statectl.run.runtime.subject import Subject

__all__ = [
    "AssignError",
    "EventDataError",
    "apply_assignments",
    "assignments_of",
    "check_event_data",
    "check_posted",
    "declared_fields",
]


class EventDataError(StatectlError):
    """Data posted with an event does not match the fields the event declares."""


class AssignError(UnhandledEventError):
    """An assignment failed at run time: the step was refused, with the row's file:line."""


def declared_fields(chart: Chart) -> dict[str, dict[str, str]] | None:
    """Event -> {field: type} for the events that declare data; ``None`` when none does."""
    found = {e.name: dict(e.fields) for e in chart.events if e.fields}
    return found or None


def check_event_data(
    declared: Mapping[str, Mapping[str, str]], device: str, event: str, data: Any
) -> None:
    """Refuse ``data`` that does not fit what ``event`` declares (rule 1)."""
    fields = declared.get(event)
    if fields is None or data is None:
        return
    if not isinstance(data, Mapping):
        listed = _listed(fields)
        raise EventDataError(
            f"{device}: event {event!r} carries data fields ({listed}), "
            f"not a {type(data).__name__}: send a mapping such as {{{listed}}}"
        )
    for key, value in data.items():
        kind = fields.get(key)
        if kind is None:
            raise EventDataError(
                f"{device}: event {event!r} has no data field {key!r}; it declares: "
                f"{_listed(fields)}"
            )
        if not field_accepts(kind, value):
            raise EventDataError(
                f"{device}: event {event!r} field {key!r} must be {kind} "
                f"(got {type(value).__name__} {value!r})"
            )


def _listed(fields: Mapping[str, str]) -> str:
    """The declared fields as a message names them (made only for a refusal: every
    accepted event with data was paying for it)."""
    return ", ".join(f"{k}: {v}" for k, v in fields.items())


def check_posted(subject: Subject, event: str, data: Any) -> None:
    """Rule 1 for a host that accepts an event before the Subject sees it (a journal):
    refuse it before it is written anywhere."""
    declared = subject._declared
    if data is not None and declared is not None:
        check_event_data(declared, subject.name, event, data)


@functools.lru_cache(maxsize=1024)
def _compiled(action: Assign) -> Expression:
    expression, diags = compile_expression(action.expr or "None", action.origin, what="assign")
    if expression is None:  # the build checked it: only a chart made by hand gets here
        raise StatectlError("; ".join(str(d) for d in diags))
    return expression


def assignments_of(
    decision: Step, data: Mapping[str, Any], event: str, event_data: Any, device: str
) -> dict[str, Any] | None:
    """The new values of the data a step assigns (rule 2); ``None`` when it assigns none.

    Pure: a journal replays it to bring the data back on resume. Raises
    :class:`AssignError` naming the row when an assignment fails.
    """
    assigns = [a for a in decision.actions if isinstance(a, Assign)]
    if not assigns:
        return None
    before = decision.source
    env: dict[str, Any] = dict(data)
    env["previous"] = before.previous
    env["In"] = before.active.__contains__
    env["_event"] = EventView(event, event_data)
    updates: dict[str, Any] = {}
    for action in assigns:
        try:
            updates[action.location] = _compiled(action).evaluate(env)
        except Exception as exc:
            where = f"{action.origin}: " if action.origin.file or action.origin.line else ""
            raise AssignError(
                f"{where}{device}: assignment {action.location} = {action.expr} "
                f"of event {event!r} failed: {type(exc).__name__}: {exc}; "
                "the event was not taken"
            ) from None
    return updates


def apply_assignments(
    subject: Subject, decision: Step, event: str, event_data: Any
) -> dict[str, Any] | None:
    """The data after the step's assignments (rule 2); ``None`` when it has none."""
    return assignments_of(decision, subject.data, event, event_data, subject.name)
