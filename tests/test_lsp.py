"""`statectl lsp` in a real session: pygls' client starts the server over stdio and speaks
LSP to it (initialize, didOpen, publishDiagnostics, hover, definition, completion, rename,
codeAction, shutdown). One session runs for the module; each test checks one answer."""

from __future__ import annotations

import asyncio
import os
import shutil
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from lsprotocol import types as lsp
from pygls.lsp.client import LanguageClient
from pygls.uris import from_fs_path

import statectl
from statectl.cell.model import load_cell
from statectl.channels.runconfig import load_run_config
from statectl.front.rules import check_paths
from statectl.kernel.errors import Diagnostic, DiagnosticError

ROOT = Path(__file__).resolve().parents[1]
SRC = Path(statectl.__file__).resolve().parents[1]
#: A guard on the whole session: a server that stops answering fails the test, never hangs it.
PATIENCE = 300.0


def uri(path: Path) -> str:
    return from_fs_path(str(path)) or str(path)


def edited(path: Path, old: str, new: str) -> str:
    text = path.read_text(encoding="utf-8")
    assert old in text, old
    return text.replace(old, new, 1)


def apply(text: str, edits: list[lsp.TextEdit]) -> str:
    """The text after an editor applies ``edits`` (from the last to the first)."""
    lines = text.split("\n")
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line) + 1)
    for e in sorted(
        edits, key=lambda e: (e.range.start.line, e.range.start.character), reverse=True
    ):
        start = offsets[e.range.start.line] + e.range.start.character
        end = offsets[e.range.end.line] + e.range.end.character
        text = text[:start] + e.new_text + text[end:]
    return text


@dataclass
class Session:
    """What the server answered, by question."""

    root: Path
    texts: dict[str, str] = field(default_factory=dict)  # what the editor holds, by file name
    diagnostics: dict[str, list[lsp.Diagnostic]] = field(default_factory=dict)  # by file name
    answers: dict[str, Any] = field(default_factory=dict)


def workspace(root: Path) -> dict[str, Path]:
    """A pick-and-place cell, the Motor in YAML, a CSV pair and Markdown, and a run config."""
    for p in (ROOT / "examples" / "pick-and-place").glob("*.yaml"):
        shutil.copy(p, root / p.name)
    for name in ("motor.yaml", "motor.states.csv", "motor.events.csv", "drivers.yaml"):
        shutil.copy(ROOT / "examples" / "motor" / name, root / name)
    from statectl.front.tables import dump, load

    tables, _ = load(ROOT / "examples" / "motor" / "motor.yaml")
    assert tables is not None
    (root / "motor.md").write_text(str(dump(tables, "md")), encoding="utf-8")
    return {p.name: p for p in root.iterdir()}


def buffers(files: dict[str, Path]) -> dict[str, str]:
    """The editor's texts: each differs from the file on disk, so a server reading the disk
    would answer about the wrong text."""
    motor = files["motor.yaml"]
    return {
        # Blocked no longer ignores Error (C404); Movement's guard reads undeclared data (B233)
        "motor.yaml": edited(
            motor,
            "ignore: [Movement completion, Initialization, Initialization completion, Error, ",
            "ignore: [Movement completion, Initialization, Initialization completion, ",
        ).replace(
            "  - event: Movement\n    condition: request from external inputs or sensors\n",
            "  - event: Movement\n    condition: request from external inputs or sensors\n"
            "    guard: _event.data.distance > 0\n",
        ),
        "motor.events.csv": edited(
            files["motor.events.csv"], ",,Moving,Blocked,", ",,Movin,Blocked,"
        ),
        "motor.md": edited(files["motor.md"], "| Blocked | Returning |", "| Blockd | Returning |"),
        "cell.yaml": edited(files["cell.yaml"], "enters: Detected", "enters: Detectd"),
        "drivers.yaml": edited(files["drivers.yaml"], "driver: sim-motor", "driver: sim-motr"),
        "gripper.yaml": files["gripper.yaml"].read_text(encoding="utf-8"),
        "cell-nodes.yaml": files["cell-nodes.yaml"].read_text(encoding="utf-8"),
    }


