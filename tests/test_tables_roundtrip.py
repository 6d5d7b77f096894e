"""Properties: conversion between the four formats is lossless; build follows the rows."""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from statectl.front.builder.build import build
from statectl.front.observers import DRIVING_KINDS
from statectl.front.tables import (
    DeviceTables,
    EventRow,
    RecoveryRow,
    StateRow,
    load,
    save,
    strip_locations,
)
from statectl.front.tables.csv_io import dump_csv, read_csv
from statectl.front.tables.md_io import dump_md, read_md
from statectl.front.tables.timeouts import format_timeout
from statectl.front.tables.xlsx_io import dump_xlsx, read_xlsx
from statectl.front.tables.yaml_io import dump_yaml, read_yaml
from statectl.kernel.model import ControlKind, EventKind, Notify, StateKind

# Names: letters and digits of any script, plus punctuation people put in names.
# No commas (they separate list cells), no line breaks, no control characters.
NAME_CHARS = st.characters(
    categories=("Lu", "Ll", "Lo", "Nd"), include_characters=" _-()./:'\"#=+|\\<>&*!?[]{}%@"
)
# Free text (descriptions, conditions, guards) may also hold commas and line breaks.
TEXT_CHARS = st.characters(
    categories=("Lu", "Ll", "Lo", "Nd", "Po", "Sm"), include_characters=" ,\n|\\"
)


def stripped(chars: st.SearchStrategy[str], min_size: int) -> st.SearchStrategy[str]:
    return (
        st.text(chars, min_size=min_size, max_size=20)
        .map(str.strip)
        .filter(lambda s: len(s) >= min_size)
    )


names = stripped(NAME_CHARS, 1)
optional_names = stripped(NAME_CHARS, 0)
texts = stripped(TEXT_CHARS, 0)
controls = st.lists(st.sampled_from(list(ControlKind)), unique=True, max_size=3).map(tuple)
scalars = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=False)
    | st.text(TEXT_CHARS, max_size=10)
)
values = scalars | st.lists(scalars, max_size=3).map(tuple)
data = st.dictionaries(
    st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True), values, max_size=3
).map(lambda d: tuple(d.items()))

# A recovery row's data: an event payload, so mappings (text keys) and lists nest.
payloads = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=3)
        | st.dictionaries(st.text(TEXT_CHARS, max_size=6), inner, max_size=3)
    ),
    max_leaves=6,
)
# A recovery row posts an event (with data) or redoes the entering step (no event, no data).
recovery_rows = st.builds(RecoveryRow, state=names, event=names, data=payloads) | st.builds(
    RecoveryRow, state=names, redo=st.just(True)
)

state_rows = st.builds(
    StateRow,
    component=optional_names,
    api=optional_names,
    state=names,
    controls=controls,
    description=texts,
    ignore=st.lists(names, max_size=3).map(tuple),
    parent=optional_names,
    type=st.none() | st.sampled_from(list(StateKind)),
    default=st.lists(names, max_size=2).map(tuple),
    timeout=st.just("")
    | st.builds(format_timeout, st.integers(1, 10**6).map(lambda ms: ms / 1000), names),
    defer=st.lists(names, max_size=2).map(tuple),
)
event_rows = st.builds(
    EventRow,
    event=names,
    condition=texts,
    guard=texts,
    old=names,
    new=names,
    kind=st.sampled_from(list(EventKind)),
    api=optional_names,
    invoke=optional_names,
    unasked=st.booleans(),
    severity=st.none() | st.integers(1, 1000),
).map(
    lambda r: replace(
        r,
        unasked=r.unasked and r.kind is EventKind.COMPLETION,
        severity=r.severity if r.kind is EventKind.FAULT else None,
    )
)
device_tables = st.builds(
    DeviceTables,
    device=names,
    states=st.lists(state_rows, min_size=1, max_size=4).map(tuple),
    events=st.lists(event_rows, min_size=1, max_size=4).map(tuple),
    data=data,
    recovery=st.lists(recovery_rows, max_size=3).map(tuple),
)


def via_yaml(t: DeviceTables) -> DeviceTables | None:
    return read_yaml(dump_yaml(t), "t.yaml")[0]


def via_csv(t: DeviceTables) -> DeviceTables | None:
    states, events, values_, recovery = dump_csv(t)
    return read_csv(
        (states, "t.states.csv"),
        (events, "t.events.csv"),
        (values_, "t.data.csv") if values_ is not None else None,
        "t",
        (recovery, "t.recovery.csv") if recovery is not None else None,
    )[0]


