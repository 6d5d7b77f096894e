"""One execution path: a wired device (monitors, journal, driver) takes the same plans.

The kernel is asked only for a step it has not planned yet; everything that hooks a
device hooks the step (watchers, step listeners), never a record stream it did not ask for.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import statectl.run.runtime.engine as engine_module
from statectl.kernel.model import Chart
from statectl.kernel.semantics import Outcome, Unhandled
from statectl.run.devices import connect, make_driver
from statectl.run.journal import Journal
from statectl.run.journal.device import JournalledDevice
from statectl.run.runtime import SimClock, Subject, attach_monitors
from statectl.run.runtime.program import program_of
from support import QuietFaults, Recorder

#: The paper's cycle without its guarded event: every step is plannable today.
CYCLE = ("Movement", "Movement completion", "Movement", "Error", "Error completion")


class Watcher:
    """A StateWatcher that writes down what it hears."""

    def __init__(self) -> None:
        self.heard: list[tuple[str, str]] = []

    def entered(self, state: str) -> None:
        self.heard.append(("entered", state))

    def exited(self, state: str) -> None:
        self.heard.append(("exited", state))

    def finished(self) -> None:
        self.heard.append(("finished", ""))


def _count_kernel_steps(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    asked: list[str] = []
    real = engine_module.step

    def counting(machine: Any, snapshot: Any, event: str, *args: Any, **kw: Any) -> Any:
        asked.append(event)
        return real(machine, snapshot, event, *args, **kw)

    monkeypatch.setattr(engine_module, "step", counting)
    return asked


def _wired(motor: Chart, wiring: str, tmp_path: Path) -> Subject:
    subject = Subject(motor, clock=SimClock())
    if wiring == "monitor":
        subject.attach(Recorder())
        attach_monitors(subject, QuietFaults())
    elif wiring == "driver":
        connect(subject, make_driver("sim-motor", {}, chart=motor))
    elif wiring == "journal":
        subject.attach(Recorder())
        JournalledDevice(subject, Journal(tmp_path / "j.db")).start()
        return subject
    else:
        subject.attach(Recorder())
    subject.start()
    return subject


@pytest.mark.parametrize("wiring", ["bare", "monitor", "driver", "journal"])
def test_a_planned_step_never_asks_the_kernel_again(
    motor: Chart, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, wiring: str
) -> None:
    """After two warm cycles (the second starts from Blocked with a previous state),
    the same cycle is taken from plans whatever is attached."""
    subject = _wired(motor, wiring, tmp_path)
    data = {"Movement": {"amount": 1}} if wiring == "driver" else {}
    for e in CYCLE * 2:
        subject.dispatch(e, data.get(e))
    asked = _count_kernel_steps(monkeypatch)
    for e in CYCLE:
        subject.dispatch(e, data.get(e))
    assert subject.configuration == {"Blocked"}
    assert asked == []


def test_a_watcher_hears_its_states_in_step_order(motor: Chart) -> None:
    """Entered and exited come for the watched states only, as the step takes them."""
    subject = Subject(motor, clock=SimClock())
    watcher = Watcher()
    subject.watch(["Moving", "Returning"], watcher)
    subject.start()
    for e in CYCLE:
        subject.dispatch(e)
    subject.close()
    assert watcher.heard == [
        ("entered", "Moving"),
        ("exited", "Moving"),
        ("entered", "Moving"),
        ("exited", "Moving"),
        ("entered", "Returning"),
        ("exited", "Returning"),
        ("finished", ""),
    ]


def test_a_watcher_hears_the_same_with_or_without_records(motor: Chart) -> None:
    """A record listener changes nothing a watcher hears (plan path and record path agree)."""
    heard = []
    for listen in (False, True):
        subject = Subject(motor, clock=SimClock())
        watcher = Watcher()
        subject.watch(["Blocked", "Moving"], watcher)
        if listen:
            subject.listen(lambda r: None)
        subject.start()
        for e in CYCLE:
            subject.dispatch(e, {"n": 1} if e == "Error" else None)
        heard.append(watcher.heard)
    assert heard[0] == heard[1]
    assert heard[0][0] == ("entered", "Blocked")


def test_watching_an_unknown_state_is_refused(motor: Chart) -> None:
    """A typo in a watched state's name is an error at once, naming the chart."""
    subject = Subject(motor, clock=SimClock())
    with pytest.raises(Exception, match="no state \\['Movin'\\]"):
        subject.watch(["Movin"], Watcher())


