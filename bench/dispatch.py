"""Dispatch speed and instance cost of statectl against its peers, in one process.

Rules:
1. Every contender runs the same work: the paper's whole Motor cycle with one
   observer attached (Movement, Movement completion, Initialization [previous ==
   'Moving'], Initialization completion, Movement, Error, Error completion, and
   Initialization again with its guard false: eight events, four notifications), a
   generated chart of 50
   states nested two levels deep (a 50-event cycle through every leaf, half by leaf
   transitions and the rest by transitions of the parent), and building a new
   started instance.
2. statectl is also measured the way users wire it, each a row of its own: with a
   listener that asked for records (a step-record listener that reads nothing, one
   that reads every typed record, and a ``listen()`` listener), with the
   Moving monitor, with the simulated motor connected as ``statectl demo`` connects
   it (driver + monitor), the same with a step-record listener that reads nothing (what
   ``statectl run``'s problem count adds), with a journal (SQLite, default guarantee), with the
   dashboard (what its owner thread pays; the page's loop is not running), with the
   trace writer (as a step listener and as a record listener), and through
   ``post()``. The worst row is reported beside the best.
2a. A wired row runs the cycle as the paper's device lives it: the simulated clock
   moves (:data:`CLOCKED`), so the Moving monitor polls every 0.1 s while the motor
   travels, the motor reports its completions itself when it arrives, and the Error
   is the monitor's (a fault injected during the second movement); only the
   commands are posted. The Moving-monitor row (no driver) moves the clock the same
   and posts the completions. The bare and listener rows dispatch all eight events,
   and so does one demo-wired row with the clock still (no poll, no completion of the
   motor's own: the figure earlier versions of this script gave as "wired as the demo").
2b. A cold row: a device's first cycle, the chart built from its file (a new chart,
   so its kernel tables and plans are new too), the simulated motor connected, the
   device started and the wired cycle run once: what the first eight events of a new
   device cost.
2c. The journal row's round ends when the journal has committed every event of the
   round (``Journal.flush``), so its commits are in the round's time.
2d. A by-hand row: the bare cycle, and after each event the very typed records a
   step-record listener reads, built directly from their fields (the clock read, one
   struct each, a tuple handed to a listener): what reading every typed record costs
   with no engine, step record or builder in between, the least any design that keeps
   the records as they are can pay.
3. One process, interleaved: each round runs every contender once, in an order
   that rotates from round to round, after warm-up rounds that are thrown away.
   A figure is the median over the rounds, so a noisy moment hurts one round of
   everybody instead of one contender.
4. The peers (transitions, python-statemachine, sismic) are imported only here,
   from the ``bench`` extra; one that is not installed is skipped with a note. Each
   implements the guard its own way (the previous state kept by a callback).
5. The hand-written dict baseline is the floor: a dictionary lookup on
   ``(state, event)``, the guard when the row has one, and a call of the observer.
6. Many devices: 1,000 Motors on one ``System`` (one owner thread), fed the paper
   cycle by 4 posting threads; the figures are events processed per second, end to
   end (wall time, 5 threads), and the process's CPU time per event (all threads);
   three runs, each in a fresh interpreter (best and worst shown), so the row does
   not pay for the garbage of the rows before it.
7. A round is timed by the process's CPU time, every thread of it (``--clock cpu``,
   the default: the journal's writer thread counts, as the rows' own thread does): on
   a machine shared with other work, wall time counts the time the other processes
   had the CPU; ``--clock wall`` times by the wall clock.

Run: ``python bench/dispatch.py`` (``--quick`` for a smoke run, ``--libs`` to choose).
"""

from __future__ import annotations

import argparse
import gc
import io
import multiprocessing
import os
import statistics
import sys
import tempfile
import threading
import time
import tracemalloc
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# benchmark the working tree, not whatever copy happens to be installed; a PYTHONPATH
# given chooses the tree (another checkout's src: a baseline timed by this same file)
if not os.environ.get("PYTHONPATH"):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from statectl.front.builder.build import load_chart
from statectl.kernel.model import Chart, State, StateKind, Transition
from statectl.run.devices import connect, make_driver
from statectl.run.journal import Journal
from statectl.run.journal.device import JournalledDevice
from statectl.run.runtime import SimClock, StepRecord, Subject, TraceWriter
from statectl.run.runtime.monitors import attach_monitors
from statectl.run.runtime.records import fields_of
from statectl.run.system import DeviceSetup, System

