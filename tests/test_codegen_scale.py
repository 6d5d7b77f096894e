"""Codegen for big sparse charts: rows without per-cell kernel steps, compact C++ rows.

The compact form is compiled and run against the Python runtime here, on random
charts and on a generated ring, with the dense limit lowered so small charts use it.
"""

from __future__ import annotations

import importlib
import io
import random
from pathlib import Path

import pytest

from codegen_support import CLANG, GXX, CppDevice, assert_equivalent, needs_gxx
from statectl.cell.explore.progress import CountProgress
from statectl.channels.cli import main
from statectl.front.builder.build import load_chart
from statectl.kernel.semantics import Machine, step
from statectl.out.codegen.cpp import render
from statectl.out.codegen.cpp_rows import DENSE_CELLS
from statectl.out.codegen.flat import Decision
from statectl.out.codegen.flatten import flatten
from test_codegen_equivalence import random_chart

flatten_module = importlib.import_module("statectl.out.codegen.flatten")
needs_clang = pytest.mark.skipif(CLANG is None, reason="no clang++ on this machine")


def ring_yaml(n: int, path: Path) -> Path:
    """A flat ring S0..S(n-1), E{i}: S{i} -> S{i+1}; every fifth state ignores E{i+2}."""
    lines = ["device: Ring", "states:"]
    for i in range(n):
        lines.append(f"  - state: S{i}")
        if i == 0:
            lines.append("    control: default")
        if i % 5 == 0:
            lines.append(f"    ignore: [E{(i + 2) % n}]")
    lines.append("events:")
    for i in range(n):
        lines += [f"  - event: E{i}", f"    old: S{i}", f"    new: S{(i + 1) % n}"]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _ring(n: int, tmp_path: Path):  # type: ignore[no-untyped-def]
    return load_chart(ring_yaml(n, tmp_path / "ring.yaml"))


def test_flatten_steps_the_kernel_only_where_an_event_is_offered(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Flattening a 200-state ring steps the kernel about once per configuration, not per
    cell, and every cell (handled, declared ignored, no transition) is still the kernel's."""
    chart = _ring(200, tmp_path)
    calls = []
    real = flatten_module.step

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(args[2])
        return real(*args, **kwargs)

    monkeypatch.setattr(flatten_module, "step", counting)
    flat, _ = flatten(chart)
    assert flat is not None
    n_configs = len(flat.configurations)
    assert len(calls) <= 2 * n_configs, (len(calls), n_configs)
    m = Machine(chart)
    reasons = set()
    for c in flat.configurations:
        row = flat.dispatch[c.index]
        for e, event in enumerate(flat.events):
            kernel = step(m, c.snapshot, event, {})
            cell = row[e]
            assert not isinstance(cell, Decision)
            assert cell.handled == kernel.handled, (c.label, event)
            assert cell.unhandled == kernel.unhandled, (c.label, event)
            reasons.add(cell.unhandled)
    assert len(reasons) == 3, reasons  # handled (None), declared ignored, no transition


def test_big_chart_header_has_compact_rows_linear_in_the_chart(tmp_path: Path) -> None:
    """Past DENSE_CELLS the header has no dense kCells table; its rows list about one
    exception per transition and ignore, not one cell per configuration and event."""
    n = 300
    flat, _ = flatten(_ring(n, tmp_path))
    assert flat is not None
    assert len(flat.configurations) * len(flat.events) > DENSE_CELLS
    header = render(flat)["ring.hpp"]
    assert "kCells[" not in header
    count = int(header.split("kRowCellCount = ")[1].split(";")[0])
    assert 0 < count <= n + n // 5 + 2, count


def test_small_chart_keeps_the_dense_table(tmp_path: Path) -> None:
    """A chart under the limit keeps kCells, and a limit below its cells switches it
    (dispatch's comment says which form it reads)."""
    flat, _ = flatten(_ring(12, tmp_path))
    assert flat is not None
    dense = render(flat)["ring.hpp"]
    assert "kCells[" in dense and "one load from kCells" in dense
    compact = render(flat, dense_limit=0)["ring.hpp"]
    assert "kCells" not in compact and "kRowCells[" in compact
    assert "binary search of the event's row" in compact


@needs_gxx
@pytest.mark.parametrize("compiler", [GXX, pytest.param(CLANG, marks=needs_clang)])
def test_compact_ring_traces_like_python(tmp_path: Path, compiler: str | None) -> None:
    """A 300-state ring in the compact form (g++ and clang++, -Werror) runs round the
    ring, with ignored and unhandled events on the way, exactly as the Python runtime."""
    n = 300
    device = CppDevice(_ring(n, tmp_path), tmp_path, compiler, dense_limit=0)
    rnd = random.Random(7)
    walk = [f"E{i}" for i in range(n)] + ["E0", "E1"]
    runs: list[tuple[dict[str, int], list[str]]] = [({}, walk)]
    for _ in range(8):
        events = []
        at = 0
        for _ in range(30):
            pick = rnd.choice([at, at, (at + 2) % n, rnd.randrange(n)])
            events.append(f"E{pick}")
            at = (at + 1) % n if pick == at else at
        runs.append(({}, events))
    assert_equivalent(device, runs)


@needs_gxx
@pytest.mark.parametrize("seed", [0, *range(3, 14)])  # seeds 1 and 2 are refused (G707)
def test_random_charts_compact_trace_like_python(tmp_path: Path, seed: int) -> None:
    """Random charts (hierarchy, history, guards, prefix matching) generated in the compact
    form trace like the Python runtime."""
    chart = random_chart(seed)
    device = CppDevice(chart, tmp_path, dense_limit=0)
    rnd = random.Random(seed)
    events = device.events
    runs = [
        ({"x": rnd.randint(-1, 3), "y": rnd.randint(-1, 3)}, rnd.choices(events, k=10))
        for _ in range(12)
    ]
    assert_equivalent(device, runs)


@pytest.mark.parametrize(
    ("after", "shown"),
    [(0.0, True), (3600.0, False)],
)
def test_progress_line_only_once_the_work_is_long(after: float, shown: bool) -> None:
    """The codegen/testgen progress line stays quiet until the work has run ``after``
    seconds, then names the counts; done() ends the line only if one was written."""
    stream = io.StringIO()
    printer = CountProgress("codegen", "configurations stepped", stream, after=after, interval=0)
    printer(5, 12)
    printer.done()
    text = stream.getvalue()
    assert ("codegen: 5 of 12 configurations stepped" in text) is shown, text
    assert text.endswith("\n") is shown


@pytest.mark.parametrize("command", ["codegen", "testgen"])
def test_progress_option_is_accepted_and_quiet_on_a_quick_run(tmp_path: Path, command: str) -> None:
    """``--progress`` is an option of codegen and testgen; a quick run prints no progress."""
    tables = ring_yaml(10, tmp_path / "ring.yaml")
    out, err = io.StringIO(), io.StringIO()
    code = main([command, str(tables), "--out", str(tmp_path / "out"), "--progress"], out, err)
    assert code == 0, err.getvalue()
    assert "\r" not in err.getvalue()
