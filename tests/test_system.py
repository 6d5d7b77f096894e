"""The System a host embeds: many devices, one owner, bounded queues, asyncio."""

from __future__ import annotations

import asyncio
import threading
import time

import pytest

from statectl import MicrostepTaken, QueueFull, SimClock, StatectlError, System, WallClock
from statectl.kernel.model import Chart
from statectl.run.system import DeviceSetup
from support import Recorder

WAIT = 10.0  # a bound on the owner loop's work, not a measurement


def _system(motor: Chart, n: int, **kw: object) -> System:
    setups = tuple(DeviceSetup(f"M{i}", motor) for i in range(n))
    return System(setups, SimClock(), **kw)  # type: ignore[arg-type]  # System's own options


def test_the_owner_visits_only_devices_with_work(motor: Chart) -> None:
    """Draining runs the devices that had something posted, and each of their events."""
    system = _system(motor, 50)
    system.start()
    touched = [system.subjects[f"M{i}"] for i in (3, 17, 42)]
    for s in touched:
        system.post(s.name, "Movement")
    assert system.drain() == 3
    assert [s.configuration for s in touched] == [{"Moving"}] * 3
    assert sum(s.events_processed for s in system.subjects.values()) == 3
    system.close()


def test_events_posted_before_the_start_are_run_at_the_start(motor: Chart) -> None:
    """A device's queue filled before start() is not forgotten by the ready list."""
    system = _system(motor, 2)
    system.subjects["M1"].post("Movement")
    system.start()
    system.drain()
    assert system.subjects["M1"].configuration == {"Moving"}
    system.close()


@pytest.mark.parametrize("clock", [SimClock, WallClock])
def test_events_posted_before_stop_are_run_before_serve_returns(
    motor: Chart, clock: type[SimClock] | type[WallClock]
) -> None:
    """A live run's feeder posts the last line and sets stop at once: serve() still runs
    that event (it used to return at the stop and drop it)."""
    system = System((DeviceSetup("M", motor),), clock())
    system.start()
    system.post("M", "Movement")
    stop = threading.Event()
    stop.set()
    system.serve(stop)
    assert system.subjects["M"].configuration == {"Moving"}
    system.close()


@pytest.mark.parametrize(("paced", "stop_first"), [(True, False), (False, False), (False, True)])
def test_a_driver_that_refuses_an_events_data_fails_that_event_only(
    motor: Chart, paced: bool, stop_first: bool
) -> None:
    """In the live owner loop (and its last drain at the stop) a driver raising on bad
    data ({amount: abc}) goes to on_failure and the loop goes on: the device's next event
    and the other devices run (the error used to leave serve() and end a --realtime or
    --dashboard run)."""
    from statectl.run.devices import SimMotor

    setups = (DeviceSetup("A", motor, driver=SimMotor()), DeviceSetup("B", motor))
    system = System(setups, SimClock())
    failures: list[str] = []
    system.on_failure.append(lambda exc: failures.append(str(exc)))
    system.start()
    stop = threading.Event()
    if stop_first:
        stop.set()
    system.post("A", "Movement", {"amount": "abc"})
    system.post("A", "Error")
    system.post("B", "Movement")
    owner = threading.Thread(target=system.serve, args=(stop,), kwargs={"paced": paced})
    owner.start()
    deadline = time.monotonic() + WAIT
    while owner.is_alive() and system.subjects["B"].configuration != {"Moving"}:
        assert time.monotonic() < deadline, "the owner loop stopped serving"
        time.sleep(0.01)
    stop.set()
    owner.join(WAIT)
    assert [("a movement needs" in f) for f in failures] == [True]
    assert system.subjects["B"].configuration == {"Moving"}
    assert system.subjects["A"].configuration != {"Moving"}  # Error left it
    system.close()


def test_a_full_queue_refuses_with_queue_full(motor: Chart) -> None:
    """With max_queue, the event past the limit raises QueueFull; the queue keeps the rest."""
    system = _system(motor, 1, max_queue=3)
    system.start()
    for _ in range(3):
        system.post("M0", "Movement")
    with pytest.raises(QueueFull, match="3 events are queued already"):
        system.post("M0", "Movement")
    assert system.subjects["M0"].queued == 3
    system.drain()
    system.post("M0", "Movement completion")  # room again once the device caught up
    system.close()


def test_max_queue_must_be_positive(motor: Chart) -> None:
    """A max_queue below 1 is a usage error at construction."""
    with pytest.raises(StatectlError, match="max_queue must be at least 1"):
        _system(motor, 1, max_queue=0)


def test_two_devices_with_one_name_are_refused(motor: Chart) -> None:
    """Names address devices, so they must be unique."""
    with pytest.raises(StatectlError, match="two devices are named 'A'"):
        System((DeviceSetup("A", motor), DeviceSetup("A", motor)), SimClock())


def test_many_posting_threads_lose_nothing(motor: Chart) -> None:
    """Four threads posting to 200 devices while the owner runs: every event is processed."""
    system = _system(motor, 200)
    recorders = {}
    for name, s in system.subjects.items():
        recorders[name] = Recorder()
        s.attach(recorders[name])
    system.start()
    halt = system.start_owner(paced=False)
    names = list(system.subjects)

    def feed(mine: list[str]) -> None:
        for _ in range(5):
            for name in mine:
                system.post(name, "Movement")
                system.post(name, "Movement completion")

    posters = [threading.Thread(target=feed, args=(names[k::4],)) for k in range(4)]
    for p in posters:
        p.start()
    for p in posters:
        p.join()
    system.drain()
    halt()
    assert sum(s.events_processed for s in system.subjects.values()) == 200 * 10
    assert all(len(r.seen) == 5 for r in recorders.values())
    system.close()