MOTOR_YAML = Path(__file__).resolve().parents[1] / "examples" / "motor" / "motor.yaml"
MOTOR_CYCLE = (
    "Movement",
    "Movement completion",
    "Initialization",  # guarded: previous == 'Moving'
    "Initialization completion",
    "Movement",
    "Error",
    "Error completion",
    "Initialization",  # guard false now (previous == 'Returning'): nothing happens
)
MOTOR_NOTIFY = {"Movement": 0, "Initialization": 1, "Error": 2}  # driving events -> invoke
MOTOR_ROWS = (  # old, event, new
    ("Blocked", "Movement", "Moving"),
    ("Moving", "Movement completion", "Blocked"),
    ("Blocked", "Initialization", "Returning"),  # [previous == 'Moving']
    ("Returning", "Initialization completion", "Blocked"),
    ("Moving", "Error", "Returning"),
    ("Returning", "Error completion", "Blocked"),
)
GUARDED = "Initialization"  # the one row with a guard: the previous state was Moving
#: Event data the demo gives: a Movement carries its amount.
MOTOR_DATA: dict[str, Any] = {"Movement": {"amount": 10}}
#: The paper cycle on a moving simulated clock (rule 2a): after each command the clock
#: runs TRAVEL seconds. The motor moves 10 units/s, so a movement of 10 arrives after
#: 1 s (Movement completion), the return after 1 s (Initialization completion); in the
#: second movement a fault injected at FAULT_AT is seen by the monitor's poll at 0.5 s
#: (Error) and the motor returns the 5 units in 0.5 s (Error completion). A little more
#: time than needed, for the floating-point arithmetic; the monitor polls every 0.1 s.
TRAVEL = 1.05
FAULT_AT = 0.45
SYSTEM_DEVICES, SYSTEM_THREADS, SYSTEM_CYCLES = 1000, 4, 20
GROUPS, LEAVES = 5, 9  # 5 parents + 45 leaves = 50 states
LIBS = ("statectl", "dict", "transitions", "python-statemachine", "sismic")

Fire = Callable[[], None]  # runs one cycle of a scenario


class Counter:
    """The one observer: counts notifications, as a cheap device driver would."""

    __slots__ = ("n",)

    def __init__(self) -> None:
        self.n = 0

    def update(self, notification: object) -> None:
        self.n += 1


def snake(event: str) -> str:
    return event.lower().replace(" ", "_")


# -- the nested chart, one description for every library --------------------------------------


def nested_rows() -> tuple[list[tuple[str, str, str]], list[str]]:
    """(source, event, target) rows and the 50-event cycle that returns to the start.

    ``next`` walks the leaves of a parent and on to the next parent's first leaf
    (leaving and entering parents); ``skip`` is a transition of the parent, so the
    leaf inherits it.
    """
    rows: list[tuple[str, str, str]] = []
    for g in range(GROUPS):
        for i in range(LEAVES):
            nxt = f"G{g}L{i + 1}" if i + 1 < LEAVES else f"G{(g + 1) % GROUPS}L0"
            rows.append((f"G{g}L{i}", "next", nxt))
        rows.append((f"G{g}", "skip", f"G{(g + 1) % GROUPS}"))
    return rows, ["next"] * (GROUPS * LEAVES) + ["skip"] * GROUPS


def nested_chart() -> Chart:
    rows, _ = nested_rows()
    states: list[State] = []
    for g in range(GROUPS):
        states.append(State(f"G{g}", StateKind.COMPOUND, initial=(f"G{g}L0",)))
        states.extend(State(f"G{g}L{i}", parent=f"G{g}") for i in range(LEAVES))
    transitions = tuple(Transition(s, (e,), (t,)) for s, e, t in rows)
    return Chart("Nested", tuple(states), transitions, ("G0",))


# -- contenders: each returns (fire one cycle, events per cycle) or None if unavailable -------


class QuietDevice:
    """A fault source that never faults: the Moving monitor polls it and finds nothing."""

    def poll_fault(self) -> str | None:
        return None


def _keep_last(subject: Subject) -> None:
    """A step-record listener that keeps the last record and reads nothing of it."""
    last: list[object] = [None]

    def hear(step: object) -> None:
        last[0] = step

    subject.listen_steps(hear)


def _read_all(subject: Subject) -> None:
    """A step-record listener that reads every typed record (builds them all)."""
    seen = [0]

    def hear(step: StepRecord) -> None:
        seen[0] += len(step.records)

    subject.listen_steps(hear)


def _typed_listener(subject: Subject) -> None:
    """A listen() listener: every typed record, one call each, as they happen."""
    seen = [0]

    def hear(record: object) -> None:
        seen[0] += 1

    subject.listen(hear)


def _by_hand(subject: Subject, hear: Callable[[tuple[Any, ...]], object] | None = None) -> Fire:
    """Rule 2d: the bare cycle, and after each event its typed records built directly:
    the clock read, then one line of struct calls per event, handed to ``hear``."""
    probe = Subject(subject.chart, clock=SimClock())
    probe.attach(Counter())
    steps: list[StepRecord] = []
    probe.listen_steps(steps.append)
    probe.start()
    cycle = [(e, MOTOR_DATA.get(e)) for e in MOTOR_CYCLE]
    for e, d in cycle:
        probe.dispatch(e, d)
    names: dict[str, Any] = {"dispatch": subject.dispatch, "now": subject.clock.now}
    names.update(hear=hear or (lambda records: None), name=subject.name)

    def bind(value: object) -> str:  # every value reaches the code by a name, never as text
        key = f"v{len(names)}"
        names[key] = value
        return key

    lines = ["def fire():"]
    for (e, d), step in zip(cycle, steps[-len(cycle) :], strict=True):
        calls = [
            f"{bind(type(r))}(name, t, {', '.join(bind(v) for v in fields_of(r))})"
            for r in step.records
        ]
        lines += [f"    dispatch({bind(e)}, {bind(d)})", "    t = now()"]
        lines.append(f"    hear(({', '.join(calls)},))")
    exec("\n".join(lines), names)
    fire: Fire = names["fire"]
    return fire


