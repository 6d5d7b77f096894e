"""YAML read with bounded work: no aliases, a nesting limit, the C parser when present.

Rules:
1. A device file, a cell file or a data cell is composed by :func:`compose`, an
   iterative composer over the parser's events: an alias (``*name``) is refused
   (T115) because no statectl file needs one and an alias bomb ("billion laughs")
   expands a few hundred bytes into gigabytes; nesting deeper than
   :data:`MAX_DEPTH` is refused (T116) before any recursive code sees it.
2. The events come from libyaml (``yaml.CSafeLoader``) when PyYAML was built with
   it, from the pure-Python parser otherwise; the tags are resolved the same way,
   so both give the very same nodes and the very same refusals. A number with an
   exponent and no dot (``1e3``) is a float, as in YAML 1.2, not text.
3. :func:`top_keys` answers "which sections does this file have?" from the parser's
   events alone, building no node: telling a cell file from a device file must not
   cost a second full load of a 100,000-row device file.
4. :func:`construct` turns a node into a plain value with the safe constructor;
   any failure (an unknown tag, a number with too many digits, a date that does
   not exist) is a :class:`YamlRefused` carrying a line, never another exception.
5. ``compose(text, flat=...)`` reads each mapping of scalars in the list under a top
   key ``flat`` accepts as a :class:`FlatRow` (its texts and lines, straight from the
   events) instead of nodes: the state and event tables of a 100,000-row file made
   ~800,000 nodes that were read once. A row holding anything but scalars (a nested
   value, an alias) is composed as nodes from where it stops being flat, so every
   refusal above is raised at the same event, with the same line.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any, NamedTuple

import yaml

__all__ = [
    "MAX_DEPTH",
    "FlatRow",
    "YamlRefused",
    "compose",
    "construct",
    "load_value",
    "top_keys",
]

#: The tag of a scalar that resolves to null (``~``, ``null``, an empty value).
NULL_TAG = "tag:yaml.org,2002:null"

#: Deepest nesting of sequences and mappings a file or a cell may have (T116).
MAX_DEPTH = 64

#: A float written with an exponent and no dot or exponent sign (``1e3``, ``2.5e-3``,
#: ``-1E+6``): YAML 1.2 reads it as a number, PyYAML's YAML 1.1 resolver as text, which
#: turned ``speed: 1e3`` into the text '1e3' and a "must be a number" refusal (rule 2).
_EXPONENT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$")


def _with_exponent_floats(loader: type[yaml.SafeLoader]) -> type[yaml.SafeLoader]:
    """``loader`` resolving :data:`_EXPONENT` as a float; its other tags are unchanged."""
    made: type[yaml.SafeLoader] = type(f"Statectl{loader.__name__}", (loader,), {})
    made.add_implicit_resolver("tag:yaml.org,2002:float", _EXPONENT, list("-+0123456789."))
    return made


_PyLoader = _with_exponent_floats(yaml.SafeLoader)
_CLoader: type[yaml.SafeLoader] | None = getattr(yaml, "CSafeLoader", None)  # libyaml's
_Loader = _PyLoader if _CLoader is None else _with_exponent_floats(_CLoader)


class YamlRefused(Exception):
    """YAML that is refused or cannot be read: a code, a 1-based line, why, what to do."""

    def __init__(self, code: str, line: int | None, message: str, hint: str = "") -> None:
        super().__init__(message)
        self.code = code
        self.line = line
        self.message = message
        self.hint = hint


def _line(mark: Any) -> int | None:
    return mark.line + 1 if mark is not None else None


def compose(
    text: str,
    loader: type[yaml.SafeLoader] | None = None,
    max_depth: int = MAX_DEPTH,
    flat: Callable[[str], bool] | None = None,
) -> yaml.Node | None:
    """The node tree of a one-document YAML text (``None`` when it is empty).

    Raises :class:`YamlRefused`: T101 malformed, T115 an alias, T116 too deep. A
    malformed text is read again by the pure-Python parser, so the line and message
    do not depend on whether libyaml is installed. ``flat`` names the top keys
    whose list's rows may be read as :class:`FlatRow` (rule 5).
    """
    try:
        return _compose_with(loader or _Loader, text, max_depth, flat)
    except YamlRefused as refused:
        if refused.code != "T101" or loader is not None or _Loader is _PyLoader:
            raise
    return _compose_with(_PyLoader, text, max_depth, flat)


def _compose_with(
    loader: type[yaml.SafeLoader], text: str, max_depth: int, flat: Callable[[str], bool] | None
) -> yaml.Node | None:
    parser: Any = None
    try:
        parser = loader(text)  # the pure-Python reader refuses control characters here
        return _compose(parser, max_depth, flat)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = exc.problem or exc.context or "malformed YAML"
        raise YamlRefused("T101", _line(mark), f"malformed YAML: {problem}") from None
    except yaml.YAMLError as exc:
        first = (str(exc).splitlines() or ["unreadable"])[0]
        raise YamlRefused("T101", None, f"malformed YAML: {first}") from None
    finally:
        if parser is not None:
            parser.dispose()


class FlatRow(NamedTuple):
    """A mapping of scalars read from the parser's events without nodes (rule 5).

    ``line`` is the mapping's 1-based line; each entry is (key text, key line, value
    text or ``None`` when the value resolves to null, value line), in file order. A
    tuple, as it is made once per row of a table of 100,000.
    """

    line: int
    entries: tuple[tuple[str, int, str | None, int], ...]


def _tagger(parser: Any) -> Callable[[Any], str]:
    """A scalar event -> its tag, as the safe composer resolves it.

    A plain scalar's tag is resolved once per distinct text: with no path resolvers
    (the safe loaders have none) it depends on the text alone.
    """
    resolve, scalar_node = parser.resolve, yaml.ScalarNode
    cacheable = not getattr(parser, "yaml_path_resolvers", None)
    plain_tags: dict[str, str] = {}  # plain scalar text -> its resolved tag

    def tag_of(event: Any) -> str:
        tag: str | None = event.tag
        if tag is not None and tag != "!":
            return tag
        value, implicit = event.value, event.implicit
        if cacheable and implicit[0]:
            tag = plain_tags.get(value)
            if tag is None:
                tag = plain_tags[value] = resolve(scalar_node, value, implicit)
            return tag
        resolved: str = resolve(scalar_node, value, implicit)
        return resolved

    return tag_of


def _compose(parser: Any, max_depth: int, flat: Callable[[str], bool] | None) -> yaml.Node | None:
    """Rule 1 over the parser's events, one pass, no recursion (rule 5 for ``flat``).

    The loop dispatches on the event's exact type (the parsers make no subclasses).
    A 10,000-state file is ~200,000 events, so each test here counts.
    """
    get = parser.get_event
    get()  # StreamStart
    if parser.check_event(yaml.StreamEndEvent):
        return None
    get()  # DocumentStart
    scalar_event, alias_event = yaml.ScalarEvent, yaml.AliasEvent
    seq_start, map_start = yaml.SequenceStartEvent, yaml.MappingStartEvent
    seq_end, map_end = yaml.SequenceEndEvent, yaml.MappingEndEvent
    scalar_node = yaml.ScalarNode
    tag_of = _tagger(parser)
    root: yaml.Node | None = None
    # each open collection: its node, its items, whether its mappings may be FlatRows
    stack: list[tuple[yaml.CollectionNode, list[Any], bool]] = []
    items: list[Any] | None = None  # the open collection's items
    pending: Any = None  # an event read ahead by _flat_row, handled next
    while True:
        event: Any = pending or get()
        pending = None
        kind = type(event)
        node: Any  # a yaml.Node, or a FlatRow in a list
        if kind is scalar_event:
            node = scalar_node(
                tag_of(event), event.value, event.start_mark, event.end_mark, event.style
            )
        elif kind is map_start or kind is seq_start:
            if len(stack) >= max_depth:
                raise _too_deep(event, max_depth)
            if kind is map_start and stack and stack[-1][2]:
                read = _flat_row(get, event, tag_of)
                if isinstance(read, FlatRow):
                    items.append(read)  # type: ignore[union-attr]  # a list is open
                    continue
                pending = read[1]  # the row holds more than scalars: compose it as nodes
            opened, items = _opened(parser, event, kind is map_start)
            stack.append((opened, items, flat is not None and _flat_list(stack, event, flat)))
            if pending is not None:
                items.extend(_scalar_nodes(read[0], tag_of))
            continue
        elif kind is map_end or kind is seq_end:
            closed, values, _ = stack.pop()
            closed.end_mark = event.end_mark
            if kind is map_end:
                closed.value = list(zip(values[::2], values[1::2], strict=True))
            else:
                closed.value = values
            node = closed
            items = stack[-1][1] if stack else None
        elif kind is alias_event:
            raise _alias(event)
        elif isinstance(event, yaml.DocumentEndEvent):
            break
        else:
            continue
        if items is not None:
            items.append(node)
        else:
            root = node  # a FlatRow is never the root: only a list's item is one
    _one_document(parser)
    return root


def _opened(parser: Any, event: Any, mapping: bool) -> tuple[yaml.CollectionNode, list[Any]]:
    """A new collection node for a start event (its items come later), and its item list."""
    made = yaml.MappingNode if mapping else yaml.SequenceNode
    tag = event.tag
    if tag is None or tag == "!":
        tag = parser.resolve(made, None, event.implicit)
    return made(tag, [], event.start_mark, event.end_mark, flow_style=event.flow_style), []


def _flat_list(stack: list[Any], event: Any, flat: Callable[[str], bool]) -> bool:
    """Rule 5: ``event`` opens a list that is the value of a top key ``flat`` names."""
    if len(stack) != 1 or type(event) is not yaml.SequenceStartEvent:
        return False
    top, items, _ = stack[0]
    return (
        type(top) is yaml.MappingNode
        and len(items) % 2 == 1
        and type(items[-1]) is yaml.ScalarNode
        and flat(items[-1].value)
    )


def _flat_row(get: Callable[[], Any], start: Any, tag_of: Callable[[Any], str]) -> Any:
    """Rule 5: the mapping ``start`` opens, read to its end as a :class:`FlatRow`; or,
    at the first event that is not a scalar, the scalar events read so far and that
    event, so the caller composes the row as nodes from there."""
    scalar_event: Any = yaml.ScalarEvent  # Any: the events' stubs are not what the loop reads
    null = NULL_TAG
    read: list[Any] = []
    entries: list[tuple[str, int, str | None, int]] = []
    key: Any
    while True:
        key = get()
        if type(key) is not scalar_event:
            break
        value: Any = get()
        read += key, value
        if type(value) is not scalar_event:
            return read[:-1], value
        text: str | None = value.value
        if tag_of(value) == null:
            text = None
        entries.append((key.value, key.start_mark.line + 1, text, value.start_mark.line + 1))
    if type(key) is not yaml.MappingEndEvent:
        return read, key
    return FlatRow(start.start_mark.line + 1, tuple(entries))


def _scalar_nodes(events: list[Any], tag_of: Callable[[Any], str]) -> list[yaml.Node]:
    """The nodes of scalar events, as the composer makes them."""
    return [yaml.ScalarNode(tag_of(e), e.value, e.start_mark, e.end_mark, e.style) for e in events]


# The refusals _compose raises, kept out of its loop so the loop reads as rule 1.


def _too_deep(event: Any, max_depth: int) -> YamlRefused:
    """T116: nesting past ``max_depth`` is refused before it costs stack or memory."""
    return YamlRefused(
        "T116",
        _line(event.start_mark),
        f"YAML nested deeper than {max_depth} levels",
        "flatten the value; see docs/limits.md",
    )


def _alias(event: Any) -> YamlRefused:
    """T115: an alias is refused, as it is how a small file expands into a huge value."""
    return YamlRefused(
        "T115",
        _line(event.start_mark),
        f"YAML alias '*{event.anchor}' refused",
        "write the value out in full; statectl files do not use anchors and aliases",
    )


def _one_document(parser: Any) -> None:
    """T101 for a second document: a file is one model, and the rest would go unread."""
    if not parser.check_event(yaml.StreamEndEvent):
        extra: Any = parser.get_event()
        raise YamlRefused(
            "T101",
            _line(extra.start_mark),
            "malformed YAML: a second document in the file",
            "remove the '---' that starts it",
        )


def construct(node: yaml.Node) -> object:
    """The node as a plain YAML value; raises :class:`YamlRefused` (T108) if it is none."""
    try:
        return yaml.SafeLoader("").construct_object(node, deep=True)
    except yaml.MarkedYAMLError as exc:
        problem = exc.problem or exc.context or "unreadable"
        line = _line(exc.problem_mark) or _line(node.start_mark)
        raise YamlRefused("T108", line, f"an unreadable value: {problem}") from None
    except (yaml.YAMLError, ValueError, OverflowError, TypeError) as exc:
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise YamlRefused(
            "T108",
            _line(node.start_mark),
            f"an unreadable value: {first}",
            "numbers are limited to 4300 digits; dates must exist",
        ) from None


def load_value(text: str, loader: type[yaml.SafeLoader] | None = None) -> object:
    """One YAML value (a data cell): compose with the limits, then construct."""
    node = compose(text, loader)
    return None if node is None else construct(node)


def top_keys(text: str) -> frozenset[str] | None:
    """The text keys of a one-document YAML mapping (rule 3); None when the text is not
    readable YAML, holds an alias or a second document, or its root is not a mapping."""
    parser: Any = _Loader(text)
    keys: set[str] = set()
    depth, at_key = 0, True  # depth of the open collections; whether a top key comes next
    try:
        while not isinstance(event := parser.get_event(), yaml.DocumentEndEvent | type(None)):
            if isinstance(event, yaml.AliasEvent):
                return None
            if isinstance(event, yaml.ScalarEvent):
                if depth == 0:
                    return None
                if depth == 1:
                    if at_key:
                        keys.add(event.value)
                    at_key = not at_key
            elif isinstance(event, yaml.CollectionStartEvent):
                if depth == 0 and not isinstance(event, yaml.MappingStartEvent):
                    return None
                depth += 1
            elif isinstance(event, yaml.CollectionEndEvent):
                depth -= 1
                at_key = not at_key if depth == 1 else at_key
        if event is None or not parser.check_event(yaml.StreamEndEvent):
            return None
    except yaml.YAMLError:
        return None
    finally:
        parser.dispose()
    return frozenset(keys)