def position(text: str, needle: str, offset: int = 0) -> lsp.Position:
    """Where ``needle`` starts in ``text`` (plus ``offset`` characters)."""
    for n, line in enumerate(text.split("\n")):
        if needle in line:
            return lsp.Position(n, line.index(needle) + offset)
    raise AssertionError(needle)


async def converse(s: Session, files: dict[str, Path]) -> None:
    """The whole conversation: every question is asked once, every answer kept."""
    client = LanguageClient("statectl-test", "1")
    received: dict[str, asyncio.Event] = {}

    @client.feature(lsp.TEXT_DOCUMENT_PUBLISH_DIAGNOSTICS)
    def published(params: lsp.PublishDiagnosticsParams) -> None:
        name = Path(params.uri).name
        s.diagnostics[name] = params.diagnostics
        received.setdefault(name, asyncio.Event()).set()

    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]),
    }
    await client.start_io(sys.executable, "-m", "statectl", "lsp", env=env, cwd=str(s.root))
    try:
        result = await client.initialize_async(
            lsp.InitializeParams(
                capabilities=lsp.ClientCapabilities(),
                root_uri=uri(s.root),
                workspace_folders=[lsp.WorkspaceFolder(uri(s.root), "ws")],
            )
        )
        s.answers["capabilities"] = result.capabilities
        client.initialized(lsp.InitializedParams())
        for name, text in s.texts.items():
            received.setdefault(name, asyncio.Event())
            language = (
                "csv" if name.endswith(".csv") else "markdown" if name.endswith(".md") else "yaml"
            )
            client.text_document_did_open(
                lsp.DidOpenTextDocumentParams(
                    lsp.TextDocumentItem(uri(files[name]), language, 1, text)
                )
            )
        for name in s.texts:
            await received[name].wait()
        await ask(client, s, files)
        first = dict(s.diagnostics)
        received["drivers.yaml"].clear()  # as you type: the typo fixed, the error goes
        client.text_document_did_change(
            lsp.DidChangeTextDocumentParams(
                lsp.VersionedTextDocumentIdentifier(2, uri(files["drivers.yaml"])),
                [lsp.TextDocumentContentChangeWholeDocument(files["drivers.yaml"].read_text())],
            )
        )
        await received["drivers.yaml"].wait()
        s.answers["after change"] = s.diagnostics["drivers.yaml"]
        s.diagnostics.update(first)
        await client.shutdown_async(None)
        client.exit(None)
    finally:
        await client.stop()