#: Bare dispatch with a listener that asked for records, three ways (rule 2).
RECORD_LISTENERS: dict[str, Callable[[Subject], None]] = {
    "steps": _keep_last,
    "steps-read": _read_all,
    "records": _typed_listener,
}

#: Where journals and traces of the wired rows go; removed when the run ends.
SCRATCH = tempfile.TemporaryDirectory(prefix="statectl-bench-")


def _motor_subject(wiring: str) -> tuple[Subject, JournalledDevice | None, Any]:
    """A started Motor wired as ``wiring`` says (bare, monitor, demo, journal, trace), its
    journalled device (the journal row) and its driver (the driven rows)."""
    chart = load_chart(MOTOR_YAML)
    subject = Subject(chart, clock=SimClock())
    journalled, driver = None, None
    if wiring in ("bare", "by-hand"):
        subject.attach(Counter())
    elif wiring in RECORD_LISTENERS:
        subject.attach(Counter())
        RECORD_LISTENERS[wiring](subject)
    elif wiring == "monitor":
        subject.attach(Counter())
        attach_monitors(subject, QuietDevice())
    else:  # as `statectl demo` wires it: the simulated motor's API and its monitors
        driver = make_driver("sim-motor", {}, chart=chart)
        connect(subject, driver)
        if wiring == "demo-steps":  # a step listener that reads nothing: run's problem count
            _keep_last(subject)
        elif wiring == "trace":  # as `statectl demo` and `statectl run` attach it
            subject.listen_steps(TraceWriter(io.StringIO(), device_width=len(subject.name)).step)
        elif wiring == "trace-records":  # the trace writer as a listen() listener
            subject.listen(TraceWriter(io.StringIO(), device_width=len(subject.name)))
        elif wiring == "dashboard":  # the owner's side: noted steps wait for a loop
            from statectl.channels.web.server import Dashboard

            Dashboard([subject])
        elif wiring == "journal":
            path = Path(SCRATCH.name) / f"journal-{id(subject)}.db"
            journalled = JournalledDevice(subject, Journal(path))
    if journalled is not None:
        journalled.start()
    else:
        subject.start()
    return subject, journalled, driver


#: Made by a contender: one cycle, its events, and what ends a round (the journal's flush).
Made = tuple[Fire, int, Fire | None]
#: The wirings with the simulated motor connected: their cycle runs on the clock (rule 2a).
DRIVEN = ("demo", "demo-steps", "journal", "dashboard", "trace", "trace-records")
MOVE = MOTOR_DATA["Movement"]


def _clocked(subject: Subject, post: Callable[..., object], driver: Any) -> Fire:
    """The paper cycle as the device lives it (rule 2a): four commands posted, the clock
    run after each; the motor reports its completions and the monitor raises the Error."""
    advance, run = subject.advance, subject.run_until_idle

    def fire() -> None:
        post("Movement", MOVE)
        advance(TRAVEL)  # ... Movement completion, from the motor
        post("Initialization")  # previous == 'Moving'
        advance(TRAVEL)  # ... Initialization completion
        post("Movement", MOVE)
        driver.inject_fault("motor stalled", after=FAULT_AT)
        advance(TRAVEL)  # ... Error from the monitor, Error completion from the motor
        post("Initialization")  # guard false
        run()

    return fire


def _clocked_monitor(subject: Subject) -> Fire:
    """The Moving-monitor row's cycle: no driver, so the completions and the Error are
    posted; the clock runs while Moving, so the monitor polls (it never finds a fault)."""
    post, advance, run = subject.post, subject.advance, subject.run_until_idle

    def fire() -> None:
        post("Movement", MOVE)
        advance(TRAVEL)
        post("Movement completion")
        post("Initialization")
        post("Initialization completion")
        post("Movement", MOVE)
        advance(FAULT_AT)
        post("Error")
        post("Error completion")
        post("Initialization")
        run()

    return fire


def _checked(subject: Subject, fire: Fire, settle: Fire | None = None) -> Made:
    """``fire`` after one run that must process the eight events and end in Blocked with
    four notifications more (rule 1), whatever moved the device."""
    events, invokes = subject.events_processed, subject.invokes_issued
    fire()
    if settle is not None:
        settle()
    got = (subject.events_processed - events, subject.invokes_issued - invokes)
    if got != (len(MOTOR_CYCLE), 4) or subject.configuration != {"Blocked"}:
        raise SystemExit(
            f"a cycle processed {got[0]} events and issued {got[1]} invokes, ending in "
            f"{sorted(subject.configuration)} (want {len(MOTOR_CYCLE)}, 4, Blocked)"
        )
    return fire, len(MOTOR_CYCLE), settle


def statectl_paper(wiring: str) -> Callable[[], Made]:
    """The paper cycle through ``dispatch()``, or on the clock when a driver or a monitor
    is wired (rule 2a; the journal's ``post()`` for the journal row), wired so."""

    def make() -> Made:
        subject, journalled, driver = _motor_subject(wiring)
        if wiring in DRIVEN:
            post = journalled.post if journalled is not None else subject.post
            settle: Fire | None = None
            if journalled is not None:
                journal = journalled.journal

                def settle() -> None:  # the round ends when every event is committed
                    journal.flush()

            return _checked(subject, _clocked(subject, post, driver), settle)
        if wiring == "monitor":
            return _checked(subject, _clocked_monitor(subject))
        if wiring == "by-hand":
            return _checked(subject, _by_hand(subject))
        cycle = [(e, MOTOR_DATA.get(e)) for e in MOTOR_CYCLE]
        dispatch = subject.dispatch

        def fire() -> None:
            for e, d in cycle:
                dispatch(e, d)

        return _checked(subject, fire)

    return make


