"""The clocks: SimClock is deterministic, WallClock never blocks its caller."""

from __future__ import annotations

import threading
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from statectl.kernel.errors import StatectlError
from statectl.run.runtime.clock import SimClock, WallClock


@pytest.mark.parametrize(
    ("delays", "advance", "expected"),
    [
        ([3.0, 1.0, 2.0], 5.0, ["1.0", "2.0", "3.0"]),
        ([1.0, 1.0, 1.0], 1.0, ["1.0", "1.0", "1.0"]),
        ([0.5, 2.0], 1.0, ["0.5"]),
        ([0.0], 0.0, ["0.0"]),
    ],
)
def test_due_timers_fire_in_time_order(
    delays: list[float], advance: float, expected: list[str]
) -> None:
    """advance() fires exactly the timers due by its end, earliest first."""
    clock = SimClock()
    fired: list[str] = []
    for d in delays:
        clock.call_later(d, lambda d=d: fired.append(str(d)))
    clock.advance(advance)
    assert fired == expected


def test_equal_times_fire_in_scheduling_order() -> None:
    """Timers due at the same time fire in the order they were scheduled."""
    clock = SimClock()
    fired: list[int] = []
    for i in range(5):
        clock.call_later(1.0, lambda i=i: fired.append(i))
    clock.advance(1.0)
    assert fired == [0, 1, 2, 3, 4]


@pytest.mark.parametrize(("inner", "fires"), [(0.5, True), (1.0, True), (1.5, False)])
def test_timer_scheduled_by_a_callback_fires_in_the_same_advance_if_due(
    inner: float, fires: bool
) -> None:
    """A callback's own timer fires during the advance when it is due by its end."""
    clock = SimClock()
    fired: list[float] = []
    clock.call_later(1.0, lambda: clock.call_later(inner, lambda: fired.append(clock.now())))
    clock.advance(2.0)
    assert (fired == [1.0 + inner]) is fires


def test_callback_sees_its_own_time() -> None:
    """During a callback now() is the timer's due time, after it the advance's end."""
    clock = SimClock(start=10.0)
    seen: list[float] = []
    clock.call_later(0.25, lambda: seen.append(clock.now()))
    clock.advance(1.0)
    assert seen == [10.25]
    assert clock.now() == 11.0


def test_cancelled_timer_never_fires() -> None:
    """cancel() before the due time stops the timer; after firing it is a no-op."""
    clock = SimClock()
    fired: list[str] = []
    a = clock.call_later(1.0, lambda: fired.append("a"))
    b = clock.call_later(2.0, lambda: fired.append("b"))
    a.cancel()
    clock.advance(3.0)
    b.cancel()
    assert fired == ["b"]
    assert clock.pending == 0


def test_next_deadline_skips_cancelled_timers() -> None:
    """next_deadline() names the earliest live timer, or None."""
    clock = SimClock()
    assert clock.next_deadline() is None
    clock.call_later(1.0, lambda: None).cancel()
    clock.call_later(2.0, lambda: None)
    assert clock.next_deadline() == 2.0


def test_settle_runs_after_every_timer() -> None:
    """The settle hook runs once after each fired timer, before the next one."""
    clock = SimClock()
    log: list[str] = []
    clock.call_later(1.0, lambda: log.append("t1"))
    clock.call_later(2.0, lambda: log.append("t2"))
    clock.advance(3.0, settle=lambda: log.append("settle"))
    assert log == ["t1", "settle", "t2", "settle"]


@pytest.mark.parametrize("delay", [-1.0, float("nan")])
def test_bad_delay_is_refused(delay: float) -> None:
    """A negative or NaN delay is an error, not a timer in the past."""
    with pytest.raises(StatectlError, match="delay"):
        SimClock().call_later(delay, lambda: None)


def test_sim_clock_cannot_go_back() -> None:
    """run_until() to an earlier time is an error."""
    clock = SimClock(start=5.0)
    with pytest.raises(StatectlError, match="back in time"):
        clock.run_until(4.0)


