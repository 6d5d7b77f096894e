"""The language server's answers in every text format, asked without the protocol: a CSV pair
and Markdown tables (tests/test_lsp.py speaks LSP to the server over stdio)."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pytest

from statectl.channels.cli import main
from statectl.channels.lsp.complete import complete
from statectl.channels.lsp.documents import FileKind, Project, kind_of
from statectl.channels.lsp.fixes import Change, fixes
from statectl.channels.lsp.navigate import definition, hover, rename
from statectl.front.rules import check_paths
from statectl.front.tables import dump, load

ROOT = Path(__file__).resolve().parents[1]
MOTOR = ROOT / "examples" / "motor"


def at(text: str, needle: str, offset: int = 0) -> tuple[int, int]:
    for n, line in enumerate(text.split("\n")):
        if needle in line:
            return n, line.index(needle) + offset
    raise AssertionError(needle)


def apply(text: str, changes: list[Change]) -> str:
    lines = text.split("\n")
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line) + 1)
    for a, b, c, d, new in sorted(changes, reverse=True):
        text = text[: offsets[a] + b] + new + text[offsets[c] + d :]
    return text


@pytest.fixture
def pair(tmp_path: Path) -> Path:
    """The Motor as a CSV pair (with its recovery table) in a scratch folder."""
    for p in MOTOR.glob("motor.*.csv"):
        shutil.copy(p, tmp_path / p.name)
    return tmp_path


@pytest.fixture
def markdown(tmp_path: Path) -> Path:
    tables, _ = load(MOTOR / "motor.yaml")
    assert tables is not None
    path = tmp_path / "motor.md"
    path.write_text(str(dump(tables, "md")), encoding="utf-8")
    return path


KINDS = [
    ("d.yaml", "device: M\nstates: []\nevents: []\n", FileKind.DEVICE),
    ("c.yaml", "devices: {a: a.yaml}\nlinks: []\n", FileKind.CELL),
    ("r.yaml", "devices:\n  M: {driver: sim-motor}\n", FileKind.RUN_CONFIG),
    ("r.yaml", "dashboard: {port: 0}\n", FileKind.RUN_CONFIG),
    ("x.yaml", "[not, a, mapping]\n", FileKind.DEVICE),
    ("x.yaml", "devices: [\n", FileKind.DEVICE),
    ("m.csv", "state\nA\n", FileKind.DEVICE),
    ("m.md", "# Device: M\n", FileKind.DEVICE),
]


@pytest.mark.parametrize(("name", "text", "kind"), KINDS)
def test_file_kind(name: str, text: str, kind: FileKind) -> None:
    """A file is a device, a cell or a run config as check and verify tell them apart."""
    assert kind_of(name, text) is kind


def test_rename_in_a_csv_pair_changes_both_files_and_only_names(pair: Path) -> None:
    """Renaming Moving from the events file renames its state row, its old/new cells, the
    guard's quoted name and the recovery row, and leaves the prose (condition) alone."""
    project = Project((str(pair),))
    events = pair / "motor.events.csv"
    doc = project.document(str(events))
    assert doc is not None
    found = rename(project, doc, *at(doc.text, ",,Moving,Blocked,", 3), "Travelling")
    assert isinstance(found, dict)
    assert {Path(p).name for p in found} == {
        "motor.states.csv",
        "motor.events.csv",
        "motor.recovery.csv",
    }
    for path, spans in found.items():
        text = Path(path).read_text(encoding="utf-8")
        after = apply(text, [(s.line, s.start, s.line, s.end, "Travelling") for s in spans])
        Path(path).write_text(after, encoding="utf-8")
    text = events.read_text(encoding="utf-8")
    assert "previous == 'Travelling'" in text and "the previous state was Moving" in text
    assert [d.code for d in check_paths([str(events)]) if d.severity.value == "error"] == []
    assert ",Travelling," in (pair / "motor.states.csv").read_text(encoding="utf-8")


def test_definition_and_hover_across_a_csv_pair(pair: Path) -> None:
    """A state named in the events file is defined in the states file; hover shows its row."""
    project = Project()
    doc = project.document(str(pair / "motor.events.csv"))
    assert doc is not None
    where = at(doc.text, ",,Returning,Blocked,", 3)
    found = definition(project, doc, *where)
    assert found is not None and found[1].row is not None and found[1].row.table == "states"
    assert Path(found[0]).name == "motor.states.csv"
    states = project.document(str(pair / "motor.states.csv"))
    assert states is not None
    event = definition(project, states, *at(states.text, "Movement completion, Init", 2))
    assert event is not None and Path(event[0]).name == "motor.events.csv"
    text = hover(project, doc, *where)
    assert text is not None and "**state `Returning`** of motor.states.csv" in text


def c404_fix(path: Path, text: str) -> str:
    """The edited text after the quick fix for the C404 the file now has."""
    path.write_text(text, encoding="utf-8")
    (c404,) = [d for d in check_paths([str(path)]) if d.code == "C404"]
    doc = Project().document(str(path))
    assert doc is not None
    ((_, changes),) = fixes(doc, "C404", c404.message, (c404.where.line or 1) - 1)
    return apply(text, changes)