def statectl_cold() -> Made:
    """Rule 2b: a new device from its file, the motor connected, its first wired cycle."""

    def fire() -> None:
        chart = load_chart(MOTOR_YAML)
        subject = Subject(chart, clock=SimClock())
        driver = make_driver("sim-motor", {}, chart=chart)
        connect(subject, driver)
        subject.start()
        _clocked(subject, subject.post, driver)()

    return fire, len(MOTOR_CYCLE), None


def statectl_motor_queued() -> Made:
    subject, _, _ = _motor_subject("bare")
    post, run = subject.post, subject.run_until_idle
    cycle = [(e, MOTOR_DATA.get(e)) for e in MOTOR_CYCLE]

    def fire() -> None:
        for e, d in cycle:
            post(e, d)
            run()

    return _checked(subject, fire)


def system_rate(devices: int, threads: int, cycles: int) -> tuple[float, float, int]:
    """Events/s (wall time) for ``devices`` Motors on one System, fed by ``threads``
    posters; the process's CPU seconds per event (every thread); events processed."""
    chart = load_chart(MOTOR_YAML)
    setups = tuple(DeviceSetup(f"M{i}", chart) for i in range(devices))
    system = System(setups, SimClock())
    for s in system.subjects.values():
        s.attach(Counter())
    system.start()
    names = list(system.subjects)
    total = devices * cycles * len(MOTOR_CYCLE)
    stop = threading.Event()
    owner = threading.Thread(target=system.serve, args=(stop,), kwargs={"paced": False})

    def feed(mine: list[str]) -> None:
        for _ in range(cycles):
            for name in mine:
                for e in MOTOR_CYCLE:
                    system.post(name, e, MOTOR_DATA.get(e))

    posters = [threading.Thread(target=feed, args=(names[k::threads],)) for k in range(threads)]
    t0, cpu0 = time.perf_counter(), time.process_time()
    owner.start()
    for p in posters:
        p.start()
    for p in posters:
        p.join()

    def done() -> int:
        return sum(s.events_processed for s in system.subjects.values())

    while done() < total:
        time.sleep(0.001)
    took, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    stop.set()
    owner.join()
    system.close()
    return total / took, cpu / total, done()


def statectl_nested_queued() -> tuple[Fire, int]:
    subject = Subject(nested_chart(), clock=SimClock())
    subject.start()
    post, run = subject.post, subject.run_until_idle
    _, cycle = nested_rows()

    def fire() -> None:
        for e in cycle:
            post(e)
            run()

    return fire, len(cycle)


def statectl_nested() -> tuple[Fire, int]:
    subject = Subject(nested_chart(), clock=SimClock())
    subject.start()
    dispatch = subject.dispatch
    _, cycle = nested_rows()

    def fire() -> None:
        for e in cycle:
            dispatch(e)

    return fire, len(cycle)


Row = tuple[str, int | None, str | None]  # new state, invoke, previous state required


class DictMachine:
    """The floor: one dict lookup on (state, event), the guard if any, then the observer."""

    __slots__ = ("observer", "previous", "state", "table")

    def __init__(self, table: dict[tuple[str, str], Row], state: str) -> None:
        self.table = table
        self.state = state
        self.previous = ""
        self.observer = Counter()

    def dispatch(self, event: str) -> None:
        new, invoke, needs = self.table[(self.state, event)]
        if needs is not None and self.previous != needs:
            return
        self.previous = self.state
        self.state = new
        if invoke is not None:
            self.observer.update(invoke)


MOTOR_TABLE: dict[tuple[str, str], Row] = {
    (o, e): (n, MOTOR_NOTIFY.get(e), "Moving" if e == GUARDED else None) for o, e, n in MOTOR_ROWS
}


def dict_motor() -> tuple[Fire, int]:
    machine = DictMachine(MOTOR_TABLE, "Blocked")
    dispatch = machine.dispatch
    cycle = MOTOR_CYCLE

    def fire() -> None:
        for e in cycle:
            dispatch(e)

    return fire, len(cycle)


def dict_nested() -> tuple[Fire, int]:
    rows, cycle = nested_rows()
    table: dict[tuple[str, str], Row] = {}
    for s, e, t in rows:  # flattened by hand: a parent's row copied to its leaves
        target = t if "L" in t else f"{t}L0"
        for leaf in [s] if "L" in s else [f"{s}L{i}" for i in range(LEAVES)]:
            table.setdefault((leaf, e), (target, None, None))
    machine = DictMachine(table, "G0L0")
    dispatch = machine.dispatch

    def fire() -> None:
        for e in cycle:
            dispatch(e)

    return fire, len(cycle)