@given(st.lists(st.floats(min_value=0, max_value=100, allow_nan=False), max_size=30))
def test_fired_order_is_sorted_by_time_then_sequence(delays: list[float]) -> None:
    """Whatever the delays, timers fire sorted by (due time, scheduling order)."""
    clock = SimClock()
    fired: list[int] = []
    for i, d in enumerate(delays):
        clock.call_later(d, lambda i=i: fired.append(i))
    clock.advance(100.0)
    assert fired == sorted(range(len(delays)), key=lambda i: (delays[i], i))
    assert clock.now() == 100.0


def test_wall_clock_runs_timers_off_the_callers_thread() -> None:
    """call_later returns at once; the callback runs on the timer thread."""
    clock = WallClock()
    done = threading.Event()
    where: list[threading.Thread] = []
    clock.call_later(0.0, lambda: (where.append(threading.current_thread()), done.set()))
    assert done.wait(5.0)
    clock.stop()
    assert where and where[0] is not threading.current_thread()


def test_wall_clock_waits_past_a_timer_further_than_the_os_can_wait() -> None:
    """A timer due later than threading.TIMEOUT_MAX leaves the timer thread alive (its wait
    raised OverflowError and killed it): a sooner timer added afterwards still fires."""
    clock = WallClock()
    clock.call_later(threading.TIMEOUT_MAX * 4, lambda: None)
    time.sleep(0.2)  # time for the timer thread to start waiting for it
    assert clock._thread is not None and clock._thread.is_alive()
    done = threading.Event()
    clock.call_later(0.0, done.set)
    assert done.wait(5.0)
    clock.stop()


def test_wall_clock_survives_a_failing_callback() -> None:
    """A callback that raises goes to on_error; later timers still fire."""
    errors: list[BaseException] = []
    clock = WallClock(on_error=errors.append)
    done = threading.Event()

    def boom() -> None:
        raise RuntimeError("boom")

    clock.call_later(0.0, boom)
    clock.call_later(0.0, done.set)
    assert done.wait(5.0)
    clock.stop()
    assert [str(e) for e in errors] == ["boom"]


def test_stopped_wall_clock_refuses_timers() -> None:
    """After stop() a WallClock takes no new timers."""
    clock = WallClock()
    clock.stop()
    with pytest.raises(StatectlError, match="stopped"):
        clock.call_later(0.0, lambda: None)


def test_work_only_deadline_skips_background_timers() -> None:
    """next_deadline(work_only=True) ignores background timers (monitor polls), not work."""
    clock = SimClock()
    clock.call_later(0.1, lambda: None, background=True)
    assert clock.next_deadline() == 0.1
    assert clock.next_deadline(work_only=True) is None
    work = clock.call_later(3.0, lambda: None)
    assert clock.next_deadline(work_only=True) == 3.0
    work.cancel()
    assert clock.next_deadline(work_only=True) is None


def test_cancelled_timers_do_not_pile_up_while_time_stands_still() -> None:
    """A timer started and cancelled per event (a monitor) keeps the heap within 2x live."""
    clock = SimClock()
    keep = [clock.call_later(5.0, lambda: None) for _ in range(10)]
    for _ in range(100_000):
        clock.call_later(1.0, lambda: None, background=True).cancel()
    assert len(clock._heap) <= max(64, 2 * 10) + 1  # the private heap: the point of the test
    assert clock.pending == 10
    assert all(not t.cancelled for t in keep)


def test_compacting_keeps_the_firing_order() -> None:
    """Timers that survive a compaction fire in (time, scheduling) order."""
    clock = SimClock()
    fired: list[int] = []
    for i in range(200):
        t = clock.call_later(float(i % 7), lambda i=i: fired.append(i))
        if i % 3 == 0:
            t.cancel()
    clock.advance(10.0)
    expected = sorted((i for i in range(200) if i % 3), key=lambda i: (i % 7, i))
    assert fired == expected
