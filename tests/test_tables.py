"""The device tables: every loader and saver, on the paper's Motor."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from openpyxl import load_workbook  # type: ignore[import-untyped, unused-ignore]  # untyped

from statectl.front.builder.build import build
from statectl.front.tables import (
    DeviceTables,
    Format,
    RecoveryRow,
    dump,
    dump_csv,
    format_of,
    load,
    save,
    strip_locations,
)
from statectl.front.tables.literals import format_literal, parse_literal
from statectl.front.tables.md_io import escape, split_row, unescape
from statectl.front.tables.schema import flat_tables
from statectl.front.tables.xlsx_io import dump_xlsx
from statectl.kernel.errors import Location
from statectl.kernel.model import ControlKind, EventKind

MOTOR = Path(__file__).resolve().parent.parent / "examples" / "motor"
MOTOR_YAML = MOTOR / "motor.yaml"


def motor() -> DeviceTables:
    tables, diags = load(MOTOR_YAML)
    assert tables is not None, diags
    return tables


def test_motor_yaml_loads_without_diagnostics() -> None:
    """The paper's Motor is a clean device file."""
    tables, diags = load(MOTOR_YAML)
    assert diags == []
    assert tables is not None
    assert tables.device == "Motor"
    assert [s.state for s in tables.states] == ["Blocked", "Moving", "Returning"]
    assert len(tables.events) == 6


def test_motor_yaml_has_its_recovery_rows() -> None:
    """The Motor's Recovery table takes a resumed Moving through Error and redoes Returning."""
    lines = MOTOR_YAML.read_text(encoding="utf-8").splitlines()
    moving = lines.index("  - state: Moving", lines.index("recovery:")) + 1
    returning = lines.index("  - state: Returning", lines.index("recovery:")) + 1
    data = {"detail": "resumed after a restart"}
    assert motor().recovery == (
        RecoveryRow("Moving", "Error", data, Location(str(MOTOR_YAML), moving)),
        RecoveryRow("Returning", origin=Location(str(MOTOR_YAML), returning), redo=True),
    )


@pytest.mark.parametrize(
    ("state", "controls"),
    [
        ("Blocked", (ControlKind.DEFAULT,)),
        ("Moving", (ControlKind.TRIGGER, ControlKind.MONITORING)),
        ("Returning", (ControlKind.TRIGGER,)),
    ],
)
def test_motor_controls(state: str, controls: tuple[ControlKind, ...]) -> None:
    """The control column reads one value or a list, in the order written."""
    row = next(s for s in motor().states if s.state == state)
    assert row.controls == controls


@pytest.mark.parametrize(
    ("event", "kind", "api", "guard"),
    [
        ("Movement", EventKind.COMMAND, "Movement", ""),
        ("Movement completion", EventKind.COMPLETION, "Movement", ""),
        ("Initialization", EventKind.COMMAND, "Initialization", "previous == 'Moving'"),
        ("Error", EventKind.FAULT, "Error", ""),
    ],
)
def test_motor_event_columns(event: str, kind: EventKind, api: str, guard: str) -> None:
    """Kind, api and guard of an event row are read as written."""
    row = next(e for e in motor().events if e.event == event)
    assert (row.kind, row.api, row.guard) == (kind, api, guard)


@pytest.mark.parametrize(
    ("which", "index", "line"),
    [("states", 0, 9), ("states", 1, 17), ("states", 2, 26), ("events", 0, 35), ("events", 5, 66)],
)
def test_yaml_rows_keep_their_line(which: str, index: int, line: int) -> None:
    """Every YAML row points at the line where its mapping starts."""
    row = getattr(motor(), which)[index]
    assert row.where == Location(str(MOTOR_YAML), line)


@pytest.mark.parametrize(
    "path",
    [
        "motor.yaml",
        "motor.states.csv",
        "motor.events.csv",
        "motor.recovery.csv",
        ".",
        "motor.xlsx",
    ],
)
def test_shipped_motor_files_equal_the_yaml(path: str) -> None:
    """The shipped CSV files and workbook hold exactly the Motor of motor.yaml, recovery too."""
    tables, diags = load(MOTOR / path)
    assert diags == []
    assert tables is not None
    assert strip_locations(tables) == strip_locations(motor())


