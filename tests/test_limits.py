"""Hostile and broken input ends in a diagnostic at a documented limit, never an exception.

Alias bombs, deep nesting, huge numbers, odd encodings and entity declarations in
device files (every table format), cell files and SCXML documents; and every CLI
command given such a file exits 1 (or 2 for a missing file) without a traceback.
"""

from __future__ import annotations

import importlib
import importlib.util
import io
from pathlib import Path
from typing import Any

import openpyxl
import pytest
import yaml

from statectl.cell.model import load_cell
from statectl.channels.cli import main
from statectl.front.builder.build import MAX_STATE_DEPTH, load_and_build
from statectl.front.tables.safeyaml import MAX_DEPTH, YamlRefused, compose, load_value
from statectl.kernel.errors import Severity
from statectl.out.scxml.reader import read_scxml
from statectl.out.scxml.xmltree import MAX_SRC_BYTES, MAX_XML_DEPTH

ROOT = Path(__file__).resolve().parents[1]

#: The checker's module: ``statectl.check``, named ``statectl.front.rules`` on branches where it was
#: renamed (the facade's ``check()`` function took the name).
RULES: Any = importlib.import_module(
    "statectl.front.rules" if importlib.util.find_spec("statectl.front.rules") else "statectl.check"
)

#: 7 levels of 9 aliases: 9**7 (4.8 million) strings once expanded, from 222 bytes.
BOMB = (
    "[&a [x,x,x,x,x,x,x,x,x]"
    + "".join(
        f", &{b} [{', '.join(['*' + a] * 9)}]" for a, b in zip("abcdef", "bcdefg", strict=True)
    )
    + "]"
)

DEVICE = """\
device: D
data:
  x: 0
states:
  - state: A
    control: default
  - state: B
    control: event trigger required
events:
  - event: go
    old: A
    new: B
  - event: back
    old: B
    new: A
"""
STATES_CSV = "# device: D\nstate,control\nA,default\nB,event trigger required\n"
EVENTS_CSV = "event,old,new\ngo,A,B\nback,B,A\n"
MD = """\
# Device: D

## States

| state | control |
|---|---|
| A | default |
| B | event trigger required |

## Events

| event | old | new |
|---|---|---|
| go | A | B |
| back | B | A |
"""


def deep_list(depth: int) -> str:
    return "[" * depth + "]" * depth


def parent_chain(depth: int) -> str:
    rows = ["device: D", "states:", "  - state: S0", "    control: default"]
    for i in range(1, depth):
        rows += [f"  - state: S{i}", f"    parent: S{i - 1}"]
    rows += ["events:", "  - event: go", f"    old: S{depth - 1}", "    new: S0"]
    return "\n".join(rows) + "\n"


def workbook(data: list[list[object]] | None, recovery: list[list[object]] | None) -> bytes:
    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = "States"
    for row in (["state", "control"], ["A", "default"], ["B", "event trigger required"]):
        ws.append(row)
    ws = wb.create_sheet("Events")
    for row in (["event", "old", "new"], ["go", "A", "B"], ["back", "B", "A"]):
        ws.append(row)
    for title, rows in (("Data", data), ("Recovery", recovery)):
        if rows is not None:
            ws = wb.create_sheet(title)
            for row in rows:
                ws.append(row)
    out = io.BytesIO()
    wb.save(out)
    return out.getvalue()


def csv_pair(data: str | None = None, recovery: str | None = None) -> dict[str, str | bytes]:
    files: dict[str, str | bytes] = {"d.states.csv": STATES_CSV, "d.events.csv": EVENTS_CSV}
    if data is not None:
        files["d.data.csv"] = data
    if recovery is not None:
        files["d.recovery.csv"] = recovery
    return files


