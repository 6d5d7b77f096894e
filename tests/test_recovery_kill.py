"""Killed at random points, a journalled run loses no acknowledged event and applies none twice.

A child process runs three journalled Motors on a simulated clock, fed with random
events, and prints ``ack SEQ`` once an event is durable. The test kills it with
SIGKILL at a random moment, ten times, once for each guarantee (``prompt``: the
device runs an event before it is durable; ``durable-first``: after). After every
restart (``resume``) the child reports its devices' states; they must equal a
replay of the journal, every acknowledged event must be in the journal, and no
accepted event may have been processed twice.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from statectl.run.journal import Guarantee, JournalReader, StepKind, load_device, replay

MOTOR = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
KILLS = 10  # per guarantee: the file stays well under 30 s
DEVICES = ("M0", "M1", "M2")

CHILD = r"""
import json, random, sys, time
from statectl.run.devices import SimMotor
from statectl.run.journal import Journal, load_device
from statectl.run.runner import DeviceSetup, System
from statectl.run.runtime import SimClock

db, path, seed, guarantee = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
DEVICES = ("M0", "M1", "M2")
dev = load_device(path)
setups = [DeviceSetup(n, dev.chart, dev.rules, path, SimMotor()) for n in DEVICES]
system = System(setups, SimClock(), Journal(db, guarantee=guarantee))
system.start(resume=True)
system.journal.flush()
states = {n: sorted(s.configuration) for n, s in system.subjects.items()}
from statectl.run.journal import JournalReader
with JournalReader(db) as r:
    last = r.last_id()
    inbox = max((x.seq for x in r.inbox()), default=0)
print("resumed " + json.dumps({"states": states, "last": last, "inbox": inbox}), flush=True)
rng = random.Random(seed)
events = [("Movement", {"amount": 5}), ("Initialization", None), ("Error", {"detail": "x"}),
          ("Movement completion", None), ("Bogus", None)]
waiting = []
while True:
    name = rng.choice(DEVICES)
    event, data = rng.choice(events)
    waiting.append(system.post(name, event, data))
    system.drain()
    system.advance(rng.choice((0.0, 0.1, 0.3)))
    still = []
    for t in waiting:
        if t.durable:
            print(f"ack {t.seq}", flush=True)
        else:
            still.append(t)
    waiting = still
    time.sleep(0.0002)  # a few thousand events a second: the journal, and each check, stay small
"""


def check_journal(db: Path, device_file: Path, report: dict[str, Any]) -> None:
    """At the resume point: states equal a replay; each accepted event applied exactly once."""
    last, states = report["last"], report["states"]
    chart = load_device(device_file).chart
    with JournalReader(db) as reader:
        result = replay(reader, dict.fromkeys(DEVICES, chart), upto=last)
        uses: dict[int, int] = {}
        for s in reader.steps(upto=last):
            if s.inbox is not None:
                assert s.kind is StepKind.EVENT
                uses[s.inbox] = uses.get(s.inbox, 0) + 1
        accepted = [r.seq for r in reader.inbox() if r.seq <= report["inbox"]]
    assert result.ok, [str(m) for m in result.mismatches]
    assert {n: sorted(s.active) for n, s in result.final.items()} == states
    assert all(n == 1 for n in uses.values()), "an accepted event was applied twice"
    assert set(uses) == set(accepted), "an accepted event was never applied"


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
@pytest.mark.parametrize("guarantee", [g.value for g in Guarantee])
def test_sigkill_at_random_points_loses_and_doubles_nothing(tmp_path: Path, guarantee: str) -> None:
    """Ten kills: acknowledged events survive, each applied once, states equal a replay."""
    # The shipped Motor: its Recovery table takes a resumed Moving through Error.
    device_file = tmp_path / "motor.yaml"
    device_file.write_text(MOTOR.read_text(encoding="utf-8"), encoding="utf-8")
    script = tmp_path / "child.py"
    script.write_text(CHILD, encoding="utf-8")
    db = tmp_path / "run.db"
    rng = random.Random(1234)
    acked: set[int] = set()
    for round_ in range(KILLS + 1):
        child = subprocess.Popen(
            [sys.executable, str(script), str(db), str(device_file), str(round_), guarantee],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        try:
            assert child.stdout is not None
            first = child.stdout.readline()
            assert first.startswith("resumed "), child.stderr.read() if child.stderr else first
            report = json.loads(first.removeprefix("resumed "))
            with JournalReader(db) as reader:
                present = {r.seq for r in reader.inbox()}
            assert acked <= present, f"acknowledged events lost: {sorted(acked - present)}"
            check_journal(db, device_file, report)
            if round_ == KILLS:
                break
            time.sleep(rng.uniform(0.02, 0.3))
            child.send_signal(signal.SIGKILL)
            rest, _ = child.communicate(timeout=30)
            acked |= {int(x.split()[1]) for x in rest.splitlines() if x.startswith("ack ")}
        finally:
            if child.poll() is None:
                child.kill()
            child.communicate(timeout=30)
    assert acked, "the child never acknowledged an event"
