"""The SCXML session, section by section, on a simulated clock (no W3C pack needed)."""

from __future__ import annotations

import pytest

from statectl.kernel.semantics import Event
from statectl.out.scxml import Scheduler, Session, SimulatedClock, read_scxml
from statectl.out.scxml.xmltree import SCXML_NS

#: A wrapper state that logs the name of every event no inner state handles.
LOGGER = '<transition event="*"><log expr="_event.name"/></transition>'


def run(
    body: str, datamodel: str = "python", until: float = 100.0
) -> tuple[str | None, list[str], float]:
    """Run a document body; return the final state reached, the log and the clock time."""
    text = f'<scxml xmlns="{SCXML_NS}" version="1.0" datamodel="{datamodel}">{body}</scxml>'
    chart, diagnostics = read_scxml(text)
    assert chart is not None, diagnostics
    clock = SimulatedClock()
    log: list[str] = []
    scheduler = Scheduler(clock, log.append)
    final = scheduler.run(Session(chart, scheduler), until)
    return final, log, clock.now()


def logged(inner: str, datamodel: str = "python") -> list[str]:
    return run(f'<state id="top">{LOGGER}{inner}</state>', datamodel)[1]


@pytest.mark.parametrize(
    ("inner", "expected"),
    [
        # 3.12 the internal queue keeps the order content raised it in
        (
            '<state id="p"><onentry><raise event="r"/></onentry><final id="f"/></state>',
            ["r", "done.state.p"],
        ),
        # 5.10 error.execution goes on the internal queue at once; the next handler still runs
        (
            '<state id="s"><onentry><assign location="nope" expr="1"/></onentry>'
            '<onentry><raise event="after"/></onentry></state>',
            ["error.execution", "after"],
        ),
        # 4.1 an error ends the rest of its block
        (
            '<state id="s"><onentry><raise event="a"/><assign location="nope" expr="1"/>'
            '<raise event="never"/></onentry></state>',
            ["a", "error.execution"],
        ),
        # 3.13 internal events come before external ones
        (
            '<state id="s"><onentry><send event="ext"/><raise event="int"/></onentry></state>',
            ["int", "ext"],
        ),
        # 3.4 a parallel's done event follows its regions' done events
        (
            '<parallel id="p"><state id="a"><final id="af"/></state>'
            '<state id="b"><final id="bf"/></state></parallel>',
            ["done.state.a", "done.state.b", "done.state.p"],
        ),
        # 5.9 a failing condition is false and raises error.execution
        (
            '<state id="s"><onentry><raise event="go"/></onentry>'
            '<transition event="go" cond="1/0" target="s"><log expr="\'taken\'"/></transition>'
            "</state>",
            ["go", "error.execution"],
        ),
    ],
)
def test_internal_queue_order(inner: str, expected: list[str]) -> None:
    """Events reach the chart in the order the spec puts them on the queues."""
    assert logged(inner) == expected


@pytest.mark.parametrize(
    ("inner", "expected"),
    [
        # a descendant's transition preempts its ancestor's
        (
            '<state id="o"><transition event="e" target="o2"/><state id="i">'
            '<transition event="e" target="i2"/></state><state id="i2">'
            "<onentry><log expr=\"'inner'\"/></onentry></state></state>"
            '<state id="o2"><onentry><log expr="\'outer\'"/></onentry></state>',
            ["inner"],
        ),
        # parallel regions both take non-conflicting transitions, in document order
        (
            '<parallel id="p"><state id="a"><transition event="e"><log expr="\'a\'"/>'
            '</transition></state><state id="b"><transition event="e"><log expr="\'b\'"/>'
            "</transition></state></parallel>",
            ["a", "b"],
        ),
        # two regions leaving the parallel conflict: the first in document order wins
        (
            '<parallel id="p"><state id="a"><transition event="e" target="x"/></state>'
            '<state id="b"><transition event="e" target="y"/></state></parallel>'
            '<state id="x"><onentry><log expr="\'x\'"/></onentry></state>'
            '<state id="y"><onentry><log expr="\'y\'"/></onentry></state>',
            ["x"],
        ),
    ],
)
def test_conflicting_transitions(inner: str, expected: list[str]) -> None:
    """removeConflictingTransitions keeps the spec's winners."""
    assert logged(inner + '<onentry><raise event="e"/></onentry>') == expected


@pytest.mark.parametrize(
    ("history", "expected"),
    [
        ("shallow", "b1"),  # shallow history re-enters b, whose initial child is b1
        ("deep", "b2"),  # deep history re-enters the atomic state b2 itself
    ],
)
def test_history_restores_configuration(history: str, expected: str) -> None:
    """Leaving and re-entering through history restores the saved configuration."""
    body = (
        f'<state id="c" initial="a"><history id="h" type="{history}"><transition target="a"/>'
        '</history><state id="a"><transition event="go" target="b2"/></state>'
        '<state id="b"><state id="b1"/><state id="b2"/></state>'
        '<transition event="out" target="away"/></state>'
        '<state id="away"><transition event="back" target="h"/></state>'
    )
    chart, _ = read_scxml(f'<scxml xmlns="{SCXML_NS}" version="1.0">{body}</scxml>')
    assert chart is not None
    scheduler = Scheduler(SimulatedClock())
    session = Session(chart, scheduler)
    for name in ("go", "out", "back"):
        session.post(Event(name, type="external"))
    scheduler.run_ready()
    assert sorted(session.run.active) == sorted(["c", "b", expected])