async def ask(client: LanguageClient, s: Session, files: dict[str, Path]) -> None:
    motor, cell, gripper = s.texts["motor.yaml"], s.texts["cell.yaml"], s.texts["gripper.yaml"]
    doc = lsp.TextDocumentIdentifier
    s.answers["hover"] = await client.text_document_hover_async(
        lsp.HoverParams(doc(uri(files["motor.yaml"])), position(motor, "state: Moving", 8))
    )
    s.answers["hover event"] = await client.text_document_hover_async(
        lsp.HoverParams(
            doc(uri(files["motor.yaml"])), position(motor, "event: Error completion", 8)
        )
    )
    s.answers["definition"] = await client.text_document_definition_async(
        lsp.DefinitionParams(doc(uri(files["cell.yaml"])), position(cell, "enters: Closed", 9))
    )
    s.answers["definition guard"] = await client.text_document_definition_async(
        lsp.DefinitionParams(doc(uri(files["motor.yaml"])), position(motor, "'Moving'", 2))
    )
    s.answers["completion"] = await client.text_document_completion_async(
        lsp.CompletionParams(doc(uri(files["cell.yaml"])), position(cell, "enters: Closed", 8))
    )
    s.answers["completion columns"] = await client.text_document_completion_async(
        lsp.CompletionParams(
            doc(uri(files["motor.yaml"])), position(motor, "  - event: Movement", 4)
        )
    )
    s.answers["completion api"] = await client.text_document_completion_async(
        lsp.CompletionParams(doc(uri(files["motor.yaml"])), position(motor, "api: Movement()", 5))
    )
    s.answers["rename"] = await client.text_document_rename_async(
        lsp.RenameParams(
            doc(uri(files["cell.yaml"])), position(cell, "enters: Closed", 9), "Gripping"
        )
    )
    s.answers["rename refused"] = None
    try:
        await client.text_document_rename_async(
            lsp.RenameParams(
                doc(uri(files["gripper.yaml"])), position(gripper, "state: Open", 8), "A, B"
            )
        )
    except Exception as exc:  # the server's JSON-RPC error, raised by the client
        s.answers["rename refused"] = str(exc)
    for name in ("motor.yaml", "motor.events.csv", "motor.md"):
        actions = []
        for d in s.diagnostics[name]:
            actions.extend(
                await client.text_document_code_action_async(
                    lsp.CodeActionParams(
                        doc(uri(files[name])), d.range, lsp.CodeActionContext(diagnostics=[d])
                    )
                )
                or []
            )
        s.answers[f"actions {name}"] = actions


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Session]:
    root = tmp_path_factory.mktemp("ws").resolve()
    files = workspace(root)
    s = Session(root, buffers(files))
    asyncio.run(asyncio.wait_for(converse(s, files), PATIENCE))
    yield s


def expected(s: Session, name: str) -> list[Diagnostic]:
    """What the command line reports for the editor's text of ``name``, saved to disk."""
    target = s.root / "saved" / name
    target.parent.mkdir(exist_ok=True)
    for other in s.root.glob("motor.*.csv"):
        shutil.copy(other, target.parent / other.name)
    for other in s.root.glob("*.yaml"):
        shutil.copy(other, target.parent / other.name)
    target.write_text(s.texts[name], encoding="utf-8")
    if name in ("cell.yaml",):
        return load_cell(target)[1]
    if name == "drivers.yaml":
        try:
            load_run_config(target)
        except DiagnosticError as exc:
            return list(exc.diagnostics)
        return []
    return [d for d in check_paths([str(target)]) if Path(d.where.file).name == name]


def shown(d: Diagnostic) -> tuple[str, str, int, str]:
    message = f"{d.message} ({d.hint})" if d.hint else d.message
    return d.code, d.severity.value, (d.where.line or 1) - 1, message


SEVERITIES = {1: "error", 2: "warning", 3: "info"}


@pytest.mark.parametrize(
    "name", ["motor.yaml", "motor.events.csv", "motor.md", "cell.yaml", "drivers.yaml"]
)
def test_diagnostics_are_the_command_lines(session: Session, name: str) -> None:
    """Each open file's diagnostics are exactly what check (verify, run --config) reports for
    the editor's text: code, severity, line, message and hint; the disk's text is valid."""
    got = [
        (str(d.code), SEVERITIES[int(d.severity or 1)], d.range.start.line, d.message)
        for d in session.diagnostics[name]
    ]
    assert got == [shown(d) for d in expected(session, name)]
    assert any(g[1] in ("error", "warning") for g in got), got


@pytest.mark.parametrize(
    ("name", "code", "word"),
    [
        ("motor.events.csv", None, "Movin"),
        ("motor.md", None, "Blockd"),
        ("cell.yaml", "V808", "Detectd"),
        ("drivers.yaml", "D505", "sim-motr"),
    ],
)
def test_diagnostic_range_is_the_name(
    session: Session, name: str, code: str | None, word: str
) -> None:
    """A diagnostic that quotes a name is placed on that name, not just its line."""
    lines = session.texts[name].split("\n")
    ranges = [
        lines[d.range.start.line][d.range.start.character : d.range.end.character]
        for d in session.diagnostics[name]
        if code is None or d.code == code
    ]
    assert word in ranges, ranges