@pytest.mark.parametrize("fmt", ["yaml", "csv", "xlsx", "md"])
def test_save_then_load_is_lossless(tmp_path: Path, fmt: str) -> None:
    """Each format gives back the tables it was given, locations aside."""
    target = tmp_path / f"motor.{fmt}"
    written = save(motor(), target, fmt)
    assert all(p.exists() for p in written)
    tables, diags = load(written[0])
    assert diags == []
    assert tables is not None
    assert strip_locations(tables) == strip_locations(motor())


@pytest.mark.parametrize("fmt", ["yaml", "csv", "xlsx", "md"])
def test_motor_builds_the_same_chart_in_every_format(tmp_path: Path, fmt: str) -> None:
    """Whatever the format, the Motor builds into the same chart (origins aside)."""
    written = save(motor(), tmp_path / f"motor.{fmt}", fmt)
    tables, _ = load(written[0])
    assert tables is not None
    chart, diags = build(strip_locations(tables))
    expected, _ = build(strip_locations(motor()))
    assert diags == []
    assert chart == expected


def test_csv_rows_point_at_their_line() -> None:
    """CSV locations count the device comment and the header."""
    tables, _ = load(MOTOR / "motor.states.csv")
    assert tables is not None
    assert [s.where.line for s in tables.states] == [3, 4, 5]


def test_xlsx_rows_name_sheet_and_row() -> None:
    """Workbook locations name the sheet and the spreadsheet row."""
    tables, _ = load(MOTOR / "motor.xlsx")
    assert tables is not None
    assert tables.events[0].where == Location(str(MOTOR / "motor.xlsx"), 2, sheet="Events")


def test_md_rows_point_at_their_line() -> None:
    """Markdown locations are the line of the table row."""
    from statectl.front.tables.md_io import read_md

    text = dump(motor(), "md")
    assert isinstance(text, str)
    tables, _ = read_md(text, "m.md", "m")
    assert tables is not None
    line = tables.events[0].where.line
    assert line is not None
    assert text.split("\n")[line - 1].startswith("| Movement |")


def test_csv_without_device_comment_takes_the_file_name(tmp_path: Path) -> None:
    """Absent '# device:', the CSV pair's NAME is the device."""
    states, events, _, _ = dump_csv(motor())
    (tmp_path / "arm.states.csv").write_text(states.split("\n", 1)[1])
    (tmp_path / "arm.events.csv").write_text(events.split("\n", 1)[1])
    tables, diags = load(tmp_path / "arm.states.csv")
    assert diags == []
    assert tables is not None
    assert tables.device == "arm"


def test_csv_columns_in_any_order_and_case(tmp_path: Path) -> None:
    """CSV headers are matched by name, leniently, in any order."""
    (tmp_path / "d.states.csv").write_text("State,Control\nIdle,Default\n")
    (tmp_path / "d.events.csv").write_text("New State,Old State,Event\nIdle,Idle,Tick\n")
    tables, diags = load(tmp_path)
    assert diags == []
    assert tables is not None
    assert tables.states[0].controls == (ControlKind.DEFAULT,)
    assert (tables.events[0].old, tables.events[0].new, tables.events[0].kind) == (
        "Idle",
        "Idle",
        EventKind.COMMAND,
    )


def test_data_round_trips_through_every_format(tmp_path: Path) -> None:
    """Data values keep their YAML type in every format."""
    data: tuple[tuple[str, object], ...] = (
        ("speed", 1.5),
        ("count", 3),
        ("on", True),
        ("label", "yes"),
        ("nothing", None),
        ("path", (1, "a, b", (2.0,))),
    )
    tables = DeviceTables("Arm", motor().states, motor().events, data)
    for fmt in ("yaml", "csv", "xlsx", "md"):
        written = save(tables, tmp_path / f"arm.{fmt}", fmt)
        back, diags = load(written[0])
        assert diags == [], fmt
        assert back is not None
        assert back.data == data, fmt