def _transitions_rows(model: Any, observer: Counter) -> list[dict[str, Any]]:
    """The Motor's rows for transitions: the guard as a condition, the previous state
    kept by a ``before`` callback, the observer called ``after``."""

    def row(o: str, e: str, n: str) -> dict[str, Any]:
        out: dict[str, Any] = {
            "trigger": snake(e),
            "source": o,
            "dest": n,
            "before": lambda o=o: setattr(model, "previous", o),
        }
        if e == GUARDED:
            out["conditions"] = lambda: model.previous == "Moving"
        if e in MOTOR_NOTIFY:
            out["after"] = lambda i=MOTOR_NOTIFY[e]: observer.update(i)
        return out

    return [row(o, e, n) for o, e, n in MOTOR_ROWS]


def _transitions_model(observer: Counter) -> Any:
    """A transitions Motor (its ``Machine`` built on a fresh model) calling ``observer``."""
    from transitions import Machine

    model = type("Motor", (), {"previous": ""})()
    Machine(
        model=model,
        states=["Blocked", "Moving", "Returning"],
        transitions=_transitions_rows(model, observer),
        initial="Blocked",
        auto_transitions=False,
    )
    return model


def transitions_motor() -> tuple[Fire, int] | None:
    try:
        model = _transitions_model(Counter())
    except ImportError:
        return None
    calls = [getattr(model, snake(e)) for e in MOTOR_CYCLE]

    def fire() -> None:
        for c in calls:
            c()

    return fire, len(calls)


def transitions_nested() -> tuple[Fire, int] | None:
    try:
        from transitions.extensions import HierarchicalMachine
    except ImportError:
        return None
    rows, cycle = nested_rows()

    def name(s: str) -> str:
        return s.replace("L", "_L") if "L" in s else s

    states = [
        {"name": f"G{g}", "children": [f"L{i}" for i in range(LEAVES)], "initial": "L0"}
        for g in range(GROUPS)
    ]
    model = type("Nested", (), {})()
    HierarchicalMachine(
        model=model,
        states=states,
        initial="G0",
        auto_transitions=False,
        transitions=[{"trigger": e, "source": name(s), "dest": name(t)} for s, e, t in rows],
    )
    calls = [getattr(model, e) for e in cycle]

    def fire() -> None:
        for c in calls:
            c()

    return fire, len(calls)


def _psm_motor_class() -> Any:
    from statemachine import State as S
    from statemachine import StateMachine

    states = {n: S(initial=(n == "Blocked")) for n in ("Blocked", "Moving", "Returning")}
    body: dict[str, Any] = {n.lower(): s for n, s in states.items()}
    for o, e, n in MOTOR_ROWS:
        guard = {"cond": "was_moving"} if e == GUARDED else {}
        body[snake(e)] = states[o].to(states[n], **guard)
    for e, i in MOTOR_NOTIFY.items():
        body[f"on_{snake(e)}"] = lambda self, i=i: self.observer.update(i)
    body["was_moving"] = lambda self: self.previous == "moving"
    # the cycle's last Initialization has its guard false: ignored, as statectl ignores it
    body["allow_event_without_transition"] = True

    def before_transition(self: Any, source: Any) -> None:
        self.previous = source.id

    body["before_transition"] = before_transition

    def init(self: Any, observer: Counter) -> None:
        self.observer = observer
        self.previous = ""
        StateMachine.__init__(self)

    body["__init__"] = init
    return type("PsmMotor", (StateMachine,), body)


def psm_motor() -> tuple[Fire, int] | None:
    try:
        cls = _psm_motor_class()
    except ImportError:
        return None
    machine = cls(Counter())
    calls = [getattr(machine, snake(e)) for e in MOTOR_CYCLE]

    def fire() -> None:
        for c in calls:
            c()

    return fire, len(calls)


def psm_nested() -> tuple[Fire, int] | None:
    try:
        from statemachine import State as S
        from statemachine import StateMachine
    except ImportError:
        return None
    rows, cycle = nested_rows()
    leaves: dict[str, Any] = {}
    body: dict[str, Any] = {}
    for g in range(GROUPS):
        inner = {f"l{i}": S(initial=(i == 0)) for i in range(LEAVES)}
        leaves.update({f"G{g}L{i}": inner[f"l{i}"] for i in range(LEAVES)})
        body[f"g{g}"] = type(f"g{g}", (S.Compound,), inner)
    parents = {f"G{g}": body[f"g{g}"] for g in range(GROUPS)}
    every = {**leaves, **parents}
    by_event: dict[str, Any] = {}
    for s, e, t in rows:
        tl = every[s].to(every[t])
        by_event[e] = tl if e not in by_event else by_event[e] | tl
    body.update(by_event)
    body["g0"] = body["g0"]
    cls = type("PsmNested", (StateMachine,), body)
    cls_initial = cls()
    calls = [getattr(cls_initial, e) for e in cycle]

    def fire() -> None:
        for c in calls:
            c()

    return fire, len(calls)


def _sismic_yaml(states: str, initial: str) -> str:
    return (
        f"statechart:\n  name: b\n  root state:\n    name: root\n    initial: {initial}\n"
        f"    states:\n{states}"
    )