def test_unchanged_files_are_clean(session: Session) -> None:
    """A valid device file and a valid cell get no errors (the gripper, the nodes cell)."""
    for name in ("gripper.yaml", "cell-nodes.yaml"):
        assert [d.code for d in session.diagnostics[name] if d.severity == 1] == [], name


def test_server_says_what_it_offers(session: Session) -> None:
    """initialize announces hover, definition, completion, rename and quick fixes."""
    caps = session.answers["capabilities"]
    assert caps.hover_provider and caps.definition_provider and caps.rename_provider
    assert caps.completion_provider is not None and caps.code_action_provider


def test_hover_shows_the_state_row_and_its_uses(session: Session) -> None:
    """Hovering a state shows its row (description) and where it is used."""
    text = session.answers["hover"].contents.value
    assert "**state `Moving`** of motor.yaml" in text
    assert "description: Triggered by Movement" in text
    assert "(old of 'Movement completion')" in text and "(guard of 'Initialization')" in text


def test_hover_on_an_event_shows_its_transitions(session: Session) -> None:
    """Hovering an event shows its rows as transitions, its condition and kind."""
    text = session.answers["hover event"].contents.value
    assert "`Returning + Error completion = Blocked`" in text
    assert "kind: completion" in text


def test_definition_from_a_cell_opens_the_device_row(session: Session) -> None:
    """Go to definition on a link's `enters: Closed` lands on gripper.yaml's state cell."""
    found = session.answers["definition"]
    assert Path(found.uri).name == "gripper.yaml"
    line = session.texts["gripper.yaml"].split("\n")[found.range.start.line]
    assert line[found.range.start.character : found.range.end.character] == "Closed"
    assert "state:" in line


def test_definition_from_a_guard(session: Session) -> None:
    """A state quoted in a guard (previous == 'Moving') leads to its row."""
    found = session.answers["definition guard"]
    line = session.texts["motor.yaml"].split("\n")[found.range.start.line]
    assert line.strip() == "state: Moving"


def labels(answer: lsp.CompletionList) -> list[str]:
    return [i.label for i in answer.items]


def test_completion_offers_the_source_devices_states(session: Session) -> None:
    """After a link's `enters:` come the states of its `from` device (the gripper)."""
    assert labels(session.answers["completion"]) == ["Open", "Closing", "Closed", "Opening"]


def test_completion_offers_columns_and_apis(session: Session) -> None:
    """At a row's key the table's columns; in `api:` the device's APIs."""
    columns = labels(session.answers["completion columns"])
    assert columns[:5] == ["event", "condition", "guard", "old", "new"]
    apis = labels(session.answers["completion api"])
    assert "Movement()" in apis and "Initialization" in apis


def test_rename_changes_the_device_and_every_cell(session: Session) -> None:
    """Renaming gripper's Closed from a cell edits gripper.yaml's definition and uses, and
    each cell that names it, and no other text."""
    changes = session.answers["rename"].changes
    files = {Path(u).name: edits for u, edits in changes.items()}
    assert {"gripper.yaml", "cell.yaml", "cell-nodes.yaml"} <= set(files)
    for name, edits in files.items():
        text = (session.root / name).read_text(encoding="utf-8")
        before = text.split("\n")
        for e in edits:
            assert (
                before[e.range.start.line][e.range.start.character : e.range.end.character]
                == "Closed"
            )
        after = apply(text, edits)
        assert after.count("Gripping") == len(edits) and len(edits) >= 1
    gripper = apply(session.texts["gripper.yaml"], files["gripper.yaml"])
    assert "state: Gripping" in gripper and "Closed" not in gripper.replace("Closed.", "")


def test_rename_refuses_a_name_with_a_comma(session: Session) -> None:
    """A new name that a list cell could not hold is refused with the reason."""
    assert "cannot name a state" in str(session.answers["rename refused"])