def test_history_default_content_runs() -> None:
    """A history state with no value runs its default transition's content on entry."""
    inner = (
        '<state id="c"><history id="h"><transition target="a"><log expr="\'default\'"/>'
        '</transition></history><state id="a"/></state>'
        '<state id="s"><onentry><raise event="go"/></onentry>'
        '<transition event="go" target="h"/></state>'
    )
    _, log, _ = run(f'<state id="top" initial="s">{inner}</state>')
    assert log == ["default"]


@pytest.mark.parametrize(
    ("sends", "expected", "elapsed"),
    [
        (
            '<send event="late" delay="2s"/><send event="soon" delay="1s"/><send event="now"/>',
            ["now", "soon", "late"],
            2.0,
        ),
        (
            '<send event="a" delay="1s" id="x"/><send event="b" delay="500ms"/>'
            '<cancel sendid="x"/>',
            ["b"],
            0.5,
        ),
        ('<send event="e" delayexpr="\'1.5s\'"/>', ["e"], 1.5),
    ],
)
def test_delayed_sends_on_simulated_clock(sends: str, expected: list[str], elapsed: float) -> None:
    """Delayed sends arrive in order of due time; cancel removes one; time only jumps."""
    _, log, now = run(
        f'<state id="top">{LOGGER}<state id="s"><onentry>{sends}</onentry></state></state>'
    )
    assert (log, now) == (expected, elapsed)


@pytest.mark.parametrize(
    ("datamodel", "cond", "expected"),
    [
        ("null", "In('s')", "pass"),
        ("null", "In('other')", "fail"),
        ("null", "1 + 1 == 2", "fail"),  # the null datamodel evaluates only In()
        ("safe", "x == 3 and In('s')", "pass"),
        ("python", "isinstance(x, int)", "pass"),
    ],
)
def test_datamodels_evaluate_conditions(datamodel: str, cond: str, expected: str) -> None:
    """Each datamodel evaluates what it supports and fails the rest."""
    data = '<datamodel><data id="x" expr="3"/></datamodel>' if datamodel != "null" else ""
    body = (
        f'{data}<state id="s"><transition cond="{cond}" target="pass"/>'
        '<transition target="fail"/></state><final id="pass"/><final id="fail"/>'
    )
    assert run(body, datamodel)[0] == expected


def test_safe_datamodel_refuses_scripts_when_it_loads() -> None:
    """A <script> in the safe datamodel is refused as the document loads (X302), never run."""
    text = (
        f'<scxml xmlns="{SCXML_NS}" version="1.0" datamodel="safe">\n'
        '<state id="s"><onentry>\n<script>import os</script></onentry></state></scxml>'
    )
    chart, diagnostics = read_scxml(text)
    assert chart is None
    assert [(d.code, d.where.line) for d in diagnostics] == [("X302", 3)]


def test_invoke_child_talks_to_parent() -> None:
    """An invoked child's sends reach the parent, then done.invoke with its donedata."""
    body = (
        '<state id="s"><invoke id="kid"><content><scxml xmlns="' + SCXML_NS + '" version="1.0"'
        ' datamodel="python"><final id="end"><onentry><send target="#_parent" event="hi"/>'
        '</onentry><donedata><param name="v" expr="7"/></donedata></final></scxml></content>'
        '</invoke><transition event="hi" target="t"/></state>'
        '<state id="t"><transition event="done.invoke.kid" cond="_event.data.v == 7"'
        ' target="pass"/></state><final id="pass"/>'
    )
    assert run(body)[0] == "pass"


def test_system_variables_are_read_only() -> None:
    """Assigning _sessionid is an error.execution and leaves it unchanged."""
    body = (
        '<datamodel><data id="before" expr="_sessionid"/></datamodel><state id="s">'
        '<onentry><assign location="_sessionid" expr="\'x\'"/></onentry>'
        '<transition event="error.execution" cond="_sessionid == before" target="pass"/>'
        '</state><final id="pass"/>'
    )
    assert run(body)[0] == "pass"


TIMED = (
    '<state id="s"><onentry><send event="go" delay="2s"/></onentry>'
    '<transition event="go" target="done"/></state><final id="done"/>'
)


def test_a_document_and_a_device_timer_share_the_runtimes_simclock() -> None:
    """On the runtime's SimClock a document's timers and a device's fire in time order."""
    from statectl.run.runtime import SimClock

    clock = SimClock()
    fired: list[tuple[str, float]] = []
    clock.call_later(1.0, lambda: fired.append(("device", clock.now())))
    clock.call_later(3.0, lambda: fired.append(("late device", clock.now())))
    chart, diagnostics = read_scxml(f'<scxml xmlns="{SCXML_NS}" version="1.0">{TIMED}</scxml>')
    assert chart is not None, diagnostics
    scheduler = Scheduler(clock)
    final = scheduler.run(Session(chart, scheduler), 10.0)
    assert (final, fired, clock.now(), clock.pending) == ("done", [("device", 1.0)], 2.0, 1)


def test_a_document_on_the_wall_clock_really_waits() -> None:
    """On a WallClock a delayed send fires on the clock's thread; the scheduler delivers it."""
    from statectl.run.runtime import WallClock

    clock = WallClock()
    body = TIMED.replace('delay="2s"', 'delay="50ms"')
    chart, diagnostics = read_scxml(f'<scxml xmlns="{SCXML_NS}" version="1.0">{body}</scxml>')
    assert chart is not None, diagnostics
    scheduler = Scheduler(clock)
    try:
        final = scheduler.run(Session(chart, scheduler), clock.now() + 5.0)
        elapsed = clock.now()
    finally:
        clock.stop()
    assert final == "done" and 0.05 <= elapsed < 5.0