def test_ignore_fix_in_csv_keeps_the_cell_quoted(pair: Path) -> None:
    """In a CSV file the ignore cell is rewritten, quoted: C404 is gone, nothing else changes."""
    states = pair / "motor.states.csv"
    text = states.read_text(encoding="utf-8").replace("Initialization completion, Error, ", "", 1)
    after = c404_fix(states, text)
    assert (
        '"Movement completion, Initialization, Error completion, Initialization completion, Error"'
        in after
    )
    states.write_text(after, encoding="utf-8")
    assert [d.code for d in check_paths([str(states)]) if d.severity.value != "info"] == []


def test_ignore_fix_in_markdown(markdown: Path) -> None:
    """In Markdown the ignore cell is rewritten in place: C404 is gone."""
    text = markdown.read_text(encoding="utf-8")
    row = next(line for line in text.split("\n") if "| Blocked |" in line)
    edited = text.replace(row, row.replace(", Error, ", ", ", 1))
    after = c404_fix(markdown, edited)
    markdown.write_text(after, encoding="utf-8")
    assert [d.code for d in check_paths([str(markdown)]) if d.severity.value != "info"] == []


def test_ignore_fix_adds_the_key_to_a_yaml_row(tmp_path: Path) -> None:
    """A YAML row without an ignore key gets one, in its own style (here a flow mapping)."""
    text = (
        "device: D\nstates:\n  - {state: A, control: default, ignore: [Back]}\n  - {state: B}\n"
        "events:\n  - {event: Go, old: A, new: B}\n  - {event: Back, old: B, new: A}\n"
    )
    after = c404_fix(tmp_path / "d.yaml", text)
    assert "  - {state: B, ignore: [Go]}\n" in after


COMPLETIONS = [
    ("motor.events.csv", ",,Blocked,Moving,", 3, {"Blocked", "Moving", "Returning"}),
    ("motor.events.csv", "event,condition", 2, {"event", "old", "new", "guard", "kind"}),
    ("motor.states.csv", '"Movement completion, Init', 2, {"all others", "Error"}),
    ("motor.md", "| command | Movement |", 3, {"command", "completion", "fault"}),
    ("motor.md", "| event | condition |", 3, {"event", "old", "new"}),
]


@pytest.mark.parametrize(("name", "needle", "offset", "some"), COMPLETIONS)
def test_completion_in_csv_and_markdown(
    pair: Path, markdown: Path, name: str, needle: str, offset: int, some: set[str]
) -> None:
    """The column under the cursor decides: states in old, events in ignore, the kinds in
    kind, the column names in a header."""
    doc = Project().document(str(pair / name if name.endswith(".csv") else markdown))
    assert doc is not None
    labels = {label for label, _ in complete(Project(), doc, *at(doc.text, needle, offset))}
    assert some <= labels, labels


def test_lsp_without_pygls_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the lsp extra, statectl lsp says what to install, in one line, exit 2."""
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "pygls" else real(name, *a)
    )
    err = io.StringIO()
    assert main(["lsp"], io.StringIO(), err) == 2
    assert err.getvalue() == (
        "statectl lsp: the language server needs pygls: pip install 'statectl[lsp]'\n"
    )


SOURCES = [
    MOTOR / "motor.yaml",
    MOTOR / "motor.states.csv",
    MOTOR / "motor.events.csv",
    MOTOR / "drivers.yaml",
    ROOT / "examples" / "pick-and-place" / "cell.yaml",
]


def damaged(text: str) -> list[str]:
    """The text cut short at many places, and with a stray quote, bracket, pipe or comma."""
    step = max(len(text) // 12, 1)
    cuts = [text[:n] for n in range(0, len(text), step)]
    stray = [text[:n] + ch + text[n:] for n in range(0, len(text), step * 3) for ch in "\"'{[|,:"]
    return [*cuts, *stray]


@pytest.mark.parametrize("source", [*SOURCES, "motor.md"], ids=lambda p: Path(p).name)
def test_damaged_text_never_raises(source: Path | str, tmp_path: Path, markdown: Path) -> None:
    """Half-typed files (cut anywhere, a stray quote or bracket) get answers or none, never
    an exception: the server runs while the user types."""
    from statectl.channels.lsp.documents import diagnose

    path = markdown if source == "motor.md" else Path(source)
    target = tmp_path / path.name
    for text in damaged(path.read_text(encoding="utf-8")):
        project = Project((str(tmp_path),))
        project.texts[str(target)] = text
        doc = project.document(str(target))
        assert doc is not None
        for d in diagnose(doc, project.texts):
            fixes(doc, d.code, d.message, (d.where.line or 1) - 1)
        lines = text.split("\n")
        for line in range(0, len(lines) + 1, 4):
            for character in (0, 9, 200):
                complete(project, doc, line, character)
                hover(project, doc, line, character)
                definition(project, doc, line, character)
                rename(project, doc, line, character, "X")
