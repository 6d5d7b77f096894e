"""The GraphWalker and XState exports carry guards, data and re-entry (docs/testing.md)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from statectl.front.builder.build import load_chart
from statectl.kernel.semantics import compiled, initial, step
from statectl.out.testgen.generator import export_graphwalker, export_xstate
from statectl.out.testgen.jsguard import js_expression
from statectl.out.testgen.paths import default_data, leaves
from statectl.run.runtime.eventdata import assignments_of
from support import MOTOR, ROOT

PRESS = ROOT / "examples" / "press" / "press.yaml"
CLAMP = ROOT / "examples" / "modbus" / "clamp.yaml"

#: Random walks over a GraphWalker model as GraphWalker takes them: the model's
#: actions, then at each vertex an edge whose guard holds, its actions run.
WALK = r"""
const vm = require("vm");
const model = JSON.parse(require("fs").readFileSync(process.argv[2], "utf8")).models[0];
let seed = 7;
const rand = () => (seed = (seed * 1103515245 + 12345) % 2147483648) / 2147483648;
const walks = [];
for (let w = 0; w < 200; w++) {
  const ctx = vm.createContext({});
  for (const a of model.actions || []) vm.runInContext(a, ctx);
  let at = model.edges[0].targetVertexId;
  const walk = [];
  for (let i = 0; i < 12; i++) {
    const open = model.edges.filter(e => e.sourceVertexId === at &&
      (!e.guard || vm.runInContext(e.guard, ctx)));
    if (!open.length) break;
    const e = open[Math.floor(rand() * open.length)];
    for (const a of e.actions || []) vm.runInContext(a, ctx);
    walk.push([e.properties.event, e.properties.data ?? null, e.targetVertexId]);
    at = e.targetVertexId;
  }
  walks.push(walk);
}
console.log(JSON.stringify(walks));
"""


@pytest.mark.parametrize("file", [MOTOR, PRESS, CLAMP], ids=lambda f: f.stem)
def test_a_graphwalker_walk_asks_only_for_possible_paths(tmp_path: Path, file: Path) -> None:
    """Every random walk over the model is a path the kernel takes, edge by edge: the
    Motor's Initialization only after a movement, the Press only below its limit."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed")
    path = export_graphwalker(file, tmp_path)
    (tmp_path / "walk.js").write_text(WALK, encoding="utf-8")
    done = subprocess.run(
        [node, str(tmp_path / "walk.js"), str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    model = json.loads(path.read_text(encoding="utf-8"))["models"][0]
    states = {v["id"]: v["properties"]["states"] for v in model["vertices"]}
    chart = load_chart(file)
    m = compiled(chart)
    taken = set()
    for walk in json.loads(done.stdout):
        first = initial(m)
        snapshot, data = first.target, dict(default_data(chart))
        for event, sent, vertex in walk:
            decided = step(m, snapshot, event, data, sent)
            assert decided.handled, (walk, event)
            assert list(leaves(chart, decided.target)) == states[vertex], (walk, event)
            snapshot = decided.target
            data.update(assignments_of(decided, data, event, sent, chart.name) or {})
            taken.add(event)
    if file == MOTOR:
        assert "Initialization" in taken  # the guarded row is walked, when it may be


def test_the_motor_model_guards_initialization_by_previous(tmp_path: Path) -> None:
    """The Motor's Initialization edge holds only after Moving; each edge sets previous."""
    model = json.loads(export_graphwalker(MOTOR, tmp_path).read_text(encoding="utf-8"))
    edges = {e["name"]: e for e in model["models"][0]["edges"]}
    assert model["models"][0]["actions"] == ["previous = null;"]
    assert edges["e_Initialization"]["guard"] == '(previous === "Moving")'
    assert edges["e_Movement"]["actions"] == ['previous = "Blocked";']


@pytest.mark.parametrize(
    ("guard", "js"),
    [
        ("previous in ('Moving', 'Returning')", '["Moving", "Returning"].includes(previous)'),
        ("_event.data.speed <= max_speed and _event.data.enable", "((4 <= max_speed) && true)"),
        ("not In('Moving') or x is None", "(!(false) || (x === null))"),
        ("x // 2 > 1", None),  # floor division means another thing in JavaScript
        ("len(x) > 1", None),
    ],
)
def test_guards_are_written_as_javascript(guard: str, js: str | None) -> None:
    """What means the same in JavaScript is written; the rest is None, not a guess."""
    names = frozenset({"max_speed", "x"})
    assert js_expression(guard, names, {"speed": 4, "enable": True}) == js


def test_xstate_marks_a_row_that_reenters_its_state(tmp_path: Path) -> None:
    """The Press's Reset (Open -> Open) re-enters Open: reenter true; other rows have none."""
    config = json.loads(export_xstate(PRESS, tmp_path).read_text(encoding="utf-8"))
    opened = config["states"]["Open"]["on"]
    assert opened["Reset"][0]["reenter"] is True
    assert "reenter" not in opened["Press"][0]
