"""A device file's rows of scalars are read from the parser's events (safeyaml rule 5):
the tables and every diagnostic, lines included, are those the node tree gives.

Each file below is read twice, once as the reader does (flat rows) and once with flat
rows turned off (every row composed as nodes, the way all rows were read before), and
the two answers must be equal: the tables with every location, and the diagnostics.
"""

from __future__ import annotations

import random

import pytest

from statectl.front.tables import safeyaml, yaml_io
from statectl.front.tables.rows import DeviceTables
from statectl.kernel.errors import Diagnostic

HEAD = "device: D\nstates:\n  - state: A\n    control: default\n  - {state: B}\nevents:\n"

#: Files whose state or event rows take each way through the reader: plain rows, nulls,
#: tags, quoting, keys to normalize, duplicates, nested values, refusals, malformed text.
FILES = {
    "block rows": HEAD + "  - event: go\n    old: A\n    new: B\n  - event: back\n"
    "    old: B\n    new: A\n    guard: x > 1\n",
    "flow rows": HEAD + "  - {event: go, old: A, new: B}\n  - {event: back, old: B, new: A}\n",
    "nulls": HEAD + "  - event: go\n    old:\n    new: ~\n    guard: null\n    api: 'null'\n",
    "tags": HEAD + "  - {event: !!str 12, old: !!null x, new: !custom B, api: ! m}\n",
    "quoted and folded": HEAD + "  - event: 'go'\n    old: \"A\"\n    new: >\n      B\n"
    "    condition: |\n      when\n      ready\n",
    "padded quoted": "device: D\nstates:\n  - {state: ' A ', control: ' Default '}\n"
    "  - {state: \"B \", control: ' event trigger required', parent: ' '}\nevents:\n"
    "  - {event: ' go ', old: \"A \", new: ' B', kind: ' Fault ', api: ' m '}\n",
    "multi-line plain": HEAD + "  - event: go\n    old: A\n    new: B\n    condition: the\n"
    "      door is shut\n",
    "comments": HEAD + "  # a comment\n  - event: go  # trailing\n    old: A\n\n    new: B\n",
    "keys to normalize": HEAD + "  - Event: go\n    OLD: A\n    new: B\n    Kind: fault\n",
    "duplicate keys": HEAD + "  - event: go\n    old: A\n    new: B\n    old: B\n",
    "duplicate after normalizing": HEAD + "  - {event: go, old: A, new: B, Old: B}\n",
    "unknown column": HEAD + "  - {event: go, old: A, new: B, colour: red}\n",
    "number keys": HEAD + "  - {event: go, old: A, new: B, 1: x, true: y, null: z}\n",
    "list cell": "device: D\nstates:\n  - state: A\n    control: [default]\n"
    "    ignore: [go, back]\n  - {state: B}\nevents:\n  - {event: go, old: A, new: B}\n",
    "list first": "device: D\nstates:\n  - ignore: [go]\n    state: A\n    control: default\n"
    "events:\n  - {event: go, old: A, new: A}\n",
    "mapping cell": HEAD + "  - {event: go, old: A, new: B, guard: {x: 1}}\n",
    "event data": HEAD + "  - event: go\n    old: A\n    new: B\n    data: {speed: float}\n"
    "    assign: {v: _event.data.speed}\n",
    "complex key": HEAD + "  - event: go\n    old: A\n    ? [k]\n    : v\n    new: B\n",
    "scalar row": HEAD + "  - go\n  - {event: go, old: A, new: B}\n",
    "list row": HEAD + "  - [go, A, B]\n",
    "empty row": HEAD + "  - {}\n  - {event: go, old: A, new: B}\n",
    "null table": "device: D\nstates:\n  - {state: A, control: default}\nevents:\n",
    "mapping table": HEAD.replace("events:\n", "events:\n  go: {old: A, new: B}\n"),
    "capital table keys": "device: D\nStates:\n  - {state: A, control: default}\n"
    "EVENTS:\n  - {event: go, old: A, new: A}\n",
    "tables twice": HEAD + "  - {event: go, old: A, new: B}\nevents:\n  - {event: x, old: A}\n",
    "anchor": HEAD + "  - {event: &e go, old: A, new: B}\n",
    "alias value": HEAD + "  - {event: &e go, old: A, new: B}\n  - {event: *e, old: B, new: A}\n",
    "alias key": HEAD + "  - {event: go, old: A, new: B}\n  - {*k : go}\n",
    "alias row": HEAD + "  - &r {event: go, old: A, new: B}\n  - *r\n",
    "deep value": HEAD + "  - {event: go, old: A, new: B, guard: " + "[" * 70 + "]" * 70 + "}\n",
    "bad indent": HEAD + "  - event: go\n    old: A\n   new: B\n",
    "unclosed flow": HEAD + "  - {event: go, old: A\n  - {event: back}\n",
    "colon in value": HEAD + "  - event: go\n    old: A: B\n",
    "tab": HEAD + "  - event: go\n\told: A\n",
    "second document": HEAD + "  - {event: go, old: A, new: B}\n---\nx: 1\n",
    "recovery": HEAD + "  - {event: go, old: A, new: B}\nrecovery:\n  - {state: B, event: go}\n"
    "  - {state: A, event: go, data: {detail: x}}\n",
}


