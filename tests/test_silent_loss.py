"""Nothing a user wrote is lost silently: carried, refused with a diagnostic, or reported."""

from __future__ import annotations

import io
import re
import zipfile
from pathlib import Path

import openpyxl
import pytest

from statectl.channels.cli import main
from statectl.channels.cli.run import run
from statectl.front.builder.build import build, load_and_build
from statectl.front.tables import load
from statectl.front.tables.yaml_io import read_yaml
from statectl.kernel.errors import Severity
from statectl.run.devices.twin import SimTwin
from statectl.run.runtime import SimClock
from statectl.run.system import DeviceSetup, System

ROOT = Path(__file__).resolve().parents[1]
MOTOR = ROOT / "examples" / "motor" / "motor.yaml"


# --- XLSX formulas ----------------------------------------------------------------------


def _workbook(path: Path, guard: str) -> None:
    wb = openpyxl.Workbook()
    states = wb.active
    assert states is not None
    states.title = "States"
    states.append(["state", "control"])
    states.append(["Idle", "default"])
    states.append(["Busy", ""])
    events = wb.create_sheet("Events")
    events.append(["event", "guard", "old", "new"])
    events.append(["Go", guard, "Idle", "Busy"])
    events.append(["Done", "", "Busy", "Idle"])
    wb.save(path)


def _cache(path: Path, cell: str, value: str) -> None:
    """Store ``value`` as the saved value of formula ``cell``, as a spreadsheet program does."""
    with zipfile.ZipFile(path) as z:
        parts = {n: z.read(n) for n in z.namelist()}
    for name, body in parts.items():
        if name.startswith("xl/worksheets/") and f'r="{cell}"'.encode() in body:
            text = body.decode()
            text = re.sub(
                rf'<c r="{cell}"([^>]*)><f>(.*?)</f><v\s*/?>(</v>)?',
                rf'<c r="{cell}"\1 t="str"><f>\2</f><v>{value}</v>',
                text,
            )
            text = re.sub(
                rf'<c r="{cell}"([^>]*)><f>(.*?)</f></c>',
                rf'<c r="{cell}"\1 t="str"><f>\2</f><v>{value}</v></c>',
                text,
            )
            parts[name] = text.encode()
    with zipfile.ZipFile(path, "w") as z:
        for name, body in parts.items():
            z.writestr(name, body)


def test_a_formula_without_a_saved_value_is_refused(tmp_path: Path) -> None:
    """A formula cell with no saved value is T124 naming file, sheet and cell, not empty."""
    path = tmp_path / "d.xlsx"
    _workbook(path, '="limit" & " > 1"')
    tables, diags = load(path)
    assert tables is None
    assert [d.code for d in diags] == ["T124"]
    d = diags[0]
    assert (d.where.file, d.where.sheet, d.where.line) == (str(path), "Events", 2)
    assert "cell B2" in d.message


def test_a_formula_with_its_saved_value_reads_that_value(tmp_path: Path) -> None:
    """A formula the spreadsheet program computed reads as its saved value."""
    path = tmp_path / "d.xlsx"
    _workbook(path, '="previous" & " == None"')
    _cache(path, "B2", "previous == None")
    tables, diags = load(path)
    assert tables is not None, diags
    assert not diags
    assert tables.events[0].guard == "previous == None"


# --- duplicate rows that disagree -------------------------------------------------------

BASE = """\
device: D
states:
  - {state: A, control: default}
  - {state: B, control: event trigger required}
events:
  - {event: go, old: A, new: B, api: Go}
  - {event: back, old: B, new: A, kind: completion, api: Go}
"""


@pytest.mark.parametrize(
    ("row", "code", "word"),
    [
        ("  - {event: go, old: A, new: B, api: Stop}\n", "B206", "api"),
        ("  - {event: go, old: A, new: B, api: Go, kind: fault}\n", "B206", "kind"),
        ("  - {event: go, old: A, new: B, api: Go, assign: 'n = 1'}\n", "B235", "assign"),
        ("  - {event: go, old: A, new: B, api: Go}\n", None, ""),
    ],
)
def test_identical_rows_that_disagree_are_not_merged_silently(
    row: str, code: str | None, word: str
) -> None:
    """Rows for one old + event = new that disagree are an error, not a silent merge."""
    text = BASE.replace("states:", "data:\n  n: 0\nstates:") + row
    tables, diags = read_yaml(text, "d.yaml")
    assert tables is not None and not diags
    chart, found = build(tables)
    errors = [d for d in found if d.severity is Severity.ERROR]
    if code is None:
        assert chart is not None and not errors
        return
    assert chart is None
    assert [d.code for d in errors] == [code]
    assert word in errors[0].message
    assert errors[0].where.line == 10  # the row that disagrees


def test_check_reports_conflicting_api_rows(tmp_path: Path) -> None:
    """statectl check exits 1 for duplicate rows with a conflicting api."""
    path = tmp_path / "d.yaml"
    path.write_text(BASE + "  - {event: go, old: A, new: B, api: Stop}\n")
    out, err = io.StringIO(), io.StringIO()
    assert main(["check", str(path)], out, err) == 1
    assert "B206" in out.getvalue() + err.getvalue()


# --- the batch run's settle limit -------------------------------------------------------


