"""Step 2 for event data: declared fields, how guards read them, and assignments.

Rules:
1. An event's declared fields (``data`` column) are those of the rows that
   declare any; rows of one event that declare different fields are B230.
2. A guard (or an assignment) reads event data as ``_event.data.NAME`` (or the
   same path subscripted, ``_event['data']['NAME']``); ``_event.name`` is the
   event's name. Any other path from ``_event`` (``_event.pressure``,
   ``_event['pressure']``) and the names ``event``, ``data`` and ``payload`` when
   no data item has that name are B231, with the spelling that works: they can
   never read the event's data, so they are refused, not left always false.
3. A field the event does not declare is B232 (the guard would fail at run
   time); reading fields of an event that declares none is B233 (a warning:
   declare them so the check and the runtime can hold the senders to them).
4. ``assign`` targets must be data items (B234), and the expressions are in the
   safe language over the data, ``previous``, ``In()`` and ``_event``
   (X301-X305, X303 for an unknown name). Each becomes an
   :class:`~statectl.kernel.model.Assign` on the row's transition, before its
   notification.
5. Rows merged as identical (B204) that differ in API or kind are B206, in their
   assignments B235: a merge would otherwise drop one silently.
"""

from __future__ import annotations

import ast
import functools
import itertools
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace

from statectl.front.builder.common import _compile, _d, _rows_text
from statectl.front.tables.rows import EventRow
from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.expr import Expression, check_names
from statectl.kernel.model import Action, Assign, field_accepts

__all__ = [
    "EVENT_WORDS",
    "assign_actions",
    "check_guard",
    "event_fields",
    "merge_conflicts",
]

#: Names people write for the event's data; refused with the working spelling (rule 2).
EVENT_WORDS = frozenset({"event", "data", "payload"})

Fields = tuple[tuple[str, str], ...]


def event_fields(rows: Sequence[EventRow], diags: list[Diagnostic]) -> dict[str, Fields]:
    """Event -> its declared fields (rule 1); B230 when rows declare different ones."""
    found: dict[str, EventRow] = {}
    for r in rows:
        if not r.fields:
            continue
        first = found.setdefault(r.event, r)
        if first.fields != r.fields:
            diags.append(
                _d(
                    "B230",
                    Severity.ERROR,
                    r.where,
                    f"rows for event {r.event!r} declare different data: "
                    f"{_shown(first.fields)} at {first.where}, {_shown(r.fields)} here",
                    "declare an event's data once, the same on every row that declares it",
                )
            )
    return {name: r.fields for name, r in found.items()}


def _shown(fields: Fields) -> str:
    return "{" + ", ".join(f"{k}: {v}" for k, v in fields) + "}"


def _parents(tree: ast.AST) -> dict[int, ast.AST]:
    parents: dict[int, ast.AST] = {}
    for node in ast.walk(tree):
        for child in ast.iter_child_nodes(node):
            parents[id(child)] = node
    return parents


def _path(node: ast.AST, parents: Mapping[int, ast.AST]) -> list[str]:
    """The constant attribute/item names read after ``node``: ``_event.data.x`` -> data, x."""
    path: list[str] = []
    while True:
        up = parents.get(id(node))
        if isinstance(up, ast.Attribute) and up.value is node:
            path.append(up.attr)
        elif (
            isinstance(up, ast.Subscript)
            and up.value is node
            and isinstance(up.slice, ast.Constant)
            and isinstance(up.slice.value, str)
        ):
            path.append(up.slice.value)
        else:
            return path
        node = up


def _reads(
    source: str,
    what: str,
    event: str,
    fields: Mapping[str, Fields],
    data_names: Iterable[str],
    where: Location,
) -> tuple[list[Diagnostic], set[str]]:
    """Rules 2-3 for one expression; also the event words it reported (not X303 then).

    Only a name in the text can be read, so a guard that spells none of the event words
    has nothing to report; the rest is worked out once per (text, event, declaration):
    a table repeats its guards, and a walk of every row's tree was a third of a check."""
    if not any(word in source for word in _READ_WORDS):
        return [], set()
    found, words = _reads_once(source, what, event, fields.get(event), frozenset(data_names))
    return [replace(d, where=where) for d in found], set(words)


_READ_WORDS = (*EVENT_WORDS, "_event")


@functools.lru_cache(maxsize=4096)
def _reads_once(
    source: str, what: str, event: str, declared: Fields | None, data: frozenset[str]
) -> tuple[tuple[Diagnostic, ...], frozenset[str]]:
    found, words = _reads_walk(source, what, event, declared, data, Location())
    return tuple(found), frozenset(words)