def test_undoing_a_watch_stops_the_calls(motor: Chart) -> None:
    """The function watch() returns removes the watcher from planned steps too."""
    subject = Subject(motor, clock=SimClock())
    watcher = Watcher()
    off = subject.watch(["Moving"], watcher)
    subject.start()
    subject.dispatch("Movement")
    off()
    subject.dispatch("Movement completion")
    subject.dispatch("Movement")
    assert watcher.heard == [("entered", "Moving")]


class Refusing:
    """An observer that refuses every call, as a driver refuses data it cannot use."""

    def update(self, notification: Any) -> None:
        raise ValueError(f"refused {notification.method}")


@pytest.mark.parametrize("path", ["plan", "kernel"])
@pytest.mark.parametrize("listening", ["none", "steps", "records"])
def test_a_step_whose_observer_raises_is_still_heard_as_taken(
    motor: Chart, path: str, listening: str
) -> None:
    """The transition is committed before the observer runs, so when the observer raises
    the on_step hooks still hear the step as handled (the journal writes its row: replay
    and resume agree with the device), and the error reaches the caller."""
    subject = Subject(motor, clock=SimClock())
    subject.attach(Refusing())
    if listening == "steps":
        subject.listen_steps(lambda step: None)
    elif listening == "records":
        subject.listen(lambda record: None)
    heard: list[tuple[str, str]] = []
    subject.on_step(lambda event, data, outcome: heard.append((event, str(outcome))))
    subject.start()
    if path == "kernel":
        subject._engine.table = {}  # no plan: the kernel decides the step
    with pytest.raises(ValueError, match="refused"):
        subject.dispatch("Movement")
    assert subject.configuration == {"Moving"}
    assert heard == [("Movement", "handled")]


def test_every_step_is_performed_by_the_one_engine_method(
    motor: Chart, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The start, dispatch(), post() + run_until_idle(), a timer's deliver() and a
    recovery's reissue() all perform their step through Engine.perform, heard or not
    (but for a start that only moves, unheard: the Motor's notifies nobody)."""
    performed: list[str | None] = []
    real = engine_module.Engine.perform

    def counting(self: Any, event: str | None, *args: Any, **kw: Any) -> Any:
        performed.append(event)
        return real(self, event, *args, **kw)

    monkeypatch.setattr(engine_module.Engine, "perform", counting)
    for listen in (False, True):
        performed.clear()
        subject = Subject(motor, clock=SimClock())
        subject.attach(Recorder())
        if listen:
            subject.listen_steps(lambda step: None)
        subject.start()
        subject.dispatch("Movement")
        subject.post("Movement completion")
        subject.run_until_idle()
        subject.deliver("Jump")
        subject.reissue(subject.machine.plans(subject.snapshot)["Movement"].step)  # type: ignore[arg-type]
        start = [None] if listen else []
        assert performed == [*start, "Movement", "Movement completion", "Jump", None]


def test_a_step_compiles_once_into_a_program_every_device_shares(motor: Chart) -> None:
    """Two devices of one chart perform a planned step from the same Program, whose
    effects are the step's in order: transition, exits, entries, notifications."""
    devices = [Subject(motor, clock=SimClock()) for _ in range(2)]
    for subject in devices:
        subject.attach(Recorder())
        subject.start()
    plan = devices[0].machine.plans(devices[0].snapshot)["Movement"]  # type: ignore[arg-type]
    for subject in devices:
        subject.dispatch("Movement")
    first, second = (d._engine._bound[plan].program for d in devices)
    assert first is second is program_of(plan.step, plan.table)
    kinds = [type(e).__name__ for e in first.effects]
    assert kinds == ["Transit", "Exit", "Enter", "Notify"]
    assert (first.outcome, first.invokes) == (Outcome.HANDLED, 1)


def test_the_outcome_is_one_enum_that_says_handled(motor: Chart) -> None:
    """Step listeners and then() hear an Outcome: HANDLED or the reason; each equals the
    string users see and the journal stores."""
    heard: list[object] = []
    subject = Subject(motor, clock=SimClock())
    subject.on_step(lambda event, data, outcome: heard.append(outcome))
    subject.start()
    subject.post("Initialization")  # declared ignored in Blocked
    subject.post("Movement", then=heard.append)
    subject.run_until_idle()
    assert heard == [Outcome.DECLARED_IGNORED, Outcome.HANDLED, Outcome.HANDLED]
    assert all(type(o) is Outcome for o in heard)
    assert heard[1] == "handled" and str(heard[0]) == "declared ignored"
    assert Unhandled is Outcome
