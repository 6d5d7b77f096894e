"""Per-state timeouts in generated C++: ``tick(now_ms)`` traces exactly like the Python runtime.

Each chart is generated and compiled once with a driver that reads sequences of events
and ticks; the Python reference runs the same sequence on a Subject over a SimClock,
where a tick is ``advance`` to that time. Durations and ticks are multiples of 250 ms,
exact in binary floating point, so the two clocks agree to the millisecond.
"""

from __future__ import annotations

import difflib
import random
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from codegen_support import FLAGS, GXX, _Recorder, canonical, driver_source, needs_gxx
from statectl.front.builder.build import load_chart
from statectl.kernel.errors import Severity, has_errors
from statectl.kernel.model import Chart, StateKind, Timeout
from statectl.out.codegen.cpp import generate, render, runtime_files
from statectl.out.codegen.flatten import flatten
from statectl.run.runtime import SimClock, Subject
from test_codegen_equivalence import random_chart

ROOT = Path(__file__).resolve().parent.parent
CLAMP = ROOT / "examples" / "clamp" / "clamp.yaml"

pytestmark = needs_gxx

#: A step of a sequence: an event name, or a tick to that many milliseconds.
Item = str | int

_TICK = """\
      if (e < 0) {
        device.tick(static_cast<std::uint32_t>(-e - 1));
        p = end;
        continue;
      }
"""


def python_trace(chart: Chart, items: Sequence[Item]) -> list[str]:
    """The reference: a Subject on a SimClock, a tick advancing the clock to its time."""
    lines: list[str] = []
    clock = SimClock()
    subject = Subject(chart, clock=clock)
    if chart.invokes:
        subject.attach(_Recorder(lines))

    def listen(record: object) -> None:
        lines.extend(canonical(record))

    subject.listen(listen)
    subject.start()
    for item in items:
        if isinstance(item, int):
            subject.advance(item / 1000 - clock.now())
        else:
            subject.post(item)
            subject.run_until_idle()
    order = [s.name for s in chart.states]
    lines.append("config " + ", ".join(s for s in order if s in subject.configuration))
    return lines