def _reads_walk(
    source: str,
    what: str,
    event: str,
    declared: Fields | None,
    data: frozenset[str],
    where: Location,
) -> tuple[list[Diagnostic], set[str]]:
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return [], set()
    parents = _parents(tree)
    out: list[Diagnostic] = []
    words: set[str] = set()
    for node in ast.walk(tree):
        if not isinstance(node, ast.Name):
            continue
        path = _path(node, parents)
        if node.id in EVENT_WORDS and node.id not in data:
            words.add(node.id)
            rest = path[1:] if node.id == "event" and path[:1] == ["data"] else path
            field = rest[0] if rest else "NAME"
            out.append(
                _d(
                    "B231",
                    Severity.ERROR,
                    where,
                    f"{what} {source.strip()!r} reads {node.id!r}, which is not the event's data",
                    f"read the data of event {event!r} as _event.data.{field}",
                )
            )
            continue
        if node.id != "_event" or not path:
            continue
        head = path[0]
        if head not in ("data", "name"):
            out.append(
                _d(
                    "B231",
                    Severity.ERROR,
                    where,
                    f"{what} {source.strip()!r} reads _event's {head!r}, which never holds "
                    "the event's data (it would always fail)",
                    f"read the data of event {event!r} as _event.data.{head}",
                )
            )
        elif head == "data" and len(path) > 1:
            field = path[1]
            if declared is None:
                out.append(
                    _d(
                        "B233",
                        Severity.WARNING,
                        where,
                        f"{what} {source.strip()!r} reads field {field!r} of event {event!r}, "
                        "which declares no data",
                        f"declare it on the event's row: data: {{{field}: float}} "
                        "(types: int, float, str, bool, list, dict, any)",
                    )
                )
            elif field not in dict(declared):
                out.append(
                    _d(
                        "B232",
                        Severity.ERROR,
                        where,
                        f"{what} {source.strip()!r} reads field {field!r}, which event "
                        f"{event!r} does not declare",
                        f"declared: {_shown(declared)}; add the field or fix the name",
                    )
                )
    if declared is not None:
        out.extend(_type_clashes(tree, parents, source, what, event, dict(declared), where))
    return out, words


def _field_of(node: ast.AST, parents: Mapping[int, ast.AST]) -> str | None:
    """The declared field an ``_event.data.NAME`` (or subscript) expression reads, if any."""
    for leaf in ast.walk(node):
        if isinstance(leaf, ast.Name) and leaf.id == "_event":
            path = _path(leaf, parents)
            if len(path) == 2 and path[0] == "data":
                # the whole node must be that path: _event.data.x, not len(_event.data.x)
                top: ast.AST = leaf
                for _ in path:
                    top = parents[id(top)]
                return path[1] if top is node else None
    return None


def _constants(node: ast.AST) -> list[object] | None:
    if isinstance(node, ast.Constant):
        return [node.value]
    if isinstance(node, ast.Tuple | ast.List | ast.Set) and all(
        isinstance(e, ast.Constant) for e in node.elts
    ):
        return [e.value for e in node.elts if isinstance(e, ast.Constant)]
    return None


def _type_clashes(
    tree: ast.AST,
    parents: Mapping[int, ast.AST],
    source: str,
    what: str,
    event: str,
    declared: Mapping[str, str],
    where: Location,
) -> list[Diagnostic]:
    """X306: a declared field compared with a literal its type never equals or orders with."""
    out: list[Diagnostic] = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Compare):
            continue
        operands = [node.left, *node.comparators]
        for a, b in itertools.pairwise(operands):
            for side, other in ((a, b), (b, a)):
                field = _field_of(side, parents)
                values = _constants(other)
                if field is None or values is None or field not in declared:
                    continue
                kind = declared[field]
                wrong = [v for v in values if not field_accepts(kind, v)]
                if wrong:
                    out.append(
                        _d(
                            "X306",
                            Severity.ERROR,
                            where,
                            f"{what} {source.strip()!r} compares field {field!r} of event "
                            f"{event!r}, declared {kind}, with {wrong[0]!r}",
                            f"compare it with a {kind}; the runtime refuses data of another "
                            "type, so this part is never true (or fails)",
                        )
                    )
    return out


def check_guard(
    expression: Expression,
    row: EventRow,
    known: Iterable[str],
    fields: Mapping[str, Fields],
    data_names: Iterable[str],
) -> list[Diagnostic]:
    """The guard's names (X303) and its event data reads (rules 2-3)."""
    found, words = _reads(expression.source, "guard", row.event, fields, data_names, row.where)
    unknown = [
        d
        for d in check_names(expression, known, row.where)
        if not any(f"undefined name {w!r}" in d.message for w in words)
    ]
    return [*unknown, *found]


def assign_actions(
    row: EventRow,
    known: Iterable[str],
    fields: Mapping[str, Fields],
    data_names: Sequence[str],
    diags: list[Diagnostic],
) -> tuple[Action, ...]:
    """The row's assignments as actions, each checked (rule 4)."""
    actions: list[Action] = []
    for target, source in row.assign:
        if target not in data_names:
            diags.append(
                _d(
                    "B234",
                    Severity.ERROR,
                    row.where,
                    f"event {row.event!r} assigns {target!r}, which is not a data item",
                    "declare it under 'data:' with its initial value (data items: "
                    + (", ".join(data_names) or "none")
                    + ")",
                )
            )
        expression, problems = _compile(source, row.where)
        diags.extend(
            Diagnostic(p.code, p.severity, p.where, p.message.replace("guard", "assign", 1), p.hint)
            for p in problems
        )
        if expression is not None:
            found, words = _reads(source, "assign", row.event, fields, data_names, row.where)
            diags.extend(
                d
                for d in check_names(expression, known, row.where, what="assign")
                if not any(f"undefined name {w!r}" in d.message for w in words)
            )
            diags.extend(found)
        actions.append(Assign(target, source, origin=row.where))
    return tuple(actions)


def merge_conflicts(group: Sequence[EventRow], diags: list[Diagnostic]) -> None:
    """Rows about to merge as identical that differ in API, kind or assignments (rule 5)."""
    first = group[0]
    rows = _rows_text([r.where for r in group])
    for column, code in (("api", "B206"), ("kind", "B206"), ("assign", "B235")):
        values = list(dict.fromkeys(getattr(r, column) for r in group))
        if len(values) < 2:
            continue
        other = next(r for r in group if getattr(r, column) != values[0])
        diags.append(
            _d(
                code,
                Severity.ERROR,
                other.where,
                f"rows for {first.old} + {first.event} = {first.new} are otherwise identical "
                f"but disagree on {column}; merging them would drop one",
                f"rows at {rows}; keep one row, or give every row the same {column}",
            )
        )