@pytest.mark.parametrize(
    ("data", "recovery", "written"),
    [
        (True, True, ["states", "events", "data", "recovery"]),
        (False, True, ["states", "events", "recovery"]),
        (True, False, ["states", "events", "data"]),
        (False, False, ["states", "events"]),
    ],
)
def test_csv_md_and_xlsx_write_the_same_tables(
    data: bool, recovery: bool, written: list[str]
) -> None:
    """The flat formats each write flat_tables' tables: data and recovery only with rows."""
    m = motor()
    extra = (("speed", 1.5),) if data else ()
    tables = DeviceTables("Motor", m.states, m.events, extra, recovery=m.recovery * recovery)
    assert [name for name, _, _ in flat_tables(tables)] == written
    files = dict(zip(("states", "events", "data", "recovery"), dump_csv(tables), strict=True))
    assert [name for name, text in files.items() if text is not None] == written
    md = dump(tables, "md")
    assert isinstance(md, str)
    assert [line[3:].lower() for line in md.splitlines() if line.startswith("## ")] == written
    book = load_workbook(io.BytesIO(dump_xlsx(tables)), read_only=True)
    assert [name.lower() for name in book.sheetnames] == [*written, "device"]


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (1, "1"),
        ("1", "'1'"),
        (True, "true"),
        (None, "null"),
        ("a, b", "'a, b'"),
        ((1, 2), "[1, 2]"),
    ],
)
def test_format_literal(value: object, text: str) -> None:
    """Data cells hold YAML flow literals that read back as the same value."""
    assert format_literal(value) == text
    assert parse_literal(text, Location(), []) == value


@pytest.mark.parametrize("text", ["a|b", "a\\b", "line\nbreak", "\\|", "x\\n", "cr\rlf"])
def test_md_escape_round_trips(text: str) -> None:
    """Pipes, backslashes and line breaks survive a Markdown cell."""
    cells = split_row("| " + escape(text) + " | z |")
    assert [unescape(c) for c in cells] == [text, "z"]


@pytest.mark.parametrize(
    ("name", "fmt"),
    [
        ("a.yaml", Format.YAML),
        ("a.YML", Format.YAML),
        ("a.states.csv", Format.CSV),
        ("a.xlsx", Format.XLSX),
        ("a.md", Format.MD),
        ("a.txt", None),
    ],
)
def test_format_of(name: str, fmt: Format | None) -> None:
    """The format comes from the file name."""
    assert format_of(name) is fmt


def test_dump_yaml_reads_like_the_motor() -> None:
    """The YAML writer puts rows in block style and name lists in flow style."""
    text = dump(motor(), "yaml")
    assert isinstance(text, str)
    assert "- event: Movement\n" in text
    assert "control: [event trigger required, monitoring required]" in text


def test_dump_csv_refuses_a_single_text() -> None:
    """A CSV device is several files, so dump() sends the caller to dump_csv()."""
    with pytest.raises(ValueError, match="dump_csv"):
        dump(motor(), "csv")


def test_csv_save_to_directory_uses_the_device_name(tmp_path: Path) -> None:
    """Saving CSV into a directory names the files after the device."""
    written = save(motor(), tmp_path, "csv")
    assert sorted(p.name for p in written) == [
        "Motor.events.csv",
        "Motor.recovery.csv",
        "Motor.states.csv",
    ]


def test_save_replaces_an_existing_file_and_leaves_no_temporaries(tmp_path: Path) -> None:
    """An atomic save replaces the old file and leaves only the target behind."""
    target = tmp_path / "m.yaml"
    target.write_text("old")
    save(motor(), target)
    assert [p.name for p in tmp_path.iterdir()] == ["m.yaml"]
    assert target.read_text().startswith("# Device tables of Motor")


def test_xlsx_text_starting_with_equals_stays_text(tmp_path: Path) -> None:
    """A cell whose text starts with '=' is stored as text, not as a formula."""
    m = motor()
    from dataclasses import replace

    tables = replace(m, events=(replace(m.events[0], condition="=SUM(A1)"), *m.events[1:]))
    save(tables, tmp_path / "m.xlsx")
    back, diags = load(tmp_path / "m.xlsx")
    assert diags == []
    assert back is not None
    assert back.events[0].condition == "=SUM(A1)"


DOCS = Path(__file__).resolve().parent.parent / "docs" / "tables.md"


def doc_blocks(language: str) -> list[str]:
    text = DOCS.read_text(encoding="utf-8")
    return [b.split("\n", 1)[1] for b in text.split("```")[1::2] if b.startswith(language + "\n")]