def fixed(session: Session, title_start: str) -> str:
    actions = [a for a in session.answers["actions motor.yaml"] if a.title.startswith(title_start)]
    assert len(actions) == 1, [a.title for a in session.answers["actions motor.yaml"]]
    (edits,) = actions[0].edit.changes.values()
    return apply(session.texts["motor.yaml"], edits)


def check_text(tmp: Path, text: str) -> list[str]:
    path = tmp / "motor.yaml"
    path.write_text(text, encoding="utf-8")
    return [d.code for d in check_paths([str(path)])]


def test_code_action_adds_the_event_to_the_ignore_column(session: Session, tmp_path: Path) -> None:
    """C404's quick fix lists the missed event in the state's ignore column: C404 is gone."""
    assert "C404" in check_text(tmp_path, session.texts["motor.yaml"])
    text = fixed(session, "Ignore Error in state Blocked")
    assert "Initialization completion, Error completion, Error]" in text
    assert "C404" not in check_text(tmp_path, text)


def test_code_action_declares_event_data(session: Session, tmp_path: Path) -> None:
    """B233's quick fix declares the field the guard reads on the event's row: B233 is gone
    and no error takes its place."""
    assert "B233" in check_text(tmp_path, session.texts["motor.yaml"])
    text = fixed(session, "Declare data field distance on event Movement")
    assert "    data: {distance: any}\n" in text
    codes = check_text(tmp_path, text)
    assert "B233" not in codes and not [c for c in codes if c.startswith(("B", "T", "X"))]


def test_diagnostics_follow_the_text_as_it_changes(session: Session) -> None:
    """didChange republishes: the run config's driver typo fixed in the editor, its D505 goes."""
    assert [d.code for d in session.diagnostics["drivers.yaml"]] == ["D505"]
    assert list(session.answers["after change"]) == []


@pytest.mark.parametrize(
    ("name", "typo", "meant"),
    [("motor.events.csv", "Movin", "Moving"), ("motor.md", "Blockd", "Blocked")],
)
def test_code_action_takes_the_did_you_mean(
    session: Session, name: str, typo: str, meant: str, tmp_path: Path
) -> None:
    """A hint "did you mean 'Moving'?" is a quick fix that puts the suggestion in place of the
    name the diagnostic is on: the file then checks clean."""
    actions = [
        a for a in session.answers[f"actions {name}"] if a.title == f"Change {typo!r} to {meant!r}"
    ]
    assert len(actions) == 1, [a.title for a in session.answers[f"actions {name}"]]
    (edits,) = actions[0].edit.changes.values()
    text = apply(session.texts[name], edits)
    assert text == session.texts[name].replace(f" {typo} |", f" {meant} |").replace(
        f",{typo},", f",{meant},"
    )
    for other in session.root.glob("motor.*"):
        shutil.copy(other, tmp_path / other.name)
    (tmp_path / name).write_text(text, encoding="utf-8")
    assert [
        d.code for d in check_paths([str(tmp_path / name)]) if d.severity.value == "error"
    ] == []


def test_rename_reaches_a_nodes_peer_lost(tmp_path: Path) -> None:
    """A node's peer_lost event (cell-nodes.yaml: {conveyor: Stop}) is renamed with the rest."""
    from statectl.channels.lsp.documents import Project
    from statectl.channels.lsp.navigate import rename

    for p in (ROOT / "examples" / "pick-and-place").glob("*.yaml"):
        shutil.copy(p, tmp_path / p.name)
    project = Project((str(tmp_path),))
    conveyor = project.document(str(tmp_path / "conveyor.yaml"))
    assert conveyor is not None
    where = position(conveyor.text, "event: Stop", 7)
    found = rename(project, conveyor, where.line, where.character, "Halt")
    assert isinstance(found, dict)
    nodes = (tmp_path / "cell-nodes.yaml").read_text(encoding="utf-8").split("\n")
    spans = found[str(tmp_path / "cell-nodes.yaml")]
    assert any("peer_lost: {conveyor: Stop}" in nodes[s.line] for s in spans)
    assert all(nodes[s.line][s.start : s.end] == "Stop" for s in spans)
