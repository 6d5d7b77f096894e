"""pairs kills every non-equivalent mutant of the issue's kinds (docs/testing.md, "The mutation
check"): the driver's real API calls checked against the tables, probes that follow paths
whose events carry data, and probe failures that say what was expected and what happened."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import mutation
from statectl.front.builder.build import load_chart
from statectl.front.observers import Notification
from statectl.kernel.model import Chart
from statectl.out.testgen import generate
from statectl.out.testgen.harness import DeviceUnderTest
from statectl.run.devices import SimMotor, SimTwin
from support import MOTOR, ROOT
from test_testgen import counts, functions, run_pytest

PRESS = ROOT / "examples" / "press" / "press.yaml"
CLAMP = ROOT / "examples" / "modbus" / "clamp.yaml"


@pytest.mark.parametrize("file", [MOTOR, PRESS, CLAMP], ids=lambda f: f.name)
def test_pairs_kills_every_non_equivalent_mutant(file: Path) -> None:
    """Every mutant tests/mutation.py makes of the example is equivalent or fails pairs."""
    rows = mutation.score(file, ("pairs",))
    missed = [f"{r['kind']}: {r['name']}" for r in rows if not r["equivalent"] and not r["pairs"]]
    assert missed == []


# -- the driver's real API calls against the tables ------------------------------------------


class Again(SimTwin):
    """Makes the call the tables ask for twice."""

    def log_call(self, function: str, *args: Any) -> None:
        super().log_call(function, *args)
        super().log_call(function, *args)


class Poking(SimTwin):
    """Calls ``Poke()`` by itself when its work is done (a timer's call, no notification)."""

    def report(self, event: str, data: Any = None) -> None:
        self.log_call("Poke")
        super().report(event, data)


class Reversing(SimMotor):
    """SimMotor that also calls ``return_to`` (Initialization's API) on every Movement."""

    def update(self, notification: Notification) -> None:
        super().update(notification)
        if notification.method == "Movement":
            self.log_call("return_to", 0.0)


#: (driver maker, tables, events given, the problem named)
CALLS: list[tuple[str, Any, Path, tuple[Any, ...], str]] = [
    (
        "an extra call",
        mutation.ExtraCall,
        MOTOR,
        ("Movement",),
        "stray API call ExtraCall.Extra() serving Movement(): the tables make no such call here",
    ),
    (
        "a wrong argument",
        mutation.WrongArgument,
        MOTOR,
        ("Movement",),
        "API call WrongArgument.Movement(-1): wrong argument, the tables give Movement()",
    ),
    (
        "a wrong argument with event data",
        mutation.WrongArgument,
        PRESS,
        (["Press", {"pressure": 3.0}],),
        "API call WrongArgument.Stroke(-1): wrong argument, "
        "the tables give Stroke({'pressure': 3.0})",
    ),
    (
        "the call made twice",
        Again,
        MOTOR,
        ("Movement",),
        "stray API call Again.Movement() serving Movement(): the tables make one Movement() call",
    ),
    (
        "a call of another method's API function",
        lambda chart: Reversing(),
        MOTOR,
        (["Movement", {"amount": 5.0}],),
        "stray API call Reversing.return_to(0.0) serving Movement(): the tables make no such "
        "call here",
    ),
]


@pytest.mark.parametrize(
    ("bug", "make", "tables", "given", "message"), CALLS, ids=[c[0] for c in CALLS]
)
def test_a_call_the_tables_do_not_make_is_named(
    bug: str, make: Any, tables: Path, given: tuple[Any, ...], message: str
) -> None:
    """The calls the driver really made (its API log), not the notifications, are checked."""
    chart = load_chart(tables)
    d = DeviceUnderTest(chart, make(chart))
    with pytest.raises(AssertionError) as failed:
        d.given(*given)
    assert message in str(failed.value)


def test_a_call_made_by_itself_is_named() -> None:
    """A call the driver makes with no notification (here when its work is done) is a stray."""
    chart = load_chart(MOTOR)
    d = DeviceUnderTest(chart, Poking(chart))
    d.given("Movement")
    d.complete("Movement completion")
    with pytest.raises(AssertionError, match=r"stray API call Poking\.Poke\(\): the driver made"):
        d.expect(states=["Blocked"], invokes=[], raised=["Movement completion"])


def test_simmotor_stopping_before_a_new_target_is_no_stray() -> None:
    """A driver with its own API table may call outside it: SimMotor's stop() before return_to."""
    chart = load_chart(MOTOR)
    d = DeviceUnderTest(chart, SimMotor(), event_data={"Movement": {"amount": 5.0}})
    d.given("Movement")
    d.send("Error")
    d.expect(states=["Returning"], invokes=[[2, "Error"]])
    assert [api for _, api in d._seen.driver_calls or ()] == [
        "SimMotor.stop()",
        "SimMotor.return_to(0.0)",
    ]


def test_the_generated_suite_fails_a_driver_with_an_extra_call(tmp_path: Path) -> None:
    """The Motor's pairs module, run by pytest on a twin that calls Extra() too, fails naming it."""
    made = generate(MOTOR, "pairs", tmp_path)
    (tmp_path / "conftest.py").write_text(
        "import pytest\nfrom statectl.run.devices import SimTwin\n\n\n"
        "class Broken(SimTwin):\n"
        "    def log_call(self, function, *args):\n"
        "        super().log_call(function, *args)\n"
        "        super().log_call('Extra')\n"
        "\n\n@pytest.fixture\ndef statectl_new_driver():\n"
        "    return Broken\n",
        encoding="utf-8",
    )
    result = run_pytest(tmp_path, "-x")
    assert counts(result).get("failed") == 1, result.stdout[-3000:]
    assert "stray API call Broken.Extra() serving" in result.stdout, result.stdout[-3000:]
    assert made.tests > 1


# -- probes through paths whose events carry data ----------------------------------------------


def test_the_clamps_held_states_get_fault_and_monitor_tests(tmp_path: Path) -> None:
    """Clamped and Weak are reached only through Clamp completion with a pressure: the path
    sends it, and each gets its fault (Leak) and monitor test."""
    made = generate(CLAMP, "pairs", tmp_path)
    found = functions(made.path)
    for name in ("test_fault_02_clamped", "test_monitor_02_clamped", "test_fault_03_weak"):
        assert name in found, sorted(found)
    text = made.path.read_text(encoding="utf-8")
    assert 'd.given("Clamp", ["Clamp completion", {"pressure": 2.5}])\n    d.fault()' in text
    assert "no fault test" not in text


def test_the_press_stroke_gets_a_completion_test(tmp_path: Path) -> None:
    """Press carries data: its Stroke() call is still probed for its completion."""
    made = generate(PRESS, "pairs", tmp_path)
    text = made.path.read_text(encoding="utf-8")
    assert 'd.given(["Press", {"pressure": 2.5}])\n    d.complete("Stroke completion")' in text


# -- what a probe's failure says --------------------------------------------------------------


def _early(chart: Chart) -> SimTwin:
    return SimTwin(chart, delay=0.01)


def test_a_completion_during_the_monitor_test_is_called_a_completion() -> None:
    """The monitor test names what the device took and what it is, not "a fault"."""
    chart = load_chart(MOTOR)
    d = DeviceUnderTest(chart, _early(chart))
    d.given("Movement")
    with pytest.raises(AssertionError) as failed:
        d.assert_monitored("Moving")
    said = str(failed.value)
    assert "expected the monitor of Moving to poll 2 time(s) and raise nothing" in said
    assert "Movement completion (a completion the device reported)" in said
    assert "fault" not in said.split("the device took", 1)[1]


def test_a_fault_that_is_not_raised_names_the_state() -> None:
    """The fault test says in which state the device reported its fault."""
    chart = load_chart(MOTOR)

    class Silent(SimTwin):
        def poll_fault(self) -> str | None:
            return None

    d = DeviceUnderTest(chart, Silent(chart))
    d.given("Movement")
    d.fault()
    with pytest.raises(AssertionError) as failed:
        d.expect(states=["Returning"], invokes=[[2, "Error"]], raised=["Error"])
    said = str(failed.value)
    assert "(device fault in Moving)" in said
    assert "raised: expected ['Error'], the device took []" in said


def test_a_completion_not_reported_names_the_call_it_answers() -> None:
    """The completion test says which completion, within what, and for which call."""
    chart = load_chart(PRESS)
    d = DeviceUnderTest(chart, mutation.NeverCompletes(chart))
    d.given(["Press", {"pressure": 2.5}])
    with pytest.raises(AssertionError) as failed:
        d.complete("Stroke completion")
    said = str(failed.value)
    assert "expected the device to report Stroke completion within 5 s; it reported nothing" in said
    assert said.endswith("the device is in ['Pressing']; the call it answers: Stroke()")