Said = tuple[str, int | None, str, str]


def _read(text: str, flat: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[object, list[Said]]:
    """What read_yaml answers, with flat rows on or off."""
    with monkeypatch.context() as patch:
        if not flat:
            patch.setattr(yaml_io, "_flat_table", lambda key: False)
        tables, diags = yaml_io.read_yaml(text, "d.yaml")
    return _plain(tables), [_said(d) for d in diags]


def _plain(tables: DeviceTables | None) -> object:
    return None if tables is None else (tables.states, tables.events, tables.recovery)


def _said(d: Diagnostic) -> Said:
    return d.code, d.where.line, d.message, d.hint


@pytest.mark.parametrize("name", sorted(FILES))
def test_a_file_reads_the_same_with_and_without_flat_rows(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Tables, locations and diagnostics are the node tree's, whichever way a row took."""
    text = FILES[name]
    assert _read(text, True, monkeypatch) == _read(text, False, monkeypatch)


def test_the_plain_rows_are_read_flat_and_the_others_as_nodes() -> None:
    """The comparison above compares two ways: rows of scalars come as FlatRows, a row
    holding a list or a mapping as a node, from either parser."""
    text = FILES["list first"].replace("events:\n", "events:\n  - {event: x, old: A, new: A}\n")
    for loader in (safeyaml._Loader, safeyaml._PyLoader):
        root = safeyaml.compose(text, loader, flat=yaml_io._flat_table)
        assert root is not None
        tables = {key.value: value for key, value in root.value}
        assert [type(row).__name__ for row in tables["states"].value] == ["MappingNode"]
        assert [type(row) for row in tables["events"].value] == [safeyaml.FlatRow] * 2


@pytest.mark.parametrize(
    ("name", "code", "line"),
    [
        ("alias value", "T115", 8),
        ("alias key", "T115", 8),
        ("alias row", "T115", 8),
        ("deep value", "T116", 7),
        ("bad indent", "T101", 9),
        ("second document", "T101", 8),
    ],
)
def test_a_refusal_inside_a_row_keeps_its_code_and_line(
    name: str, code: str, line: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An alias, a deep nesting or malformed text in a row is refused where it stands."""
    _, diags = _read(FILES[name], True, monkeypatch)
    assert [(c, at) for c, at, _, _ in diags] == [(code, line)]


#: Pieces of an event row, each a (key, value) as written: the generated files below mix
#: them in block and flow style, so the two ways meet rows they were not written for.
PIECES = [
    ("event", "go"),
    ("event", "back"),
    ("Event", "go"),
    ("old", "A"),
    ("old", ""),
    ("old", "~"),
    ("new", "B"),
    ("new", "'B'"),
    ("new", "' B '"),
    ("kind", "' Fault '"),
    ("guard", "x > 1"),
    ("guard", "[a, b]"),
    ("kind", "fault"),
    ("kind", "sometimes"),
    ("api", "null"),
    ("data", "{v: int}"),
    ("colour", "red"),
    ("ignore", "[go]"),
]


def _generated(seed: int) -> str:
    rng = random.Random(seed)
    lines = [HEAD.rstrip("\n")]
    for _ in range(rng.randint(1, 6)):
        pieces = rng.sample(PIECES, rng.randint(0, 6))
        if not pieces:
            lines.append("  - {}")
        elif rng.random() < 0.5:
            lines.append("  - {" + ", ".join(f"{k}: {v}" for k, v in pieces) + "}")
        else:
            lines += [f"    {k}: {v}" for k, v in pieces]
            lines[-len(pieces)] = "  - " + lines[-len(pieces)].lstrip()
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", range(60))
def test_generated_rows_read_the_same_with_and_without_flat_rows(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Rows mixed from the pieces above: the same tables and diagnostics both ways."""
    text = _generated(seed)
    assert _read(text, True, monkeypatch) == _read(text, False, monkeypatch), text


@pytest.mark.parametrize(
    ("table", "text", "read"),
    [
        ("events", "{event: go, old: A, new: B, guard: x > 1}", True),
        ("events", "{event: go, old: A, new: B, kind: sometimes}", False),  # T107
        ("events", "{event: go, old: A, new: B, data: x}", False),  # not a plain column
        ("events", "{Event: go, old: A, new: B}", False),  # a key to normalize
        ("events", "{event: go, old: A, new: B, old: C}", False),  # a key twice
        ("states", "{state: A, control: default, description: ~}", True),
        ("states", "{state: A, control: 'default, final'}", False),  # two controls
    ],
)
def test_a_plain_row_is_read_at_once_and_any_other_gets_its_cells(
    table: str, text: str, read: bool
) -> None:
    """A plain row comes read (no cells to make); any other row keeps its cells, so the
    comparisons above compare the two ways."""
    root = safeyaml.compose(f"{table}:\n  - {text}\n", flat=yaml_io._flat_table)
    assert root is not None
    (row,) = root.value[0][1].value
    got = yaml_io._raw_row("d.yaml", table, row, [])
    assert (got.read is not None, bool(got.cells)) == (read, not read)