def test_docs_yaml_example_loads_as_the_motor(tmp_path: Path) -> None:
    """The YAML Motor in docs/tables.md is a valid device file with the Motor's states."""
    path = tmp_path / "doc.yaml"
    path.write_text(doc_blocks("yaml")[0], encoding="utf-8")
    tables, diags = load(path)
    assert diags == []
    assert tables is not None
    assert [(s.state, s.controls, s.ignore) for s in tables.states] == [
        (s.state, s.controls, s.ignore) for s in motor().states
    ]
    assert strip_locations(tables).events == strip_locations(motor()).events[:4]


def test_docs_csv_example_loads_as_the_motor(tmp_path: Path) -> None:
    """The CSV files in docs/tables.md hold the Motor's states, all its events and recovery."""
    states, events, recovery = doc_blocks("csv")
    (tmp_path / "motor.states.csv").write_text(states, encoding="utf-8")
    (tmp_path / "motor.events.csv").write_text(events, encoding="utf-8")
    (tmp_path / "motor.recovery.csv").write_text(recovery, encoding="utf-8")
    tables, diags = load(tmp_path)
    assert diags == []
    assert tables is not None
    assert strip_locations(tables).events == strip_locations(motor()).events
    assert strip_locations(tables).recovery == strip_locations(motor()).recovery
    assert [s.state for s in tables.states] == ["Blocked", "Moving", "Returning"]


def test_docs_recovery_example_is_the_motors(tmp_path: Path) -> None:
    """The Recovery table in docs/tables.md is the one motor.yaml ships."""
    block = next(b for b in doc_blocks("yaml") if "\nrecovery:\n" in b)
    two_tables = MOTOR_YAML.read_text(encoding="utf-8").split("\nrecovery:\n")[0]
    path = tmp_path / "doc.yaml"
    path.write_text(two_tables + "\n" + block, encoding="utf-8")
    tables, diags = load(path)
    assert diags == []
    assert tables is not None
    assert strip_locations(tables).recovery == strip_locations(motor()).recovery


def test_docs_list_every_code() -> None:
    """Every T1xx and B2xx code the code defines is documented in docs/tables.md."""
    from statectl.front.builder.build import CODES as BUILD_CODES
    from statectl.front.tables import CODES as TABLE_CODES

    text = DOCS.read_text(encoding="utf-8")
    assert [c for c in (*TABLE_CODES, *BUILD_CODES) if f"| {c} |" not in text] == []


# --- the Recovery table ------------------------------------------------------------------

RECOVERY = (
    RecoveryRow("Moving", "Error", {"detail": "resumed after a restart", "tries": [1, 2.5]}),
    RecoveryRow("Returning", "Error completion"),
    RecoveryRow("Blocked", "Initialization", "a, b | c"),
    RecoveryRow("Homing", redo=True),
)


@pytest.mark.parametrize("fmt", ["yaml", "csv", "xlsx", "md"])
def test_recovery_round_trips_through_every_format(tmp_path: Path, fmt: str) -> None:
    """Recovery rows keep their order and their data's YAML types in every format."""
    tables = DeviceTables("Arm", motor().states, motor().events, recovery=RECOVERY)
    written = save(tables, tmp_path / f"arm.{fmt}", fmt)
    back, diags = load(written[0])
    assert diags == []
    assert back is not None
    assert strip_locations(back).recovery == RECOVERY


@pytest.mark.parametrize(
    ("fmt", "marker"),
    [("yaml", "recovery:"), ("csv", "recovery.csv"), ("xlsx", "Recovery"), ("md", "## Recovery")],
)
def test_an_empty_recovery_table_is_left_out(tmp_path: Path, fmt: str, marker: str) -> None:
    """Without recovery rows no format writes a Recovery table (file, sheet or section)."""
    tables = DeviceTables("Arm", motor().states, motor().events)
    written = save(tables, tmp_path / f"arm.{fmt}", fmt)
    if fmt == "xlsx":
        import openpyxl

        found = " ".join(openpyxl.load_workbook(written[0]).sheetnames)
    elif fmt == "csv":
        found = " ".join(p.name for p in tmp_path.iterdir())
    else:
        found = written[0].read_text(encoding="utf-8")
    assert marker not in found


