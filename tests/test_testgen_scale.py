"""testgen for big sparse charts: an explorer that steps only offered events, and a
compact module (one test per unhandled-event table, paths written once) that still
fails when the device is wrong."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from statectl.out.testgen import generate
from statectl.out.testgen.paths import explore
from test_codegen_scale import ring_yaml

SRC = Path(__file__).resolve().parent.parent / "src"
PLUGIN = ("-p", "statectl.out.testgen.plugin", "-p", "no:cacheprovider")

paths_module = importlib.import_module("statectl.out.testgen.paths")


def _module(n: int, tmp_path: Path) -> Path:
    tmp_path.mkdir(parents=True, exist_ok=True)
    tables = ring_yaml(n, tmp_path / "ring.yaml")
    return generate(tables, "rows", tmp_path / "tests").path


def _run(directory: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", *PLUGIN, str(directory)],
        cwd=directory,
        env={**os.environ, "PYTHONPATH": str(SRC)},
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_explore_steps_the_kernel_only_for_offered_or_ignored_events(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Exploring a 200-state ring asks the kernel about each node's offered and ignored
    events only, and every node still lists what it was asked (the rest is quiet)."""
    tables = ring_yaml(200, tmp_path / "ring.yaml")
    from statectl.front.builder.build import load_chart

    chart = load_chart(tables)
    calls = []
    real = paths_module.step

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(args[2])
        return real(*args, **kwargs)

    monkeypatch.setattr(paths_module, "step", counting)
    g = explore(chart)
    nodes = len(g.stepped)
    assert nodes >= 200
    assert len(calls) <= 2 * nodes, (len(calls), nodes)
    s0 = next(n for n in g.stepped if n.snapshot.active == frozenset({"S0"}))
    assert g.stepped[s0] == {"E0", "E2"}  # E0 taken, E2 declared ignored


def test_big_module_is_one_test_per_table_and_grows_linearly(tmp_path: Path) -> None:
    """A ring past LOOP_ROWS gets one test per table and its paths once: doubling the
    ring about doubles the module (the parametrised form would quadruple it)."""
    small = _module(150, tmp_path / "a").read_text(encoding="utf-8")
    big = _module(300, tmp_path / "b").read_text(encoding="utf-8")
    assert "_each_unhandled(d, " in big and "def test_unhandled_in_s7(statectl_device):" in big
    assert '("event", "reason")' not in big
    assert len(big) < 2.6 * len(small), (len(small), len(big))


def test_big_module_passes_on_the_twin(tmp_path: Path) -> None:
    """The compact module of a 150-state ring passes on the simulated twin."""
    module = _module(150, tmp_path)
    done = _run(module.parent)
    assert done.returncode == 0, done.stdout[-3000:]
    assert "300 passed" in done.stdout, done.stdout[-500:]


@pytest.mark.parametrize(
    ("edit", "failing", "event"),
    [
        # S3 now ignores E7: its table expected no transition
        ("  - state: S3\n", "test_unhandled_in_s3", "'E7'"),
        # a new row E9: S4 -> S0: S4's table expected E9 unhandled
        (None, "test_unhandled_in_s4", "'E9'"),
    ],
)
def test_big_module_fails_when_the_device_differs(
    tmp_path: Path, edit: str | None, failing: str, event: str
) -> None:
    """After the device (the twin of the edited tables) changes one pair, the compact
    module fails in that state's table test, and the message names the event."""
    module = _module(150, tmp_path)
    tables = tmp_path / "ring.yaml"
    text = tables.read_text(encoding="utf-8")
    if edit is not None:
        text = text.replace(edit, edit + "    ignore: [E7]\n", 1)
    else:
        text += "  - event: E9\n    old: S4\n    new: S0\n"
    tables.write_text(text, encoding="utf-8")
    done = _run(module.parent)
    assert done.returncode == 1, done.stdout[-2000:]
    failed = [line for line in done.stdout.splitlines() if line.startswith("FAILED")]
    assert any(failing + " " in line or line.endswith(failing) for line in failed), failed
    assert f"event {event} in" in done.stdout, done.stdout[-2000:]