@pytest.mark.parametrize(
    ("limit", "lines", "code", "said", "final"),
    [
        (None, "Movement\n", 0, "", "Blocked"),  # one second settles within the default 60 s
        (5.0, "Movement\n", 0, "", "Blocked"),
        # cut at 0.25 s after the line, and again at the end (0.5 s): left part-way
        (0.25, "Movement\n", 1, "the run ended with device work still in flight", "Moving"),
        # cut at 0.5 s, done by the end's settle at 1 s: nothing acted on it part-way
        (0.5, "Movement\n", 0, "", "Blocked"),
        # +SECONDS lines let the work finish: not a problem
        (0.25, "Movement\n+0.5\n+0.5\n", 0, "", "Blocked"),
        # an event line that comes while the movement is in flight: line 2 acted part-way
        (0.5, "Movement\nError\n", 1, "line 2 came while device work was still in", None),
        (0.1, "Movement\nError\nMovement\n", 1, "lines 2, 3 came while", None),
    ],
)
def test_work_outlasting_a_settle_is_reported_when_it_matters(
    limit: float | None, lines: str, code: int, said: str, final: str | None
) -> None:
    """A batch run whose device work outlasts --settle-limit exits 1 naming the event lines
    that came while it was in flight, or the end that left it part-way; a cut whose
    work finished before the next event line (the limit's time passed) is no problem."""
    out, err = io.StringIO(), io.StringIO()
    got = run(str(MOTOR), settle_limit=limit, events=io.StringIO(lines), out=out, err=err)
    assert got == code, err.getvalue()
    assert ("--settle-limit" in err.getvalue()) is bool(said)
    assert said in err.getvalue()
    if final is not None:
        assert f"final state {final}" in out.getvalue()


def test_a_settle_cut_short_lets_its_limit_pass() -> None:
    """System.settle stops at the limit with the limit's time passed (monitor polls ran),
    and work_pending says the cut work is still due until it is done."""
    chart, _ = load_and_build(MOTOR)
    assert chart is not None
    clock = SimClock()
    system = System([DeviceSetup("Motor", chart, driver=SimTwin(chart, delay=1.0))], clock)
    system.start()
    try:
        system.post("Motor", "Movement")
        system.settle(0.25)
        assert (clock.now(), system.work_pending(), system.settle_cut) == (0.25, True, 1)
        system.settle(1.0)
        assert (clock.now(), system.work_pending(), system.settle_cut) == (1.0, False, 1)
        assert system.subjects["Motor"].configuration == {"Blocked"}
    finally:
        system.close()


def test_the_settle_limit_option_must_be_positive() -> None:
    """--settle-limit 0 is a usage error (exit 2)."""
    out, err = io.StringIO(), io.StringIO()
    assert run(str(MOTOR), settle_limit=0, events=io.StringIO(""), out=out, err=err) == 2
    assert "--settle-limit" in err.getvalue()


def test_the_settle_limit_is_a_run_option(monkeypatch: pytest.MonkeyPatch) -> None:
    """statectl run --settle-limit reaches the run: a short limit exits 1 with the note."""
    monkeypatch.setattr("sys.stdin", io.StringIO("Movement\n"))
    out, err = io.StringIO(), io.StringIO()
    assert main(["run", str(MOTOR), "--settle-limit", "0.25"], out, err) == 1
    assert "--settle-limit" in err.getvalue()


def test_load_and_build_of_the_motor_is_clean() -> None:
    """The shipped Motor builds without errors (the baseline the cases above change)."""
    chart, diags = load_and_build(MOTOR)
    assert chart is not None
    assert not [d for d in diags if d.severity is Severity.ERROR]


# --- the Recovery table through SCXML ---------------------------------------------------


def test_scxml_export_carries_the_motors_recovery_table(tmp_path: Path) -> None:
    """Export then import keeps the Motor's Recovery rules and its chart."""
    from statectl.front.builder.build import load_chart, strip_origins
    from statectl.front.tables import strip_locations

    doc, back = tmp_path / "motor.scxml", tmp_path / "motor.yaml"
    out, err = io.StringIO(), io.StringIO()
    assert main(["scxml", "export", str(MOTOR), "--out", str(doc)], out, err) == 0, err.getvalue()
    assert doc.read_text().count("<statectl:recovery ") == 2
    assert main(["scxml", "import", str(doc), "--out", str(back)], out, err) == 0, err.getvalue()
    original, _ = load(MOTOR)
    again, diags = load(back)
    assert original is not None and again is not None and not diags
    assert strip_locations(again).recovery == strip_locations(original).recovery
    assert strip_origins(load_chart(back)) == strip_origins(load_chart(MOTOR))


@pytest.mark.parametrize(
    ("element", "word"),
    [
        ('<statectl:recovery state="Returning" redo="maybe"/>', "redo"),
        ('<statectl:recovery state="Moving"/>', "neither"),
        ('<statectl:recovery event="Error"/>', "'state'"),
        ('<statectl:recovery state="Moving" event="Error" when="now"/>', "unknown attribute"),
        ('<statectl:recovery state="Moving" event="Error" data="{a: [1"/>', "plain value"),
    ],
)
def test_a_bad_recovery_element_is_refused_on_import(element: str, word: str) -> None:
    """A <statectl:recovery> that is no valid Recovery row is S623, with its line."""
    from statectl.kernel.errors import DiagnosticError
    from statectl.out.scxml.tables_io import export_file, import_text

    text = export_file(MOTOR)
    lines = [ln for ln in text.split("\n") if "<statectl:recovery " not in ln]
    lines.insert(2, "  " + element)
    with pytest.raises(DiagnosticError) as caught:
        import_text("\n".join(lines), "m.scxml")
    found = [d for d in caught.value.diagnostics if d.code == "S623"]
    assert found, caught.value.diagnostics
    assert all(d.where.line == 3 for d in found)
    assert any(word in d.message for d in found), found