def test_csv_save_without_recovery_removes_a_stale_recovery_file(tmp_path: Path) -> None:
    """Saving tables without recovery rows over CSV files that had them loads back without."""
    save(motor(), tmp_path / "motor.states.csv")
    assert (tmp_path / "motor.recovery.csv").exists()
    tables = DeviceTables("Motor", motor().states, motor().events)
    save(tables, tmp_path / "motor.states.csv")
    back, diags = load(tmp_path / "motor.states.csv")
    assert diags == []
    assert back is not None
    assert (back.recovery, (tmp_path / "motor.recovery.csv").exists()) == ((), False)


@pytest.mark.parametrize(
    ("fmt", "where"),
    [
        ("yaml", Location("arm.yaml", None)),  # line: found below
        ("csv", Location("arm.recovery.csv", 4)),  # after the device comment and the header
        ("xlsx", Location("arm.xlsx", 3, sheet="Recovery")),  # row 1 is the header
        ("md", Location("arm.md", None)),
    ],
)
def test_recovery_rows_point_at_their_row(tmp_path: Path, fmt: str, where: Location) -> None:
    """A recovery row's origin is its file and line, or its sheet and row."""
    tables = DeviceTables("arm", motor().states, motor().events, recovery=RECOVERY)
    written = save(tables, tmp_path / f"arm.{fmt}", fmt)
    back, _ = load(written[0])
    assert back is not None
    origin = back.recovery[1].origin
    assert (Path(origin.file).name, origin.sheet) == (where.file, where.sheet)
    if fmt in ("yaml", "md"):
        assert origin.line is not None
        line = written[0].read_text(encoding="utf-8").split("\n")[origin.line - 1]
        assert "Returning" in line
    else:
        assert origin.line == where.line


def test_dump_yaml_writes_recovery_last_with_flow_data() -> None:
    """The YAML writer puts recovery after the events, its data in flow style, as in the Motor."""
    text = dump(motor(), "yaml")
    assert isinstance(text, str)
    assert text.endswith(
        "recovery:\n- state: Moving\n  event: Error\n  data: {detail: resumed after a restart}\n"
        "- state: Returning\n  redo: yes\n"
    )


@pytest.mark.parametrize(
    ("fmt", "marker"),
    [("yaml", "redo:"), ("csv", ",redo"), ("xlsx", "redo"), ("md", "| redo |")],
)
@pytest.mark.parametrize("redo", [False, True])
def test_the_redo_column_is_written_only_when_a_row_uses_it(
    tmp_path: Path, fmt: str, marker: str, redo: bool
) -> None:
    """Event rows alone keep the Recovery table's three columns; a redo row adds ``redo``."""
    rows = RECOVERY if redo else RECOVERY[:3]
    tables = DeviceTables("Arm", motor().states, motor().events, recovery=rows)
    written = save(tables, tmp_path / f"arm.{fmt}", fmt)
    if fmt == "xlsx":
        import openpyxl

        sheet = openpyxl.load_workbook(written[0])["Recovery"]
        found = " ".join(str(c.value) for c in sheet[1])
    elif fmt == "csv":
        found = (tmp_path / "arm.recovery.csv").read_text(encoding="utf-8")
    else:
        found = written[0].read_text(encoding="utf-8")
    assert (marker in found) is redo


@pytest.mark.parametrize(
    ("cell", "redo"),
    [("yes", True), ("Yes", True), ("true", True), ("TRUE", True), ("no", False), ("false", False)],
)
def test_redo_cells_read_yes_no_true_false(tmp_path: Path, cell: str, redo: bool) -> None:
    """The redo column takes yes/no and true/false in any case; no is an event row."""
    event = "" if redo else "Error"
    (tmp_path / "m.states.csv").write_text(
        (MOTOR / "motor.states.csv").read_text(encoding="utf-8"), encoding="utf-8"
    )
    (tmp_path / "m.events.csv").write_text(
        (MOTOR / "motor.events.csv").read_text(encoding="utf-8"), encoding="utf-8"
    )
    (tmp_path / "m.recovery.csv").write_text(
        f"state,event,redo\nMoving,{event},{cell}\n", encoding="utf-8"
    )
    tables, diags = load(tmp_path / "m.states.csv")
    assert diags == []
    assert tables is not None
    assert [(r.event, r.redo) for r in tables.recovery] == [(event, redo)]