# (case id, files (the first is loaded), code, line or row, a word the message or hint holds)
DEVICE_CASES: list[tuple[str, dict[str, str | bytes], str, int, str]] = [
    ("yaml-alias-bomb", {"d.yaml": DEVICE.replace("x: 0", "x: " + BOMB)}, "T115", 3, "alias"),
    (
        "yaml-alias-in-a-cell",
        {"d.yaml": DEVICE.replace("new: B\n", "new: &n B\n").replace("new: A", "new: *n")},
        "T115",
        15,
        "alias",
    ),
    (
        "yaml-deep-data",
        {"d.yaml": DEVICE.replace("x: 0", "x: " + deep_list(5000))},
        "T116",
        3,
        "64",
    ),
    (
        "yaml-deep-block",
        {"d.yaml": DEVICE + "x:\n" + "".join("  " * i + "- \n" for i in range(200))},
        "T116",
        80,
        "nested",
    ),
    (
        "yaml-huge-integer",
        {"d.yaml": DEVICE.replace("x: 0", "x: " + "9" * 5000)},
        "T108",
        3,
        "digits",
    ),
    (
        "yaml-date-that-does-not-exist",
        {"d.yaml": DEVICE.replace("x: 0", "x: 2020-13-45")},
        "T108",
        3,
        "month",
    ),
    (
        "yaml-guard-too-deep",
        {"d.yaml": DEVICE.replace("new: B\n", "new: B\n    guard: " + "not " * 5000 + "x\n")},
        "X305",  # the expression language's own depth and length limit
        10,
        "nested levels",
    ),
    (
        "yaml-parent-chain-4000",
        {"d.yaml": parent_chain(4000)},
        "B218",
        2 * MAX_STATE_DEPTH + 3,
        "levels",
    ),
    ("csv-data-alias-bomb", csv_pair(data=f'name,value\nx,"{BOMB}"\n'), "T115", 2, "alias"),
    ("csv-data-deep", csv_pair(data=f"name,value\nx,{deep_list(300)}\n"), "T116", 2, "nested"),
    (
        "csv-recovery-alias-bomb",
        csv_pair(recovery=f'# device: D\nstate,event,data\nB,back,"{BOMB}"\n'),
        "T115",
        3,
        "alias",
    ),
    (
        "md-data-alias-bomb",
        {"d.md": MD + f"\n## Data\n\n| name | value |\n|---|---|\n| x | {BOMB} |\n"},
        "T115",
        21,
        "alias",
    ),
    (
        "md-recovery-alias-bomb",
        {
            "d.md": MD + f"\n## Recovery\n\n| state | event | data |\n|---|---|---|\n"
            f"| B | back | {BOMB} |\n"
        },
        "T115",
        21,
        "alias",
    ),
    (
        "xlsx-data-alias-bomb",
        {"d.xlsx": workbook([["name", "value"], ["x", BOMB]], None)},
        "T115",
        2,
        "alias",
    ),
    (
        "xlsx-recovery-alias-bomb",
        {"d.xlsx": workbook(None, [["state", "event", "data"], ["B", "back", BOMB]])},
        "T115",
        2,
        "alias",
    ),
    (
        "xlsx-data-huge-integer",
        {"d.xlsx": workbook([["name", "value"], ["x", "9" * 5000]], None)},
        "T108",
        2,
        "digits",
    ),
]


def write(tmp_path: Path, files: dict[str, str | bytes]) -> Path:
    tmp_path.mkdir(parents=True, exist_ok=True)
    for name, content in files.items():
        path = tmp_path / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")
    return tmp_path / next(iter(files))


@pytest.mark.parametrize(
    ("files", "code", "line", "word"),
    [pytest.param(f, c, ln, w, id=i) for i, f, c, ln, w in DEVICE_CASES],
)
def test_hostile_device_file_is_refused_at_its_line(
    tmp_path: Path, files: dict[str, str | bytes], code: str, line: int, word: str
) -> None:
    """A hostile device file gives its code at its line and no chart, whatever the format."""
    chart, diags = load_and_build(write(tmp_path, files))
    assert chart is None
    found = [d for d in diags if d.code == code]
    assert found, [str(d) for d in diags]
    assert found[0].severity is Severity.ERROR
    assert found[0].where.line == line, str(found[0])
    assert word.lower() in (found[0].message + " " + found[0].hint).lower(), str(found[0])