def _sismic_motor_yaml() -> str:
    out = []
    for st in ("Blocked", "Moving", "Returning"):
        out.append(f"    - name: {st}\n      transitions:\n")
        for o, e, n in MOTOR_ROWS:
            if o == st:
                call = f"; observer.update({MOTOR_NOTIFY[e]})" if e in MOTOR_NOTIFY else ""
                guard = "\n        guard: previous == 'Moving'" if e == GUARDED else ""
                out.append(
                    f"      - target: {n}\n        event: {e}{guard}\n"
                    f"        action: previous = '{o}'{call}\n"
                )
    return _sismic_yaml("".join(out), "Blocked")


def _sismic_nested_yaml() -> str:
    rows, _ = nested_rows()
    out = []
    for g in range(GROUPS):
        out.append(f"    - name: G{g}\n      initial: G{g}L0\n      transitions:\n")
        out.extend(f"      - target: {t}\n        event: {e}\n" for s, e, t in rows if s == f"G{g}")
        out.append("      states:\n")
        for i in range(LEAVES):
            out.append(f"      - name: G{g}L{i}\n        transitions:\n")
            out.extend(
                f"        - target: {t}\n          event: {e}\n"
                for s, e, t in rows
                if s == f"G{g}L{i}"
            )
    return _sismic_yaml("".join(out), "G0")


def _sismic(yaml: str, cycle: Sequence[str]) -> tuple[Fire, int] | None:
    try:
        from sismic.interpreter import Interpreter  # type: ignore[import-untyped]  # no stubs
        from sismic.io import import_from_yaml  # type: ignore[import-untyped]  # no stubs
    except ImportError:
        return None
    context = {"observer": Counter(), "previous": ""}
    interpreter = Interpreter(import_from_yaml(yaml), initial_context=context)
    interpreter.execute()
    queue, execute = interpreter.queue, interpreter.execute

    def fire() -> None:
        for e in cycle:
            queue(e)
            execute()

    return fire, len(cycle)


def sismic_motor() -> tuple[Fire, int] | None:
    return _sismic(_sismic_motor_yaml(), MOTOR_CYCLE)


def sismic_nested() -> tuple[Fire, int] | None:
    return _sismic(_sismic_nested_yaml(), nested_rows()[1])


# -- new instances ------------------------------------------------------------------------------


def instance_makers() -> dict[str, Callable[[], Callable[[], object]] | None]:
    """Per library, a factory of the 'new started Motor instance' callable (None: skipped)."""

    def statectl_new() -> Callable[[], object]:
        chart, clock = load_chart(MOTOR_YAML), SimClock()

        def new() -> object:
            s = Subject(chart, clock=clock)
            s.start()
            return s

        new()  # the chart is compiled once per process, on its first instance
        return new

    def dict_new() -> Callable[[], object]:
        return lambda: DictMachine(MOTOR_TABLE, "Blocked")

    def transitions_new() -> Callable[[], object]:
        import transitions  # noqa: F401  # skipped when not installed

        return lambda: _transitions_model(Counter())

    def psm_new() -> Callable[[], object]:
        cls = _psm_motor_class()
        return lambda: cls(Counter())

    def sismic_new() -> Callable[[], object]:
        from sismic.interpreter import Interpreter
        from sismic.io import import_from_yaml

        chart = import_from_yaml(_sismic_motor_yaml())

        def new() -> object:
            it = Interpreter(chart, initial_context={"observer": Counter(), "previous": ""})
            it.execute()
            return it

        return new

    makers: dict[str, Callable[[], Callable[[], object]]] = {
        "statectl": statectl_new,
        "dict": dict_new,
        "transitions": transitions_new,
        "python-statemachine": psm_new,
        "sismic": sismic_new,
    }
    out: dict[str, Callable[[], Callable[[], object]] | None] = {}
    for lib, maker in makers.items():
        try:
            maker()
        except ImportError:
            out[lib] = None
        else:
            out[lib] = maker
    return out


def instance_bytes(new: Callable[[], object], count: int) -> float:
    """Bytes allocated and kept per instance (tracemalloc, ``count`` kept alive)."""
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    keep = [new() for _ in range(count)]
    used = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    del keep
    return used / count


# -- timing -------------------------------------------------------------------------------------


@dataclass(slots=True)
class Contender:
    scenario: str
    lib: str
    label: str
    fire: Fire
    per_call: int  # events (or instances) per fire()
    settle: Fire | None = None  # ends a round inside its time (the journal's commits)
    loops: int = 1
    samples: list[float] | None = None


def calibrate(c: Contender, budget: float) -> None:
    """Choose how many cycles one round runs so it takes about ``budget`` seconds."""
    loops = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(loops):
            c.fire()
        took = time.perf_counter() - t0
        if took >= budget / 10 or loops >= 1 << 20:
            c.loops = max(1, int(loops * budget / max(took, 1e-9)))
            return
        loops *= 4


#: Clocks a round can be timed with (rule 7): the process's CPU time, or wall time.
CLOCKS: dict[str, Callable[[], int]] = {"cpu": time.process_time_ns, "wall": time.perf_counter_ns}


def measure(
    contenders: list[Contender], rounds: int, warmup: int, budget: float, clock: str = "cpu"
) -> None:
    now = CLOCKS[clock]
    for c in contenders:
        calibrate(c, budget)
        c.samples = []
    for r in range(warmup + rounds):
        shift = r % len(contenders)
        for c in contenders[shift:] + contenders[:shift]:
            fire, loops = c.fire, c.loops
            gc_was = gc.isenabled()
            gc.disable()
            t0 = now()
            for _ in range(loops):
                fire()
            if c.settle is not None:
                c.settle()
            took = now() - t0
            if gc_was:
                gc.enable()
            if r >= warmup:
                assert c.samples is not None
                c.samples.append(took / (loops * c.per_call))


