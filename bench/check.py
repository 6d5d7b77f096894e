"""Benchmark loading, building and checking large but legitimate inputs.

Usage: python bench/check.py [--rows 20000] [--states 20000] [--keep DIR] [--flat-only]
       python bench/check.py --scale 100000 [--keep DIR]

Two generated inputs, written to a temporary directory:

- a YAML device file with ``--rows`` event rows: ``rows / 4`` states in a ring,
  each handling ``e0`` and ``e1`` unguarded and ``e2`` twice under exclusive guards
  that cover every case (``mode <= 1``, ``mode > 1``), so every rule of ``statectl
  check`` has work (C403 proves them exclusive, C419 covering) and
  the file checks clean. Timed: load (tables), build (chart), check (rules).
- an SCXML document with ``--states`` states in a ring (one transition each),
  timed through the reader, and then the first step of a session
  (``statectl scxml run``'s start).

A baseline of 1,000 rows (and 1,000 states) is timed in the same run, so the ratio
shows whether the work grows linearly (ratio near rows / 1,000) or worse.

``--scale ROWS`` times only ``statectl check`` end to end (a new process: wall and CPU
seconds) on the ring device of ``ROWS`` event rows as YAML and as a CSV pair, and on a
"wide" device of ``ROWS / 4`` states each with its own event and warnings to print, with
a tenth of the rows as baseline; issue 28's target is 100,000 rows in under 5 s.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from statectl.front.builder.build import build
from statectl.front.tables import load
from statectl.out.scxml import read_scxml

# ``statectl.check`` is ``statectl.front.rules`` where the facade's check() took the name
check_chart = importlib.import_module(
    "statectl.front.rules" if importlib.util.find_spec("statectl.front.rules") else "statectl.check"
).check_chart


def device_text(rows: int) -> str:
    """A device file with ``rows`` event rows that builds and checks clean."""
    states = max(2, rows // 4)
    out = ["device: Big", "data:", "  mode: 0", "states:"]
    for s in range(states):
        out.append(f"  - state: S{s}")
        out.append("    control: default" if s == 0 else "    control: event trigger required")
    out.append("events:")
    for i in range(rows):
        s, k = divmod(i, 4)
        s %= states
        event = f"e{min(k, 2)}"
        out.append(f"  - event: {event}")
        out.append(f"    old: S{s}")
        out.append(f"    new: S{(s + 1 + k) % states}")
        if k >= 2:
            out.append("    guard: mode <= 1" if k == 2 else "    guard: mode > 1")
    return "\n".join(out) + "\n"


def scxml_text(states: int) -> str:
    """An SCXML document of ``states`` states in a ring, one transition each."""
    out = ['<scxml xmlns="http://www.w3.org/2005/07/scxml" version="1.0" initial="s0">']
    for s in range(states):
        out.append(f'  <state id="s{s}"><transition event="go" target="s{(s + 1) % states}"/>')
        out.append("  </state>")
    out.append("</scxml>")
    return "\n".join(out) + "\n"


def csv_texts(rows: int) -> dict[str, str]:
    """The ring device of :func:`device_text` as a CSV pair and its data file."""
    states = max(2, rows // 4)
    head = "# device: Big\n"
    state_lines = ["state,control", "S0,default"]
    state_lines += [f"S{s},event trigger required" for s in range(1, states)]
    event_lines = ["event,guard,old,new"]
    for i in range(rows):
        s, k = divmod(i, 4)
        s %= states
        guard = "" if k < 2 else ("mode <= 1" if k == 2 else "mode > 1")
        event_lines.append(f"e{min(k, 2)},{guard},S{s},S{(s + 1 + k) % states}")
    return {
        "states": head + "\n".join(state_lines) + "\n",
        "events": head + "\n".join(event_lines) + "\n",
        "data": head + "name,value\nmode,0\n",
    }


def wide_text(states: int) -> str:
    """``states`` states in a ring, each left by its own event: every state misses the
    others' events (a C404 warning each), so the end-to-end run also prints."""
    lines = ["device: Wide", "states:", "  - {state: S0, control: default}"]
    lines += [f"  - {{state: S{i}, control: event trigger required}}" for i in range(1, states)]
    lines.append("events:")
    lines += [
        f"  - {{event: E{i}, old: S{i}, new: S{(i + 1) % states}, kind: command, api: A{i % 50}}}"
        for i in range(states)
    ]
    return "\n".join(lines) + "\n"