def zip_bomb() -> bytes:
    """A valid workbook plus one part of zeros that unpacks past the limit (~70 KiB packed)."""
    import zipfile

    from statectl.front.tables.xlsx_io import MAX_UNPACKED_BYTES

    out = io.BytesIO(workbook(None, None))
    with zipfile.ZipFile(out, "a", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("xl/padding.bin", bytes(MAX_UNPACKED_BYTES + 1))
    return out.getvalue()


def test_xlsx_zip_bomb_is_t117(tmp_path: Path) -> None:
    """A workbook whose parts unpack past the limit is T117 and is never unpacked."""
    content = zip_bomb()
    assert len(content) < 1 << 20
    chart, diags = load_and_build(write(tmp_path, {"d.xlsx": content}))
    assert chart is None
    assert [d.code for d in diags] == ["T117"]


def test_state_depth_at_the_limit_builds(tmp_path: Path) -> None:
    """A parent chain exactly MAX_STATE_DEPTH deep builds; the limit is not off by one."""
    chart, diags = load_and_build(write(tmp_path, {"d.yaml": parent_chain(MAX_STATE_DEPTH)}))
    assert chart is not None, [str(d) for d in diags if d.severity is Severity.ERROR]


def test_yaml_depth_at_the_limit_loads() -> None:
    """A value nested exactly MAX_DEPTH deep loads; one level more is T116."""
    assert load_value(deep_list(MAX_DEPTH)) is not None
    with pytest.raises(YamlRefused) as info:
        load_value(deep_list(MAX_DEPTH + 1))
    assert info.value.code == "T116"


LOADERS = [yaml.SafeLoader] + ([yaml.CSafeLoader] if hasattr(yaml, "CSafeLoader") else [])
EXAMPLE_YAML = sorted(p for p in (ROOT / "examples").rglob("*.yaml"))


def _shape(node: yaml.Node | None) -> object:
    """A node tree as plain data: tag, value and line of every node."""
    if node is None:
        return None
    if isinstance(node, yaml.ScalarNode):
        return (node.tag, node.value, node.start_mark.line)
    if isinstance(node, yaml.MappingNode):
        return (node.tag, [(_shape(k), _shape(v)) for k, v in node.value], node.start_mark.line)
    return (node.tag, [_shape(v) for v in node.value], node.start_mark.line)


@pytest.mark.parametrize("path", EXAMPLE_YAML, ids=lambda p: p.name)
def test_c_and_python_loaders_compose_the_same_tree(path: Path) -> None:
    """libyaml and the pure-Python parser give the same nodes, tags and lines."""
    text = path.read_text(encoding="utf-8")
    shapes = [_shape(compose(text, loader)) for loader in LOADERS]
    assert shapes[0] is not None
    assert all(s == shapes[0] for s in shapes)


@pytest.mark.parametrize(
    ("text", "code"),
    [
        (BOMB, "T115"),
        (deep_list(MAX_DEPTH + 1), "T116"),
        ("a: 1\n---\nb: 2\n", "T101"),
        ("x: " + "9" * 5000, "T108"),
        ("!!python/object:os.system {}", "T108"),
    ],
    ids=["alias", "deep", "two-documents", "huge-int", "python-tag"],
)
def test_both_loaders_refuse_alike(text: str, code: str) -> None:
    """Each loader refuses the same hostile text with the same code."""
    codes = []
    for loader in LOADERS:
        with pytest.raises(YamlRefused) as info:
            load_value(text, loader)
        codes.append(info.value.code)
    assert codes == [code] * len(LOADERS)


CELL = """\
cell: C
devices:
  d: d.yaml
"""


@pytest.mark.parametrize(
    ("cell", "device", "code", "line"),
    [
        (CELL, DEVICE.replace("x: 0", "x: " + BOMB), "V805", 3),
        (CELL + "links: &l []\nenvironment: *l\n", DEVICE, "T115", 5),
        (CELL + "invariants: " + deep_list(500) + "\n", DEVICE, "T116", 4),
        (CELL.encode("utf-8") + b"x: \xff\xfe\n", DEVICE, "V801", 1),
        (
            CELL + 'invariants:\n  - {name: x, holds: "' + "not " * 5000 + "In('d.A')\"}\n",
            DEVICE,
            "X305",  # the expression language's own depth and length limit
            5,
        ),
    ],
    ids=["device-with-alias-bomb", "alias-in-cell", "deep-cell", "not-utf8", "deep-invariant"],
)
def test_hostile_cell_file_is_refused(
    tmp_path: Path, cell: str | bytes, device: str, code: str, line: int
) -> None:
    """A cell file, or a device it includes, that is hostile gives a diagnostic, no cell."""
    write(tmp_path, {"c.cell.yaml": cell, "d.yaml": device})
    loaded, diags = load_cell(tmp_path / "c.cell.yaml")
    assert loaded is None
    assert [(d.code, d.where.line) for d in diags if d.severity is Severity.ERROR][:1] == [
        (code, line)
    ], [str(d) for d in diags]


SCXML_HEAD = '<scxml xmlns="http://www.w3.org/2005/07/scxml" version="1.0"'
STATECTL = ' xmlns:statectl="urn:statectl:scxml"'


def lol(levels: int) -> bytes:
    """A billion-laughs DTD: each entity ten of the one before."""
    decls = '<!ENTITY e0 "ha">' + "".join(
        f'<!ENTITY e{i} "{f"&e{i - 1};" * 10}">' for i in range(1, levels)
    )
    return (
        f'<?xml version="1.0"?>\n<!DOCTYPE scxml [{decls}]>\n{SCXML_HEAD}>'
        f'<final id="f"><onentry><log expr="\'&e{levels - 1};\'"/></onentry></final></scxml>\n'
    ).encode()


SCXML_CASES: list[tuple[str, bytes, str, int]] = [
    ("invalid-utf8", f'{SCXML_HEAD}>\n<final id="f\xff"/></scxml>'.encode("latin-1"), "S601", 2),
    (
        "unknown-encoding",
        (
            f'<?xml version="1.0" encoding="no-such-codec"?>\n{SCXML_HEAD}><final id="f"/></scxml>'
        ).encode(),
        "S621",
        1,
    ),
    ("billion-laughs", lol(10), "S622", 2),
    (
        "external-entity",
        f'<?xml version="1.0"?>\n<!DOCTYPE scxml [<!ENTITY x SYSTEM "file:///etc/passwd">]>\n'
        f'{SCXML_HEAD}><final id="f"><onentry><log expr="\'&x;\'"/></onentry></final>'
        "</scxml>".encode(),
        "S622",
        2,
    ),
    (
        "deep-if",
        (
            f'{SCXML_HEAD} initial="a">\n<state id="a"><onentry>'
            + '<if cond="true">' * 3000
            + "</if>" * 3000
            + "</onentry></state></scxml>"
        ).encode(),
        "S620",
        2,
    ),
    (
        "deep-states",
        (
            f"{SCXML_HEAD}>\n"
            + "".join(f'<state id="s{i}">' for i in range(3000))
            + "</state>" * 3000
            + "</scxml>"
        ).encode(),
        "S620",
        2,
    ),
    (
        "huge-invoke-number",
        f'{SCXML_HEAD}{STATECTL}>\n<statectl:invoke number="{"9" * 5000}" name="a" method="b"/>'
        f'<final id="f"/></scxml>'.encode(),
        "S603",
        2,
    ),
    (
        "unicode-digit-notify",
        f'{SCXML_HEAD}{STATECTL}>\n<final id="f"><onentry><statectl:notify invoke="\u00b2" '
        f'name="a" method="b" event="c"/></onentry></final></scxml>'.encode(),
        "S603",
        2,
    ),
]


@pytest.mark.parametrize(
    ("content", "code", "line"), [pytest.param(c, k, ln, id=i) for i, c, k, ln in SCXML_CASES]
)
def test_hostile_scxml_is_refused_at_its_line(content: bytes, code: str, line: int) -> None:
    """A hostile SCXML document gives its code at its line and no chart."""
    chart, diags = read_scxml(content, "doc.scxml")
    assert chart is None
    assert [(d.code, d.where.line) for d in diags if d.severity is Severity.ERROR][:1] == [
        (code, line)
    ], [str(d) for d in diags]


def test_scxml_depth_at_the_limit_reads() -> None:
    """States nested exactly to MAX_XML_DEPTH (with the root) read; the limit is not off by one."""
    depth = MAX_XML_DEPTH - 1
    text = (
        f"{SCXML_HEAD}>"
        + "".join(f'<state id="s{i}">' for i in range(depth))
        + "</state>" * depth
        + "</scxml>"
    )
    chart, diags = read_scxml(text)
    assert chart is not None, [str(d) for d in diags]


def test_scxml_text_ignores_its_prolog_encoding() -> None:
    """Text (already decoded) is parsed as it is, whatever encoding its prolog names."""
    text = f'<?xml version="1.0" encoding="no-such-codec"?>\n{SCXML_HEAD}><final id="f"/></scxml>'
    chart, diags = read_scxml(text)
    assert chart is not None, [str(d) for d in diags]


def test_scxml_bytes_in_a_declared_encoding_read() -> None:
    """Bytes in the encoding the prolog declares (Latin-1 here) are decoded by it."""
    text = (
        f'<?xml version="1.0" encoding="ISO-8859-1"?>\n{SCXML_HEAD}><final id="f\u00e9"/></scxml>'
    )
    chart, diags = read_scxml(text.encode("latin-1"))
    assert chart is not None, [str(d) for d in diags]
    assert [s.name for s in chart.states] == ["f\u00e9"]


def test_oversized_src_is_s607(tmp_path: Path) -> None:
    """A ``<script src>`` larger than MAX_SRC_BYTES is S607, read no further than the limit."""
    (tmp_path / "big.py").write_bytes(b"#" * (MAX_SRC_BYTES + 1))
    text = f'{SCXML_HEAD} datamodel="python">\n<script src="big.py"/><final id="f"/></scxml>'
    chart, diags = read_scxml(text, "doc.scxml", str(tmp_path))
    assert chart is None
    assert [(d.code, d.where.line) for d in diags] == [("S607", 2)]
    assert "larger" in diags[0].message


# -- every CLI command on every broken file -----------------------------------------------------

DEVICE_COMMANDS = [
    ["check"],
    ["build"],
    ["observers"],
    ["render"],
    ["tables", "--to", "csv", "--out", "OUT/x.csv"],
    ["codegen", "--out", "OUT"],
    ["scxml", "export"],
]
SCXML_COMMANDS = [["scxml", "run", "--timeout", "2"], ["scxml", "import", "--out", "OUT/x.yaml"]]
CELL_COMMANDS = [["verify"], ["run", "--walk", "3"]]


def _broken_inputs(tmp_path: Path) -> list[tuple[list[list[str]], Path]]:
    inputs: list[tuple[list[list[str]], Path]] = []
    for i, (_, files, code, _, _) in enumerate(DEVICE_CASES):
        # a file that loads but does not build (B218) is still converted by `tables`
        commands = DEVICE_COMMANDS if code.startswith("T") else DEVICE_COMMANDS[:4]
        inputs.append((commands, write(tmp_path / f"dev{i}", files)))
    for i, (_, content, _, _) in enumerate(SCXML_CASES):
        (tmp_path / f"doc{i}").mkdir()
        path = tmp_path / f"doc{i}" / "doc.scxml"
        path.write_bytes(content)
        inputs.append((SCXML_COMMANDS, path))
    bomb_device = DEVICE.replace("x: 0", "x: " + BOMB)
    inputs.append(
        (CELL_COMMANDS, write(tmp_path / "cell", {"c.cell.yaml": CELL, "d.yaml": bomb_device}))
    )
    return inputs


def _run(argv: list[str]) -> tuple[int, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(argv, out, err)
    return code, out.getvalue() + err.getvalue()


def test_every_command_refuses_every_broken_file(tmp_path: Path) -> None:
    """Each command given a broken file exits 1 naming the file, with no traceback.

    The file named may be the CSV pair's data or recovery file, or the device a cell
    includes: the text must name a file in the input's directory.
    """
    failures = []
    for commands, path in _broken_inputs(tmp_path):
        for command in commands:
            argv = [a.replace("OUT", str(path.parent / "out")) for a in command] + [str(path)]
            code, text = _run(argv)
            if code != 1 or f"{path.parent}/" not in text or "Traceback" in text:
                failures.append((argv, code, text[-300:]))
            assert not (path.parent / "out").exists(), argv
    assert failures == []


@pytest.mark.parametrize(
    "command", [*DEVICE_COMMANDS, *SCXML_COMMANDS, *CELL_COMMANDS], ids=lambda c: " ".join(c[:2])
)
def test_missing_file_exits_2(tmp_path: Path, command: list[str]) -> None:
    """Every command given a file that does not exist exits 2 and names it."""
    missing = tmp_path / "nowhere.yaml"
    argv = [a.replace("OUT", str(tmp_path / "out")) for a in command] + [str(missing)]
    code, text = _run(argv)
    assert (code, "nowhere.yaml" in text, "Traceback" in text) == (2, True, False), text


# -- check: the indexes and limits behind its speed ---------------------------------------------

EVENTS = ["go", "error", "error.execution", "error.execution.deep", "a.b", ".x", "x..y", "*"]
DESCRIPTORS = [*EVENTS, "error.*", "error.execution.*", "a", "a.*", ".*", "x.", "x.*", "err"]


def test_descriptor_index_agrees_with_name_match() -> None:
    """The descriptors check looks up for an event are exactly those name_match accepts."""
    _matching = RULES._matching
    from statectl.kernel.semantics import name_match

    disagree = [
        (d, e) for d in DESCRIPTORS for e in EVENTS if name_match([d], e) != (d in _matching(e))
    ]
    assert disagree == []


def test_c403_compares_at_most_the_row_limit(tmp_path: Path) -> None:
    """Beyond MAX_OVERLAP_ROWS rows for one state and event, C403 warns once at the limit."""
    check_paths, MAX_OVERLAP_ROWS = RULES.check_paths, RULES.MAX_OVERLAP_ROWS

    rows = MAX_OVERLAP_ROWS + 50
    text = DEVICE.replace(
        "events:\n",
        "events:\n"
        + "".join(f"  - {{event: go, old: A, new: B, guard: x == {i}}}\n" for i in range(rows)),
    )
    path = write(tmp_path, {"d.yaml": text})
    found = [d for d in check_paths([str(path)]) if d.code == "C403"]
    assert [(d.severity, d.where.line, str(MAX_OVERLAP_ROWS) in d.message) for d in found] == [
        (Severity.WARNING, 10 + MAX_OVERLAP_ROWS, True)
    ]


def test_guard_too_deep_to_walk_is_not_proven() -> None:
    """A guard nested past the recursion limit is "not proven" exclusive, not a crash."""
    from statectl.front.rules.guards import guards_exclusive

    assert guards_exclusive("not " * 5000 + "x", "x") is False
    assert guards_exclusive("x == 1", "x == 2") is True


def test_c404_names_at_most_the_listed_events(tmp_path: Path) -> None:
    """A state missing more than MAX_LISTED events names that many and counts the rest."""
    check_paths, MAX_LISTED = RULES.check_paths, RULES.MAX_LISTED

    extra = MAX_LISTED + 5
    text = DEVICE + "".join(f"  - {{event: e{i}, old: B, new: B}}\n" for i in range(extra))
    path = write(tmp_path, {"d.yaml": text})
    found = [d for d in check_paths([str(path)]) if d.code == "C404" and "'A'" in d.message]
    assert len(found) == 1
    listed = found[0].message.split(" ignores ")[1].split(" and ")[0]
    assert listed.count("'") // 2 == MAX_LISTED
    missed = extra + 1  # every e<i> and 'back'
    assert f"and {missed - MAX_LISTED} more" in found[0].message


def ring(states: int, wrong: str = "") -> str:
    """A device file of ``states`` states in a ring; ``wrong`` replaces one old state."""
    rows = ["device: D", "states:"]
    rows += [f"  - {{state: S{i}, control: event trigger required}}" for i in range(states)]
    rows[2] = "  - {state: S0, control: default}"
    rows.append("events:")
    rows += [f"  - {{event: go, old: S{i}, new: S{(i + 1) % states}}}" for i in range(states)]
    if wrong:
        rows[-1] = rows[-1].replace(f"old: S{states - 1}", f"old: {wrong}")
    return "\n".join(rows) + "\n"


def test_hints_stay_short_and_still_suggest(tmp_path: Path) -> None:
    """In a 1,000-state file a wrong name's hint lists 20 names, counts the rest, and the
    did-you-mean still finds the close one."""
    chart, diags = load_and_build(write(tmp_path, {"d.yaml": ring(1000, "S99x")}))
    assert chart is None
    found = [d for d in diags if d.code == "B201"]
    assert len(found) == 1
    assert found[0].hint.startswith("did you mean 'S99'?")
    assert found[0].hint.endswith("and 980 more")


def test_scxml_unknown_target_hint_stays_short() -> None:
    """An SCXML transition to an unknown state names 20 known states and counts the rest."""
    states = "".join(f'<state id="s{i}"><transition target="nowhere"/></state>' for i in range(300))
    chart, diags = read_scxml(f"{SCXML_HEAD}>{states}</scxml>")
    assert chart is None
    hints = {d.hint for d in diags if d.code == "S605"}
    assert len(hints) == 1
    assert hints.pop().endswith("and 280 more")


def test_default_loader_is_libyaml_when_present() -> None:
    """With PyYAML built on libyaml, files are parsed by the C parser (issue 10)."""
    from statectl.front.tables import safeyaml

    want = yaml.CSafeLoader if getattr(yaml, "__with_libyaml__", False) else yaml.SafeLoader
    assert safeyaml._Loader.__base__ is want  # with YAML 1.2 exponent floats added


@pytest.mark.parametrize("was_on", [True, False], ids=["collector-on", "collector-off"])
def test_gc_paused_restores_the_collector(was_on: bool) -> None:
    """A load pauses the cyclic collector and leaves it as it found it, also on error."""
    import gc

    from statectl.front.tables.bulk import gc_paused

    before = gc.isenabled()
    (gc.enable if was_on else gc.disable)()
    try:
        with pytest.raises(ValueError), gc_paused():
            assert not gc.isenabled()
            raise ValueError("a load that fails")
        assert gc.isenabled() is was_on
    finally:
        (gc.enable if before else gc.disable)()
