"""Step 2 for the Event Definition table: identical rows merged (B204), one EventDef
per event with rows that disagree reported (B206), invoke names checked (B211). Split
from :mod:`statectl.front.builder.chart` because the event rows are checked on their own.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from statectl.front.builder.common import _d, _rows_text, _unique
from statectl.front.builder.eventdata import merge_conflicts
from statectl.front.tables.rows import EventRow
from statectl.kernel.errors import Diagnostic, Severity
from statectl.kernel.model import (
    EventDef,
)


def _merge_events(rows: Sequence[EventRow], diags: list[Diagnostic]) -> list[EventRow]:
    groups: dict[tuple[str, str, str, str], list[EventRow]] = {}
    for r in rows:
        groups.setdefault((r.event, r.old, r.new, r.guard), []).append(r)
    merged: list[EventRow] = []
    for (event, old, new, _), group in groups.items():
        first = group[0]
        if len(group) > 1:
            merge_conflicts(group, diags)
            diags.append(
                _d(
                    "B204",
                    Severity.INFO,
                    first.where,
                    f"{len(group)} identical rows for {old} + {event} = {new} merged into "
                    "one transition",
                    f"rows at {_rows_text([r.where for r in group])}",
                )
            )
            conditions = "; ".join(_unique([r.condition for r in group]))
            first = dataclasses.replace(
                first,
                condition=conditions,
                invoke=first.invoke or next((r.invoke for r in group if r.invoke), ""),
                fields=first.fields or next((r.fields for r in group if r.fields), ()),
            )
        merged.append(first)
    return merged


def _event_defs(rows: Sequence[EventRow], diags: list[Diagnostic]) -> tuple[EventDef, ...]:
    groups: dict[str, list[EventRow]] = {}
    for r in rows:
        groups.setdefault(r.event, []).append(r)
    defs: list[EventDef] = []
    for name, group in groups.items():
        first = group[0]
        for column in ("kind", "api"):
            same = getattr(first, column)
            if all(getattr(r, column) == same for r in group):  # the usual event: agreed
                continue
            values = list(dict.fromkeys(getattr(r, column) for r in group))
            if len(values) > 1:
                shown = [v.value if column == "kind" else repr(v) for v in values]
                diags.append(
                    _d(
                        "B206",
                        Severity.ERROR,
                        next(r.where for r in group if getattr(r, column) != values[0]),
                        f"rows for event {name!r} disagree on {column}: " + ", ".join(shown),
                        f"rows at {_rows_text([r.where for r in group])}; "
                        f"give every row of an event the same {column}",
                    )
                )
        defs.append(
            EventDef(
                name,
                first.kind,
                first.api or None,
                "; ".join(_unique([r.condition for r in group])),
                first.where,
                unasked=any(r.unasked for r in group),
                severity=max((r.severity for r in group if r.severity is not None), default=None),
            )
        )
    return tuple(defs)


def _check_invokes(rows: Sequence[EventRow], diags: list[Diagnostic]) -> None:
    named: dict[str, EventRow] = {}
    for r in rows:
        if r.invoke and not r.api:
            diags.append(
                _d(
                    "B211",
                    Severity.ERROR,
                    r.where,
                    f"event {r.event!r} names invoke {r.invoke!r} but no API",
                    "an invoke number belongs to an API: fill in the 'api' cell",
                )
            )
        elif r.invoke:
            seen = named.setdefault(r.api, r)
            if seen.invoke != r.invoke:
                diags.append(
                    _d(
                        "B211",
                        Severity.ERROR,
                        r.where,
                        f"API {r.api!r} is named invoke {seen.invoke!r} at {seen.where} "
                        f"and {r.invoke!r} here",
                        "give one invoke name per API",
                    )
                )