def median(c: Contender) -> float:
    assert c.samples
    return statistics.median(c.samples)


# -- main ---------------------------------------------------------------------------------------


def build(libs: Sequence[str]) -> tuple[list[Contender], list[str]]:
    table: list[tuple[str, str, str, Callable[[], tuple[Fire, int] | Made | None]]] = [
        ("motor", "statectl", "statectl bare dispatch()", statectl_paper("bare")),
        (
            "motor",
            "statectl",
            "statectl bare + step-record listener",
            statectl_paper("steps"),
        ),
        (
            "motor",
            "statectl",
            "statectl bare + step records, all typed records read",
            statectl_paper("steps-read"),
        ),
        (
            "motor",
            "statectl",
            "statectl bare + the same typed records built by hand (no engine)",
            statectl_paper("by-hand"),
        ),
        (
            "motor",
            "statectl",
            "statectl bare + listen() record listener",
            statectl_paper("records"),
        ),
        ("motor", "statectl", "statectl + Moving monitor", statectl_paper("monitor")),
        (
            "motor",
            "statectl",
            "statectl wired as the demo (driver + monitor)",
            statectl_paper("demo"),
        ),
        (
            "motor",
            "statectl",
            "statectl demo wiring, clock still (no polls; completions dispatched)",
            statectl_paper("demo-still"),
        ),
        (
            "motor",
            "statectl",
            "statectl demo wiring + step-record listener",
            statectl_paper("demo-steps"),
        ),
        ("motor", "statectl", "statectl demo wiring + journal", statectl_paper("journal")),
        (
            "motor",
            "statectl",
            "statectl demo wiring + dashboard (the owner's side)",
            statectl_paper("dashboard"),
        ),
        ("motor", "statectl", "statectl demo wiring + trace", statectl_paper("trace")),
        (
            "motor",
            "statectl",
            "statectl demo wiring + trace as a listen() listener",
            statectl_paper("trace-records"),
        ),
        ("motor", "statectl", "statectl bare post()+run_until_idle()", statectl_motor_queued),
        (
            "motor",
            "statectl",
            "statectl cold: built from the file, motor connected, first cycle",
            statectl_cold,
        ),
        ("motor", "dict", "dict baseline", dict_motor),
        ("motor", "transitions", "transitions", transitions_motor),
        ("motor", "python-statemachine", "python-statemachine", psm_motor),
        ("motor", "sismic", "sismic", sismic_motor),
        ("nested", "statectl", "statectl dispatch()", statectl_nested),
        ("nested", "statectl", "statectl post()+run_until_idle()", statectl_nested_queued),
        ("nested", "dict", "dict baseline (flattened by hand)", dict_nested),
        ("nested", "transitions", "transitions (HierarchicalMachine)", transitions_nested),
        ("nested", "python-statemachine", "python-statemachine", psm_nested),
        ("nested", "sismic", "sismic", sismic_nested),
    ]
    out: list[Contender] = []
    notes: list[str] = []
    for scenario, lib, label, make in table:
        if lib not in libs:
            continue
        made = make()
        if made is None:
            notes.append(f"{lib} not installed: skipped ({scenario}); pip install '.[bench]'")
            continue
        settle = made[2] if len(made) == 3 else None  # Made's third
        out.append(Contender(scenario, lib, label, made[0], made[1], settle))
    makers = instance_makers()
    for lib in libs:
        maker = makers.get(lib)
        if maker is None:
            notes.append(f"{lib} not installed: skipped (new instance)")
            continue
        new = maker()

        def fire(new: Callable[[], object] = new) -> None:
            new()

        out.append(Contender("new", lib, lib, fire, 1))
    return out, notes