def check_cli(path: Path) -> tuple[float, float, str]:
    """Wall and CPU seconds of ``statectl check PATH`` in a new process, and its last line."""
    cli = [sys.executable, "-m", "statectl", "check", str(path)]
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall, done = timed(lambda: subprocess.run(cli, env=env, capture_output=True, check=False))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = done.stdout.decode().splitlines()  # type: ignore[attr-defined]
    return wall, cpu, lines[-1] if lines else ""


def scale_rows(where: Path, rows: int) -> int:
    """Issue 28: ``statectl check`` end to end on ``rows`` event rows, target < 5 s."""
    print(f"$ python bench/check.py --scale {rows}")
    print(f"Python {sys.version.split()[0]}; files in {where}; load {os.getloadavg()[0]:.1f}")
    print(f"{'statectl check on':<30} {'wall s':>7} {'cpu s':>7}  last line")
    for n in (max(rows // 10, 8), rows):
        ring = where / f"ring{n}.yaml"
        ring.write_text(device_text(n), encoding="utf-8")
        for part, text in csv_texts(n).items():
            (where / f"ring{n}.{part}.csv").write_text(text, encoding="utf-8")
        wide = where / f"wide{n // 4}.yaml"
        wide.write_text(wide_text(n // 4), encoding="utf-8")
        for label, path in (
            (f"ring, {n:,} rows, YAML", ring),
            (f"ring, {n:,} rows, CSV", where / f"ring{n}.states.csv"),
            (f"wide, {n // 4:,} rows, YAML", wide),
        ):
            wall, cpu, last = check_cli(path)
            verdict = f"  target < 5 s: {'met' if cpu < 5 else 'MISSED'}" if n == rows else ""
            print(f"{label:<30} {wall:7.2f} {cpu:7.2f}  {last}{verdict}")
    return 0


def timed(work: Callable[[], object]) -> tuple[float, object]:
    start = time.perf_counter()
    result = work()
    return time.perf_counter() - start, result


def bench_device(path: Path) -> tuple[float, float, float, int]:
    """Seconds to load, build and check ``path``, and the number of diagnostics."""
    t_load, got = timed(lambda: load(path))
    tables, diags = got  # type: ignore[misc]
    assert tables is not None, diags
    t_build, built = timed(lambda: build(tables))
    chart, bdiags = built  # type: ignore[misc]
    assert chart is not None, bdiags
    t_check, found = timed(lambda: list(check_chart(chart)))
    return t_load, t_build, t_check, len(found)  # type: ignore[arg-type]


def bench_scxml(path: Path) -> tuple[float, float]:
    """Seconds to read ``path`` and to start a session on it (to its first stable state)."""
    from statectl.out.scxml import Scheduler, Session, SimulatedClock

    text = path.read_text(encoding="utf-8")
    t_read, got = timed(lambda: read_scxml(text, str(path), str(path.parent)))
    chart, diags = got  # type: ignore[misc]
    assert chart is not None, diags

    def start() -> object:
        clock = SimulatedClock()
        scheduler = Scheduler(clock, None, None)
        session = Session(chart, scheduler, base=path.parent)
        return scheduler.run(session, clock.now() + 0.0)

    t_start, _ = timed(start)
    return t_read, t_start


def flat_text(states: int) -> str:
    """A flat device of ``states`` states in a ring, one event row each (issue 10's chart)."""
    lines = ["device: Flat", "states:"]
    lines.append("  - {state: S0, control: default}")
    lines += [f"  - {{state: S{i}, control: event trigger required}}" for i in range(1, states)]
    lines.append("events:")
    lines += [
        f"  - {{event: E{i}, old: S{i}, new: S{(i + 1) % states}, kind: command, api: Go}}"
        for i in range(states)
    ]
    return "\n".join(lines) + "\n"


def bench_flat(path: Path) -> tuple[float, float, float]:
    """Load (tables + build) and compile (the kernel's Machine, a started Subject), wall
    seconds; and the CPU seconds of both (on a shared machine, wall time also counts
    the other processes)."""
    from statectl.front.builder.build import load_chart
    from statectl.run.runtime import SimClock, Subject

    cpu = time.process_time()
    t_load, chart = timed(lambda: load_chart(path))
    assert not isinstance(chart, BaseException)

    def start() -> object:
        subject = Subject(chart, clock=SimClock())  # type: ignore[arg-type]  # a Chart
        subject.start()
        return subject

    t_compile, _ = timed(start)
    return t_load, t_compile, time.process_time() - cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=20_000)
    parser.add_argument("--states", type=int, default=20_000)
    parser.add_argument("--keep", help="write the generated files here and keep them")
    parser.add_argument("--flat-only", action="store_true", help="only the flat-chart rows")
    parser.add_argument("--scale", type=int, help="only statectl check end to end on N rows")
    args = parser.parse_args()
    where = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="statectl-bench-"))
    where.mkdir(parents=True, exist_ok=True)
    if args.scale:
        return scale_rows(where, args.scale)
    if args.flat_only:
        return flat_rows(where)
    print(f"$ python bench/check.py --rows {args.rows} --states {args.states}")
    print(f"Python {sys.version.split()[0]}; files in {where}")
    print(f"{'input':<28} {'load s':>8} {'build s':>8} {'check s':>8} {'total s':>8} {'diags':>6}")
    totals: list[float] = []
    for rows in (1_000, args.rows):
        path = where / f"big{rows}.yaml"
        path.write_text(device_text(rows), encoding="utf-8")
        t_load, t_build, t_check, n = bench_device(path)
        total = t_load + t_build + t_check
        totals.append(total)
        label = f"device, {rows:,} rows"
        print(f"{label:<28} {t_load:8.2f} {t_build:8.2f} {t_check:8.2f} {total:8.2f} {n:6}")
    print(
        f"ratio total {args.rows:,} / 1,000 rows: {totals[1] / totals[0]:.1f} "
        f"(linear would be {args.rows / 1000:.0f})"
    )

    cli = [sys.executable, "-m", "statectl", "check", str(where / f"big{args.rows}.yaml")]
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    t_cli, _ = timed(lambda: subprocess.run(cli, env=env, capture_output=True, check=False))
    print(f"$ statectl check big{args.rows}.yaml (a new process, end to end): {t_cli:.2f} s")
    print(f"{'input':<28} {'read s':>8} {'start s':>8}")
    reads: list[float] = []
    for states in (1_000, args.states):
        path = where / f"ring{states}.scxml"
        path.write_text(scxml_text(states), encoding="utf-8")
        t_read, t_start = bench_scxml(path)
        reads.append(t_read + t_start)
        label = f"SCXML, {states:,} states"
        print(f"{label:<28} {t_read:8.2f} {t_start:8.2f}")
    print(
        f"ratio read+start {args.states:,} / 1,000 states: {reads[1] / reads[0]:.1f} "
        f"(linear would be {args.states / 1000:.0f})"
    )
    return flat_rows(where)


def flat_rows(where: Path) -> int:
    """Issue 10's flat chart: 1,000 and 10,000 states, load and compile, target < 2 s."""
    print(f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'input':<28} {'load s':>8} {'compile s':>9} {'total s':>8} {'cpu s':>6}")
    for states in (1_000, 10_000):
        path = where / f"flat{states}.yaml"
        path.write_text(flat_text(states), encoding="utf-8")
        t_load, t_compile, cpu = bench_flat(path)
        label = f"flat chart, {states:,} states"
        total = t_load + t_compile
        verdict = (
            ""
            if states < 10_000
            else f"  (target < 2 s: cpu {'met' if cpu < 2 else 'MISSED'}, "
            f"wall {'met' if total < 2 else 'MISSED'})"
        )
        print(f"{label:<28} {t_load:8.2f} {t_compile:9.2f} {total:8.2f} {cpu:6.2f}{verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