class TimedDevice:
    """The chart generated and compiled with a driver that also ticks (negative numbers)."""

    def __init__(self, chart: Chart, workdir: Path) -> None:
        self.chart = chart
        flat, diags = flatten(chart)
        assert flat is not None and not has_errors(diags), diags
        for rel, text in {**render(flat), **runtime_files()}.items():
            path = workdir / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
        self.events = list(flat.events)
        source = driver_source(chart, [], {})
        anchor = "      device.dispatch(static_cast<"
        assert anchor in source
        tick = _TICK
        if not any(s.timeout for s in chart.states):  # no tick(): time changes nothing
            tick = tick.replace("device.tick(static_cast<std::uint32_t>(-e - 1));", "")
        (workdir / "driver.cpp").write_text(source.replace(anchor, tick + anchor, 1))
        self.binary = workdir / "driver"
        cmd = [GXX or "g++", *FLAGS, "-O0", "-DSTATECTL_TRACE=1", "-I", str(workdir)]
        cmd += [str(workdir / "driver.cpp"), "-o", str(self.binary)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        assert done.returncode == 0, done.stderr

    def traces(self, runs: Sequence[Sequence[Item]]) -> list[list[str]]:
        lines = []
        for items in runs:
            codes = [
                str(-(i + 1)) if isinstance(i, int) else str(self.events.index(i)) for i in items
            ]
            lines.append(" ; " + " ".join(codes) + "\n")
        done = subprocess.run(
            [str(self.binary)], input="".join(lines), capture_output=True, text=True, check=True
        )
        return [c.splitlines() for c in done.stdout.split("---\n")[: len(runs)]]

    def assert_equivalent(self, runs: Sequence[Sequence[Item]]) -> None:
        for items, got in zip(runs, self.traces(runs), strict=True):
            expected = python_trace(self.chart, items)
            if got != expected:
                diff = difflib.unified_diff(expected, got, "python", "c++", lineterm="", n=2)
                raise AssertionError(f"{list(items)}\n" + "\n".join(diff))


CLAMP_RUNS: list[list[Item]] = [
    ["Close", 1000, "Closed", 5000, "Release"],  # closes in time: no timeout
    ["Close", 1999, 2000, "Reset", "Close", 3000, 4000],  # times out at 2000 and at 4000
    ["Close", "Release", 500, "Closed"],  # the deferred Release is released once Clamped
    ["Close", "Release", "Release", 2000, "Reset"],  # kept twice, then dropped in Jammed
    [3000, "Close", 4999, 5000],  # armed at the last tick's time
    ["Close", 10000],  # one tick long past the deadline fires once, at the deadline
    [],
]


def test_clamp_timeouts_trace_like_python(tmp_path: Path) -> None:
    """The clamp example: every scenario with ticks traces in C++ as in Python."""
    device = TimedDevice(load_chart(CLAMP), tmp_path)
    device.assert_equivalent(CLAMP_RUNS)


def test_a_timeout_that_is_not_whole_milliseconds_is_refused(tmp_path: Path) -> None:
    """A timeout the C++ cannot count exactly (G711) or whose event is unknown (G710)."""
    chart = load_chart(CLAMP)
    for timeout, code in ((Timeout(0.0005, "Close timeout"), "G711"), (Timeout(1, "Nope"), "G710")):
        bad = replace(
            chart,
            states=tuple(
                replace(s, timeout=timeout) if s.name == "Closing" else s for s in chart.states
            ),
        )
        written, diags = generate(bad, tmp_path / code)
        assert not written
        assert [d.code for d in diags if d.severity is Severity.ERROR] == [code]


def test_a_chart_without_timeouts_generates_no_timer_code(tmp_path: Path) -> None:
    """The Motor's header has no tick(), no timeout table: nothing costs without timeouts."""
    flat, _ = flatten(load_chart(ROOT / "examples" / "motor" / "motor.yaml"))
    assert flat is not None
    header = next(text for name, text in render(flat).items() if name.endswith("motor.hpp"))
    assert "tick(" not in header and "kTimeout" not in header


def with_timeouts(chart: Chart, rng: random.Random) -> Chart:
    """The chart with timeouts on about half its states that can be active, and deferred
    events (any, handled or not: the kernel takes a transition first) on about a third."""
    events = chart.event_names
    states = []
    for s in chart.states:
        if s.kind.is_history or s.kind is StateKind.FINAL:
            states.append(s)
            continue
        if rng.random() < 0.5:
            ms = rng.choice((250, 500, 750, 1000))
            s = replace(s, timeout=Timeout(ms / 1000, rng.choice(events)))
        if rng.random() < 0.35:
            s = replace(s, defer=tuple(rng.sample(events, min(2, len(events)))))
        states.append(s)
    return replace(chart, states=tuple(states))


items = st.one_of(
    st.sampled_from(("go", "stop", "tick", "go fast")),
    st.integers(1, 6).map(lambda n: -n),  # a tick n * 250 ms later (made absolute below)
)


def absolute(steps: list[str | int]) -> list[Item]:
    now, out = 0, []
    for s in steps:
        if isinstance(s, int):
            now += -s * 250
            out.append(now)
        else:
            out.append(s)
    return out


def test_random_charts_with_timeouts_trace_like_python() -> None:
    """Random charts with timeouts and deferred events: C++ traces as Python does."""
    compiled = 0

    @settings(
        max_examples=12,
        deadline=None,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(seed=st.integers(0, 10**6), data=st.data())
    def check(seed: int, data: st.DataObject) -> None:
        nonlocal compiled
        chart = with_timeouts(random_chart(seed), random.Random(seed))
        if not any(s.timeout or s.defer for s in chart.states):
            return
        flat, diags = flatten(chart)
        if flat is None or has_errors(diags):
            return  # refused for reasons of its own (G706/G707): the equivalence suite's
        with tempfile.TemporaryDirectory() as tmp:
            device = TimedDevice(chart, Path(tmp))
            runs = data.draw(st.lists(st.lists(items, max_size=14), min_size=8, max_size=8))
            device.assert_equivalent([absolute(r) for r in runs])
            compiled += 1

    check()
    assert compiled >= 6, compiled


@pytest.mark.parametrize("ms", [250, 1000])
def test_the_tick_fires_exactly_at_the_deadline(tmp_path: Path, ms: int) -> None:
    """One millisecond before the deadline nothing happens; at it the timeout is taken."""
    chart = load_chart(CLAMP)
    chart = replace(
        chart,
        states=tuple(
            replace(s, timeout=Timeout(ms / 1000, "Close timeout")) if s.timeout else s
            for s in chart.states
        ),
    )
    device = TimedDevice(chart, tmp_path)
    before, at = device.traces([["Close", ms - 1], ["Close", ms]])
    assert before[-1] == "config Closing" and at[-1] == "config Jammed"