def report(contenders: list[Contender], sizes: dict[str, float], notes: list[str]) -> str:
    lines = []
    head = "| scenario | library | ns/event | vs dict | transitions / this |"
    titles = {
        "motor": "paper cycle",
        "nested": "50 states, 2 levels",
        "new": "new started instance",
    }
    for scenario in ("motor", "nested", "new"):
        rows = [c for c in contenders if c.scenario == scenario]
        if not rows:
            continue
        base = next((median(c) for c in rows if c.lib == "dict"), None)
        peer = next((median(c) for c in rows if c.lib == "transitions"), None)
        if scenario == "new":
            lines.append("")
            lines.append("| scenario | library | us/instance | bytes/instance | vs dict (time) |")
            lines.append("|---|---|---:|---:|---:|")
        elif not lines:
            lines.append(head)
            lines.append("|---|---|---:|---:|---:|")
        for c in rows:
            t = median(c)
            vs_dict = f"{t / base:.1f}" if base else "-"
            if scenario == "new":
                size = sizes.get(c.lib)
                size_text = f"{size:,.0f}" if size is not None else "-"
                cells = (titles[scenario], c.label, f"{t / 1000:,.2f}", size_text, vs_dict)
                lines.append("| " + " | ".join(cells) + " |")
            else:
                vs_peer = f"{peer / t:.1f}" if peer else "-"
                lines.append(
                    f"| {titles[scenario]} | {c.label} | {t:,.0f} | {vs_dict} | {vs_peer} |"
                )
    lines.extend(f"note: {n}" for n in notes)
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="a short smoke run (noisy figures)")
    parser.add_argument(
        "--libs", default=",".join(LIBS), help=f"comma-separated subset of {', '.join(LIBS)}"
    )
    parser.add_argument("--rounds", type=int, default=None, help="measured rounds (default 15)")
    parser.add_argument(
        "--clock",
        choices=tuple(CLOCKS),
        default="cpu",
        help="time rounds by the thread's CPU time (default) or by wall time",
    )
    args = parser.parse_args(argv)
    libs = [x.strip() for x in args.libs.split(",") if x.strip()]
    unknown = [x for x in libs if x not in LIBS]
    if unknown:
        parser.error(f"unknown library {unknown} (choose from {', '.join(LIBS)})")
    rounds = args.rounds or (3 if args.quick else 15)
    warmup = 1 if args.quick else 3
    budget = 0.002 if args.quick else 0.05
    same_work(libs)
    contenders, notes = build(libs)
    measure(contenders, rounds, warmup, budget, args.clock)
    sizes: dict[str, float] = {}
    for c in contenders:
        if c.scenario == "new":
            maker = instance_makers()[c.lib]
            assert maker is not None
            sizes[c.lib] = instance_bytes(maker(), 50 if args.quick else 500)
    print(
        f"python {sys.version.split()[0]}, {rounds} rounds (median), interleaved, "
        f"{args.clock} time; load average {os.getloadavg()[0]:.1f}"
    )
    print(report(contenders, sizes, notes))
    print(summary(contenders))
    if "statectl" in libs:
        devices = 100 if args.quick else SYSTEM_DEVICES
        cycles = 2 if args.quick else SYSTEM_CYCLES
        runs = sorted(fresh_system_rates(devices, cycles, 1 if args.quick else 3))
        print(
            f"\n{devices:,} Motors on one System (1 owner thread, {SYSTEM_THREADS} posting "
            f"threads), paper cycle x {cycles}, {len(runs)} run{'s' * (len(runs) > 1)}, each in a "
            "fresh process:"
        )
        ends = (("worst", runs[-1]), ("best", runs[0]))
        for label, (cpu, rate, processed) in ends:
            print(
                f"  {label}: {rate:,.0f} events/s wall time; {cpu * 1e9:,.0f} ns/event of "
                f"the process's CPU, all threads ({1 / cpu:,.0f} events per CPU second; "
                f"{processed:,} events processed)"
            )
    return 0


def fresh_system_rates(devices: int, cycles: int, runs: int) -> list[tuple[float, float, int]]:
    """:func:`system_rate` ``runs`` times, each in a new interpreter: what a process that
    runs 1,000 Motors pays, not the garbage the rows before it left for the collector
    (which cost this row a third of its speed). (CPU per event, events/s, processed)."""
    context = multiprocessing.get_context("spawn")
    out = []
    with context.Pool(1, maxtasksperchild=1) as pool:
        for _ in range(runs):
            rate, cpu, processed = pool.apply(system_rate, (devices, SYSTEM_THREADS, cycles))
            out.append((cpu, rate, processed))
    return out


def same_work(libs: Sequence[str]) -> None:
    """Fail loudly unless every contender ends one paper cycle Blocked with 4 notifications.

    A peer whose guard never held (or always held) would be timing other work.
    """
    ends: dict[str, tuple[str, int]] = {}
    if "statectl" in libs:
        subject, _, _ = _motor_subject("bare")
        for e in MOTOR_CYCLE:
            subject.dispatch(e, MOTOR_DATA.get(e))
        ends["statectl"] = (",".join(sorted(subject.configuration)), subject.invokes_issued)
    if "dict" in libs:
        machine = DictMachine(MOTOR_TABLE, "Blocked")
        for e in MOTOR_CYCLE:
            machine.dispatch(e)
        ends["dict"] = (machine.state, machine.observer.n)
    try:
        observer = Counter()
        model = _transitions_model(observer)
    except ImportError:
        pass
    else:
        if "transitions" in libs:
            for e in MOTOR_CYCLE:
                getattr(model, snake(e))()
            ends["transitions"] = (model.state, observer.n)
    wrong = {lib: end for lib, end in ends.items() if end != ("Blocked", 4)}
    if wrong:
        raise SystemExit(f"contenders do different work (want Blocked, 4 notifications): {wrong}")


def summary(contenders: list[Contender]) -> str:
    """The best and the worst statectl row of the paper cycle, against transitions."""
    rows = [c for c in contenders if c.scenario == "motor" and c.lib == "statectl"]
    peer = next(
        (median(c) for c in contenders if c.scenario == "motor" and c.lib == "transitions"), None
    )
    if not rows:
        return ""
    best, worst = min(rows, key=median), max(rows, key=median)
    out = []
    for tag, c in (("best", best), ("worst", worst)):
        vs = f", {peer / median(c):.1f}x transitions" if peer else ""
        out.append(f"statectl {tag}: {c.label} {median(c):,.0f} ns/event{vs}")
    return "\n" + "\n".join(out)


if __name__ == "__main__":
    raise SystemExit(main())
