"""A cell's link events are journalled with the step that fired them: one commit, or none.

The cell is two Motors; ``left`` entering Moving sends ``Movement`` to ``right``.
Nothing else sends ``right`` a Movement, so at every committed point of the
journal the number of ``left`` steps that took Movement (Blocked -> Moving, the
only way into Moving) must equal the number of Movement rows in ``right``'s inbox.
A link event committed apart from its step breaks that count at some commit; a
kill there would lose the link event (or keep one whose cause was lost).
"""

from __future__ import annotations

import json
import os
import random
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from statectl.cell.model import load_cell_or_raise
from statectl.run.journal import Guarantee, Journal, JournalReader, StepKind, replay
from statectl.run.runner import System, cell_setups
from statectl.run.runtime import SimClock

MOTOR = (Path(__file__).resolve().parents[1] / "examples" / "motor" / "motor.yaml").as_posix()
CELL = f"""\
cell: Linked motors
devices:
  left: {MOTOR}
  right: {MOTOR}
links:
  - {{from: left, enters: Moving, to: right, send: Movement}}
"""
#: What the tests post: every Motor event to ``left``, all but Movement to ``right``.
EVENTS = {
    "left": ("Movement", "Movement completion", "Error", "Error completion", "Initialization",
             "Initialization completion"),
    "right": ("Movement completion", "Error", "Error completion", "Initialization",
              "Initialization completion"),
}  # fmt: skip


def counts(
    db: Path, *, upto_step: int | None = None, upto_seq: int | None = None
) -> tuple[int, int]:
    """(left steps that took Movement, right inbox rows for Movement) in the committed journal."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        steps = con.execute(
            "SELECT count(*) FROM steps WHERE device='left' AND event='Movement' "
            "AND outcome='handled' AND id <= ?",
            (upto_step if upto_step is not None else 2**62,),
        ).fetchone()[0]
        sent = con.execute(
            "SELECT count(*) FROM inbox WHERE device='right' AND event='Movement' AND seq <= ?",
            (upto_seq if upto_seq is not None else 2**62,),
        ).fetchone()[0]
    finally:
        con.close()
    return int(steps), int(sent)


def write_cell(tmp_path: Path) -> Path:
    path = tmp_path / "cell.yaml"
    path.write_text(CELL, encoding="utf-8")
    return path


@pytest.mark.parametrize("guarantee", [g.value for g in Guarantee])
def test_every_commit_holds_a_step_with_the_links_it_fired(tmp_path: Path, guarantee: str) -> None:
    """With one queue item per commit, no commit ever has a step without its link event."""
    cell = load_cell_or_raise(write_cell(tmp_path))
    db = tmp_path / "run.db"
    journal = Journal(db, guarantee=guarantee, max_batch=1)  # as many commits as possible
    seen: list[tuple[int, int]] = []
    journal.after_commit(lambda: seen.append(counts(db)))
    system = System(cell_setups(cell), SimClock(), journal, cell=cell)
    system.start()
    rng = random.Random(7)
    for _ in range(300):
        device = rng.choice(("left", "right"))
        system.post(device, rng.choice(EVENTS[device]))
        system.quiesce()
    system.close()
    final = counts(db)
    assert final[0] > 10, "the run never moved left: the test would prove nothing"
    assert final[0] == final[1]
    assert [c for c in seen if c[0] != c[1]] == []


def test_links_fired_while_resuming_are_sent(tmp_path: Path) -> None:
    """An accepted Movement for left not yet run at a crash runs on resume and sends its link."""
    cell = load_cell_or_raise(write_cell(tmp_path))
    db = tmp_path / "run.db"
    journal = Journal(db)
    first = System(cell_setups(cell), SimClock(), journal, cell=cell)
    first.start()
    journal.accept("left", "Movement")  # accepted, never run: the process "died" here
    first.close()
    again = System(cell_setups(cell), SimClock(), Journal(db), cell=cell)
    again.start(resume=True)
    again.quiesce()
    states = {n: sorted(s.configuration) for n, s in again.subjects.items()}
    again.close()
    assert states == {"left": ["Moving"], "right": ["Moving"]}
    assert counts(db) == (1, 1)


CHILD = r"""
import json, random, sys, time
from statectl.cell.model import load_cell_or_raise
from statectl.run.journal import Journal, JournalReader
from statectl.run.runner import System, cell_setups
from statectl.run.runtime import SimClock

db, path, seed, guarantee = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
EVENTS = json.loads(sys.argv[5])
cell = load_cell_or_raise(path)
system = System(cell_setups(cell), SimClock(), Journal(db, guarantee=guarantee), cell=cell)
system.start(resume=True)
system.quiesce()
states = {n: sorted(s.configuration) for n, s in system.subjects.items()}
with JournalReader(db) as r:
    last = r.last_id()
    inbox = max((x.seq for x in r.inbox()), default=0)
print("resumed " + json.dumps({"states": states, "last": last, "inbox": inbox}), flush=True)
rng = random.Random(seed)
while True:
    device = rng.choice(("left", "right"))
    system.post(device, rng.choice(EVENTS[device]))
    system.drain()
    system.advance(0.1)
    time.sleep(0.0002)
"""


def check_resume_point(db: Path, report: dict[str, Any]) -> None:
    """States equal a replay; each accepted event applied once; every link with its step."""
    chart = load_cell_or_raise(db.with_name("cell.yaml")).devices[0].chart
    with JournalReader(db) as reader:
        result = replay(reader, {"left": chart, "right": chart}, upto=report["last"])
        uses: dict[int, int] = {}
        for s in reader.steps(upto=report["last"]):
            if s.inbox is not None:
                assert s.kind is StepKind.EVENT
                uses[s.inbox] = uses.get(s.inbox, 0) + 1
        accepted = {r.seq for r in reader.inbox() if r.seq <= report["inbox"]}
    assert result.ok, [str(m) for m in result.mismatches]
    assert {n: sorted(s.active) for n, s in result.final.items()} == report["states"]
    assert all(n == 1 for n in uses.values()), "an accepted event was applied twice"
    assert set(uses) == accepted, "an accepted event was never applied"
    steps, sent = counts(db, upto_step=report["last"], upto_seq=report["inbox"])
    assert steps == sent, f"{steps} Movement steps of left but {sent} link events to right"


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
@pytest.mark.parametrize("guarantee", [g.value for g in Guarantee])
def test_sigkill_never_separates_a_step_from_its_links(tmp_path: Path, guarantee: str) -> None:
    """Eight kills of a linked cell: after each resume every link event is there with its step."""
    cell_file = write_cell(tmp_path)
    script = tmp_path / "child.py"
    script.write_text(CHILD, encoding="utf-8")
    db = tmp_path / "run.db"
    rng = random.Random(99)
    for round_ in range(9):
        child = subprocess.Popen(
            [sys.executable, str(script), str(db), str(cell_file), str(round_), guarantee,
             json.dumps(EVENTS)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )  # fmt: skip
        try:
            assert child.stdout is not None
            first = child.stdout.readline()
            assert first.startswith("resumed "), child.stderr.read() if child.stderr else first
            check_resume_point(db, json.loads(first.removeprefix("resumed ")))
            if round_ == 8:
                break
            time.sleep(rng.uniform(0.05, 0.3))
            child.send_signal(signal.SIGKILL)
        finally:
            if child.poll() is None:
                child.kill()
            child.communicate(timeout=30)
    assert counts(db)[0] > 0, "left never moved: the kills proved nothing"