def test_send_resolves_with_the_outcome(motor: Chart) -> None:
    """await send() returns once the device ran the event: handled, or why not."""
    system = _system(motor, 1)
    system.start()
    halt = system.start_owner(paced=False)

    async def main() -> list[str]:
        return [
            await system.send("M0", "Initialization"),  # its guard: previous == 'Moving'
            await system.send("M0", "Movement"),
            await system.send("M0", "Movement"),  # Moving declares Movement ignored
            await system.send("M0", "Bogus"),
        ]

    try:
        outcomes = asyncio.run(asyncio.wait_for(main(), 10))
    finally:
        halt()
    # Initialization's guard is false in Blocked, which lists it as ignored for that case
    assert outcomes == ["declared ignored", "handled", "declared ignored", "unknown event"]
    assert system.subjects["M0"].configuration == {"Moving"}
    system.close()


def test_records_iterate_every_devices_records(motor: Chart) -> None:
    """async for over records() sees the states each device enters, in order."""
    system = _system(motor, 2)
    system.start()
    halt = system.start_owner(paced=False)

    async def main() -> list[tuple[str, str]]:
        seen: list[tuple[str, str]] = []
        stream = system.records()
        reader = asyncio.ensure_future(_collect(stream, seen, 4))
        await asyncio.sleep(0)  # the iterator is listening before anything happens
        await system.send("M0", "Movement")
        await system.send("M1", "Movement")
        await system.send("M0", "Movement completion")
        await system.send("M1", "Movement completion")
        await asyncio.wait_for(reader, 10)
        await stream.aclose()
        return seen

    try:
        seen = asyncio.run(main())
    finally:
        halt()
    assert seen == [("M0", "Moving"), ("M1", "Moving"), ("M0", "Blocked"), ("M1", "Blocked")]
    assert not any(s.listening for s in system.subjects.values())  # the listener left
    system.close()


async def _collect(stream: object, seen: list[tuple[str, str]], n: int) -> None:
    async for r in stream:  # type: ignore[attr-defined]  # an async generator
        if isinstance(r, MicrostepTaken):
            seen.extend((r.device, s) for s in r.entered)
            if len(seen) == n:
                return


def test_send_runs_on_a_journalled_system_too(motor: Chart, tmp_path: object) -> None:
    """send() on a journalled System accepts through the journal and resolves once the
    device ran the event (it used to refuse: use post() and wait for the ticket)."""
    from pathlib import Path

    from statectl.run.journal import Journal, JournalReader

    path = Path(str(tmp_path)) / "j.db"
    system = System((DeviceSetup("M0", motor),), SimClock(), Journal(path))
    system.start()
    assert asyncio.run(system.send("M0", "Movement")) == "handled"
    assert system.subjects["M0"].configuration == {"Moving"}
    system.close()
    with JournalReader(path) as reader:
        assert [r.event for r in reader.pending("M0")] == []  # accepted and processed
        last = reader.last_step("M0")
        assert last is not None and last.event == "Movement" and last.inbox is not None


def test_a_driver_given_where_the_rules_go_is_refused(motor: Chart) -> None:
    """``DeviceSetup(name, chart, driver)``: the third field is the rules, so it is a TypeError.

    Otherwise the driver lands in ``rules`` and the device runs with no driver at all.
    """
    from statectl.run.devices import SimMotor

    with pytest.raises(TypeError, match="give a driver as driver="):
        DeviceSetup("M", motor, SimMotor())  # type: ignore[arg-type]  # the mistake tested
    assert isinstance(DeviceSetup("M", motor, driver=SimMotor()).driver, SimMotor)


def test_a_realtime_run_goes_on_past_a_driver_refusing_a_line_and_exits_1() -> None:
    """`statectl run --realtime`: a line whose data the driver refuses is reported, the
    next lines still run, and the run exits 1 saying so (it used to stop at that line)."""
    import io
    from pathlib import Path

    from statectl.channels.cli.run import run

    motor = Path(__file__).parent.parent / "examples" / "motor" / "motor.yaml"
    out, err = io.StringIO(), io.StringIO()
    lines = io.StringIO("Movement {amount: abc}\nError\n")
    code = run(str(motor), driver="sim-motor", realtime=True, events=lines, out=out, err=err)
    said = err.getvalue()
    assert (code, "a movement needs" in said, "1 event(s) a driver refused" in said) == (
        1,
        True,
        True,
    ), said
    assert "Moving -> Returning  on Error" in out.getvalue()


def test_a_driver_failure_on_the_journal_writers_drain_is_reported(
    motor: Chart, tmp_path: object
) -> None:
    """Under durable-first the journal's writer runs the events it committed; a driver that
    refuses an event's data there goes to on_failure and the next event runs (it used to
    print a traceback on the writer's thread and count for nothing)."""
    from pathlib import Path

    from statectl.run.devices import SimMotor
    from statectl.run.journal import Journal

    journal = Journal(Path(str(tmp_path)) / "j.db", guarantee="durable-first")
    system = System((DeviceSetup("A", motor, driver=SimMotor()),), SimClock(), journal)
    failures: list[str] = []
    system.on_failure.append(lambda exc: failures.append(str(exc)))
    system.start()
    for event, data in (("Movement", {"amount": "abc"}), ("Error", None)):
        ticket = system.post("A", event, data)
        assert ticket is not None
        ticket.wait()
    deadline = time.monotonic() + WAIT
    while system.subjects["A"].configuration == {"Moving"} and time.monotonic() < deadline:
        time.sleep(0.01)
    system.close()
    assert [("a movement needs" in f) for f in failures] == [True]
    assert system.subjects["A"].configuration != {"Moving"}  # Error ran after the failure