def via_xlsx(t: DeviceTables) -> DeviceTables | None:
    return read_xlsx(dump_xlsx(t), "t.xlsx", "t")[0]


def via_md(t: DeviceTables) -> DeviceTables | None:
    return read_md(dump_md(t), "t.md", "t")[0]


@settings(max_examples=150, deadline=None)
@given(device_tables)
def test_yaml_csv_xlsx_md_chain_is_lossless(tables: DeviceTables) -> None:
    """YAML -> CSV -> XLSX -> MD -> YAML gives back the same tables (recovery rows too)."""
    expected = strip_locations(tables)
    current: DeviceTables | None = tables
    for convert in (via_yaml, via_csv, via_xlsx, via_md, via_yaml):
        assert current is not None
        current = convert(current)
        assert current is not None, convert.__name__
        assert strip_locations(current) == expected, convert.__name__


@settings(max_examples=25, deadline=None)
@given(device_tables, st.sampled_from(["yaml", "csv", "xlsx", "md"]))
def test_save_and_load_files_is_lossless(tables: DeviceTables, fmt: str) -> None:
    """Through real files too, load(save(t)) equals t except for locations."""
    with tempfile.TemporaryDirectory() as tmp:
        written = save(tables, Path(tmp) / f"dev.{fmt}", fmt)
        back, diags = load(written[0])
    assert diags == []
    assert back is not None
    assert strip_locations(back) == strip_locations(tables)


# --- build ------------------------------------------------------------------------------

SIMPLE = st.text("abcdefgh", min_size=1, max_size=4)
GUARDS = ["", "limit > 1", "previous == 'x'", "limit > 0 and _event is not None"]


@st.composite
def buildable_tables(draw: st.DrawFn) -> DeviceTables:
    """Valid tables: one default state, events with one kind and API each."""
    state_names = draw(st.lists(SIMPLE, min_size=1, max_size=5, unique=True))
    default = draw(st.sampled_from(state_names))
    states = []
    for name in state_names:
        rest = draw(
            st.lists(st.sampled_from([ControlKind.MONITORING, ControlKind.TRIGGER]), unique=True)
        )
        kinds = (ControlKind.DEFAULT, *rest) if name == default else tuple(rest)
        states.append(StateRow("Dev", "", name, kinds, "", ()))
    event_names = draw(st.lists(SIMPLE.map(str.upper), min_size=1, max_size=4, unique=True))
    meta = {
        e: (draw(st.sampled_from(list(EventKind))), draw(st.sampled_from(["", "Run", "Stop"])))
        for e in event_names
    }
    rows = []
    for _ in range(draw(st.integers(1, 8))):
        event = draw(st.sampled_from(event_names))
        kind, api = meta[event]
        rows.append(
            EventRow(
                event,
                "",
                draw(st.sampled_from(GUARDS)),
                draw(st.sampled_from(state_names)),
                draw(st.sampled_from(state_names)),
                kind,
                api,
            )
        )
    return DeviceTables("Dev", tuple(states), tuple(rows), (("limit", 2),))


@settings(max_examples=150, deadline=None)
@given(buildable_tables())
def test_build_transitions_match_the_rows(tables: DeviceTables) -> None:
    """Each distinct (event, old, new, guard) row is one transition, in row order,
    notifying an invoke exactly when its event drives an API."""
    chart, diags = build(tables)
    assert chart is not None, [str(d) for d in diags]
    distinct = list(
        dict.fromkeys((r.event, r.old, r.new, r.guard, r.kind, r.api) for r in tables.events)
    )
    assert len(chart.transitions) == len(distinct)
    by_method = {i.method: i for i in chart.invokes}
    for t, (event, old, new, guard, kind, api) in zip(chart.transitions, distinct, strict=True):
        assert (t.source, t.events, t.targets, t.guard) == (old, (event,), (new,), guard or None)
        notifies = kind in DRIVING_KINDS and bool(api)
        assert t.actions == (
            (Notify(by_method[api].number, by_method[api].name, api, event),) if notifies else ()
        )
    assert chart.initial == tuple(
        s.state for s in tables.states if ControlKind.DEFAULT in s.controls
    )
    kept = (
        {s.state for s in tables.states if s.controls}
        | {r.old for r in tables.events}
        | {r.new for r in tables.events}
    )
    assert {s.name for s in chart.states} == kept
