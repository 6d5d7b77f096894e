"""Many devices on one clock and one owner: the :class:`System` a host embeds.

Rules:
1. A :class:`System` is devices on one clock with one owner at a time: whoever
   holds the owner lock (the thread in :meth:`System.serve`, a caller of
   :meth:`System.drain`, or the journal's writer) processes the devices' events,
   run-to-completion, so devices never race each other. The owner visits only
   the devices that have work: a device tells the System when something is
   queued for it (:meth:`~statectl.run.runtime.Subject.on_queued`), so 1,000 idle
   devices cost nothing and need no thread of their own.
2. With a journal every event from outside is accepted through it and every
   step is journalled; ``resume`` brings each device back from the journal,
   through its recovery rules, before the owner takes any new event. The
   journal's guarantee says when an accepted event reaches its device. Under
   ``prompt`` (default) a post queues the inbox row, hands the event to its
   device and wakes the owner, as without a journal; the ticket turns durable
   at the next commit. Under ``durable-first`` the writer, right after a
   commit, delivers the batch's events and, if the owner lock is free, drains
   the devices itself in the same wake-up (no second thread hop); if another
   thread owns them it only wakes the serve loop, which picks the events up.
3. A cell runs the same way: one device per instance, on one clock and one
   owner, and the cell's links (:class:`~statectl.cell.explore.replay.CellLinks`):
   after a device's step, each link it fired whose guard holds sends its event
   to the target, through the journal when there is one: the link events are
   journalled with the step that fired them, in one commit, so after a crash
   both are in the journal (the link event is redelivered if its target had not
   run it) or neither is (the step runs again on resume and fires them again).
   Each device's queue is first in, first out.
4. :meth:`System.post` never blocks (but for a cell's command with a ``when``,
   which waits for the owner to run what came before it, rule 6). With
   ``max_queue`` a device whose queue holds that many events refuses more from
   outside with :class:`QueueFull`: a producer learns it outruns the device.
5. asyncio: ``await system.submit(...)`` (or :meth:`System.send`) resolves once the
   device ran the event; :meth:`System.records` is an async iterator of every
   device's records. Both hand results to the loop with ``call_soon_threadsafe``.
6. A cell's rules hold at run time as verify assumed them (explore/enforce.py): an
   environment command whose every ``when`` is false is refused
   (:class:`~statectl.cell.explore.enforce.Refused`), judged as verify takes a command:
   once everything posted or accepted before it has run and its links have settled
   (the poster runs them as the owner if the owner has not yet); invariants are
   checked once a stimulus's cascade has settled (every link event it caused
   delivered), each violation goes to the ``on_violation`` callbacks and sends the
   invariant's declared events (through the journal when there is one); link events
   carry their data; a device guard's ``In('other.State')`` reads the other device.
7. A row that fails while the owner drains (a guard or an assignment that raises, a
   driver refusing an event's data) refuses that event only: the message goes to the
   ``on_failure`` callbacks (``statectl run`` prints it and exits 1), and the other
   devices and the device's later events go on.
8. One front door, :meth:`System.submit` (DESIGN.md): every event from stdin, the Python
   API, the dashboard, OPC UA, Zenoh, a cell link, a driver's completion, a state's
   timeout or a monitor's fault enters there (:meth:`post` and :meth:`send` are submit
   without a handle, and awaited). Its ``origin`` (:mod:`statectl.run.commands`) enters
   if :attr:`System.commands` allows it, else ``CommandRefused``, journalled as a
   ``refused`` step that changes nothing (a refused link, driver, timer or monitor event
   is dropped with one log line). Without an origin it is the host's own (the Python
   API). Whether the submitting thread runs the step at once is decided there alone
   (:meth:`_run_here`): when the System is live and nobody owns the devices, it does (no
   hop to the owner's thread); else the owner is woken. Timers and monitors are the
   owner's own work, queued on the device at their point of its queue; when one runs out
   or finds a fault, its event passes the door's check as origin ``timer`` or
   ``monitor`` (the device) and is then processed as it always was: a timeout at once,
   at that point of the queue, a fault posted.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections import deque
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from statectl.cell.explore.conditions import bind_cross_guards
from statectl.cell.explore.enforce import CellRules, Violation
from statectl.cell.explore.replay import CellLinks
from statectl.cell.model import Cell
from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart
from statectl.kernel.semantics.eventview import GuardError
from statectl.run.commands import Commands
from statectl.run.devices import DeviceDriver, connect
from statectl.run.door import Door
from statectl.run.journal import (
    Guarantee,
    Journal,
    JournalError,
    JournalledDevice,
    JournalReader,
    RecoveryRule,
)
from statectl.run.runtime import Clock, Record, SimClock, StepRecord, Subject, WallClock
from statectl.run.runtime.eventdata import AssignError

__all__ = ["SETTLE_LIMIT", "DeviceSetup", "System"]

#: Simulated seconds a batch run lets pass at most for one event to settle.
SETTLE_LIMIT = 60.0
_TICK = 0.02


@dataclass(frozen=True, slots=True)
class DeviceSetup:
    """One device of a run: its chart, recovery rules, file and driver."""

    name: str
    chart: Chart
    rules: tuple[RecoveryRule, ...] = ()
    source: str = ""
    driver: DeviceDriver | None = None

    def __post_init__(self) -> None:
        """A driver given third lands in ``rules`` and would be dropped without a word."""
        if not isinstance(self.rules, tuple | list) or not all(
            isinstance(r, RecoveryRule) for r in self.rules
        ):
            raise TypeError(
                f"DeviceSetup {self.name!r}: rules must be RecoveryRule values, "
                f"got {self.rules!r}; give a driver as driver=..."
            )


@dataclass(slots=True)
class System(Door):
    """Devices on one clock with one owner; optionally journalled, a cell, bounded (rules 1-4)."""

    setups: Sequence[DeviceSetup]
    clock: Clock
    journal: Journal | None = None
    cell: Cell | None = None
    max_queue: int | None = None
    #: a cell's run-time rules (rule 6: refusals, invariants); off for a harness that
    #: drives the links from any state (statectl.out.testgen)
    enforce: bool = True
    #: who may command which device (rule 8): the run config's ``commands:`` section
    commands: Commands = field(default_factory=Commands)
    subjects: dict[str, Subject] = field(default_factory=dict)
    bound: dict[str, JournalledDevice] = field(default_factory=dict)
    wake: threading.Event = field(default_factory=threading.Event)
    owner: threading.RLock = field(default_factory=threading.RLock)
    links: CellLinks | None = None
    #: a cell's environment conditions and invariants, enforced (explore/enforce.py)
    rules: CellRules | None = None
    #: called on the owner with each invariant violation a step caused (rule 6)
    on_violation: list[Callable[[Violation], None]] = field(default_factory=list)
    #: called on the owner with each row that failed while draining (rule 7)
    on_failure: list[Callable[[StatectlError], None]] = field(default_factory=list)
    _live: bool = False  # started and not closing: the writer may drain
    #: devices that had something queued since the owner last looked (rule 1)
    _ready: deque[Subject] = field(default_factory=deque)
    #: simulated seconds a batch settle lets pass at most (``statectl run --settle-limit``)
    settle_limit: float = SETTLE_LIMIT
    #: settles that stopped at ``settle_limit`` with device work still pending
    settle_cut: int = 0
    #: a step of a cell ran since the invariants were last checked (rule 6)
    _unchecked: bool = False
    #: the owner is draining now (rule 6: a post from one of its steps does not drain again)
    _draining: bool = False
    #: ``statectl run --driver none``: settling never moves time (only ``advance`` does), so
    #: a timeout runs out only when the user lets time pass
    hold_time: bool = False

    def __post_init__(self) -> None:
        self.commands.check_names({d.name: d.chart.event_names for d in self.setups})
        if self.max_queue is not None and self.max_queue < 1:
            raise StatectlError(f"max_queue must be at least 1 (got {self.max_queue!r})")
        ready = self._ready.append
        for d in self.setups:
            if d.name in self.subjects:
                raise StatectlError(f"two devices are named {d.name!r}; names must be unique")
            s = Subject(d.chart, clock=self.clock, name=d.name)
            s.on_queued(ready)
            self.subjects[d.name] = s
            # its completions, timeouts and monitors' faults come through the door (rule 8)
            driver = d.driver
            monitors = () if driver is None else connect(s, driver, report=self._reporter(d.name))
            self._route_own(d.name, monitors)
            if self.journal is not None:
                self.bound[d.name] = JournalledDevice(s, self.journal, source=d.source)
        if self.cell is not None and self.journal is not None:
            carrying = [k.label for k in self.cell.links if k.data is not None or k.forward_data]
            if carrying:
                raise StatectlError(
                    f"links that carry event data ({'; '.join(carrying)}) do not run with a "
                    "journal yet: the journal would drop the data; run without --journal"
                )
        if self.cell is not None:
            bind_cross_guards(self.subjects)  # guards reading another device (rule 6)
            links = self.links = CellLinks(self.cell, self.subjects)
            self.rules = CellRules(self.cell, links) if self.enforce else None
            for name, s in self.subjects.items():
                s.listen_steps(links.watch_step)
                if name in self.bound:
                    self.bound[name].sends = self._link_sends  # journalled with the step
                else:
                    s.on_step(self._link_step)
        if self.journal is not None and self.journal.guarantee is Guarantee.DURABLE_FIRST:
            self.journal.after_commit(self._committed)

    def _link_step(self, event: str, data: Any, outcome: str) -> None:
        """Rule 4: on the owner after a device's step, send the links it fired."""
        assert self.links is not None
        if not self._live:
            self.links.fired.clear()  # entering the initial states fires nothing
            return
        links = self.links.cell.links
        for send in self.links.sends(data):
            self._pass_link(links[send.link].source, send.target, send.event, send.data)
        self._unchecked = self.rules is not None  # rule 6: once the cascade settles

    def _link_sends(self) -> list[tuple[JournalledDevice, str]]:
        """Rule 4 with a journal: the links a device's step fired, to journal with the step."""
        assert self.links is not None
        if not self._live:
            self.links.fired.clear()  # entering the initial states fires nothing
            return []
        self._unchecked = self.rules is not None  # rule 6: once the cascade settles
        return [
            (self.bound[k.target], k.event)
            for k in self.links.due()
            if self._link_admitted(k.source, k.target, k.event, None)
        ]

    def _settled_check(self) -> bool:
        """Rule 6 at the end of a cascade: report the invariants it broke and send their
        events (through the journal when the device is journalled); whether any was sent."""
        if not self._unchecked or (self.journal is not None and self.journal.queued):
            return False  # link events still wait in the journal: the cascade goes on
        self._unchecked = False
        sent = False
        for device, ev in self._violations():
            self._send_own(device, ev)
            sent = True
        return sent

    def _violations(self) -> list[tuple[str, str]]:
        """Rule 6: invariants a step broke, reported; the events they send."""
        if self.rules is None:
            return []
        out: list[tuple[str, str]] = []
        for v in self.rules.check(self.clock.now()):
            for callback in self.on_violation:
                callback(v)
            out.extend(v.sends)
        return out

    def _committed(self) -> None:
        """On the writer after a commit (rule 2): drain now if nobody owns the devices."""
        if not self._live:
            return
        self._run_here()

    def listen(self, callback: Callable[[Any], None]) -> None:
        """Every device's typed records, one call each (``Subject.listen``)."""
        for s in self.subjects.values():
            s.listen(callback)

    def listen_steps(self, callback: Callable[[StepRecord], None]) -> None:
        """Every device's steps, one :class:`StepRecord` each (``Subject.listen_steps``):
        the typed records are built only if the callback reads them."""
        for s in self.subjects.values():
            s.listen_steps(callback)

    def start(self, *, resume: bool = False) -> dict[str, bool]:
        """Start every device, or resume it from the journal; which ones were resumed."""
        resumed: dict[str, bool] = {}
        if resume and self.journal is None:
            raise StatectlError("--resume needs --journal DB")
        if resume and self.journal is not None:
            self.journal.flush()
            # the Journal checked the file when it opened it (journal/check.py); a row
            # it did not type that resume reads (a redo's walk back) is refused here
            path = self.journal.path
            try:
                with JournalReader(path, check=False) as reader:
                    misfits = [m for d in self.setups if (m := self.bound[d.name].misfit(reader))]
                    if misfits:
                        raise JournalError(
                            f"journal {path} was written by another chart: "
                            f"{'; '.join(misfits)}. Nothing was started. Resume with the "
                            "device file the journal was written with, or give another "
                            "--journal"
                        )
                    for d in self.setups:
                        resumed[d.name] = self.bound[d.name].resume(reader, d.rules)
            except JournalError as exc:
                if str(path) in str(exc):
                    raise
                raise JournalError(f"journal {path}: {exc}; nothing was resumed") from None
        else:
            for d in self.setups:
                if d.name in self.bound:
                    self.bound[d.name].start()
                else:
                    self.subjects[d.name].start()
                resumed[d.name] = False
        if self.links is not None:
            self.links.fired.clear()  # entering the initial or restored states fires nothing
        self._ready.extend(self.subjects.values())  # whatever was queued before the start
        self._live = True
        self.drain()  # recovery transitions, redelivered events: the links they fire are sent
        self.wake.set()  # events delivered before the start are drained by the owner
        return resumed

    def drain(self) -> int:
        """Be the owner once: process every device's queue until all are empty."""
        with self.owner:
            return self._drain()

    def _drain(self) -> int:
        """As the owner: run the devices that have work until none has (rule 1)."""
        total = 0
        ready = self._ready
        was, self._draining = self._draining, True
        try:
            while True:
                while ready:
                    s = ready.popleft()
                    if s.queued:
                        try:
                            total += s.run_until_idle()
                        except (GuardError, AssignError) as exc:  # rule 7: that event only
                            for callback in self.on_failure:
                                callback(exc)
                            if s.queued:
                                ready.append(s)
                if not self._settled_check():
                    return total
        finally:
            self._draining = was

    def _as_owner(self, step: Callable[[], object]) -> None:
        """As the owner, run ``step`` as a drain would: what it posts or submits is queued
        for the drain after it (rule 6: a post from a step does not drain again)."""
        was, self._draining = self._draining, True
        try:
            step()
        finally:
            self._draining = was

    def advance(self, seconds: float) -> None:
        """On a SimClock: let ``seconds`` pass as the owner, draining after every timer."""
        clock = self.clock
        if not isinstance(clock, SimClock):
            raise StatectlError("advance() needs a SimClock; a WallClock moves by itself")
        with self.owner:  # timers touch the clock and the devices: the owner's work
            self._drain()
            clock.advance(seconds, settle=self._drain)
            self._drain()

    def settle(self, limit: float | None = None) -> None:
        """On a SimClock: let time pass until the work in flight is done (or ``limit`` seconds,
        default :attr:`settle_limit`, all of which pass; such a cut is counted in
        :attr:`settle_cut` and :meth:`work_pending` says the work is still due).

        Work is every timer but the background ones: a monitor polls for as long as
        its state is active, so waiting for it would always run to the limit. Polls
        that fall due meanwhile still run, in time order.
        """
        clock = self.clock
        with self.owner:
            if not isinstance(clock, SimClock):
                self._drain()
                return
            end = clock.now() + (self.settle_limit if limit is None else limit)
            if self.hold_time:
                end = clock.now()
            self._drain()
            while True:
                self._commit()
                due = clock.next_deadline(work_only=True)
                if due is not None and due > end and not self.hold_time:
                    self.settle_cut += 1  # work pending at the limit: the limit's time passes
                    clock.run_until(end, settle=self._drain)
                    self._drain()
                    self._commit()
                    break
                if due is None or due > end:
                    break
                clock.run_until(due, settle=self._drain)
                self._drain()

    def work_pending(self) -> bool:
        """On a SimClock: device work (not a monitor's polls) is still due, as after a
        :meth:`settle` cut short at its limit; never with :attr:`hold_time`."""
        clock = self.clock
        if not isinstance(clock, SimClock) or self.hold_time:
            return False
        with self.owner:
            return clock.next_deadline(work_only=True) is not None

    def _commit(self) -> None:
        """As the owner: let accepted events (links) commit and run before time moves on.

        Otherwise a link event would wait in the journal while the clock ran to
        the settle limit, and a twin's completion would come before it.
        """
        while self.journal is not None and self.journal.queued:
            self.journal.flush()
            self._drain()

    def quiesce(self) -> None:
        """A batch run's pause: settle, and let every accepted event (links too) commit and run."""
        while True:
            self.settle()
            if self.journal is None:
                return
            self.journal.flush()
            with self.owner:
                if self.journal.queued == 0 and not any(s.queued for s in self.subjects.values()):
                    return

    def serve(self, stop: threading.Event, *, paced: bool = True) -> None:
        """The owner loop until ``stop``: drain when woken; on a SimClock follow the wall clock.

        Events wake it at once; the tick only moves a paced SimClock on and looks at ``stop``.
        Events posted before ``stop`` are run before it returns (the last line typed before
        the input ends, posted just before the feeder sets ``stop``, used to be dropped).
        """
        last = time.monotonic()
        sim = paced and isinstance(self.clock, SimClock)
        while not stop.is_set():
            self.wake.wait(_TICK)
            self.wake.clear()
            try:
                if sim:
                    now = time.monotonic()
                    self.advance(now - last)
                    last = now
                else:
                    self.drain()
            except StatectlError as exc:  # rule 7: a driver refused the event's data
                self._failed(exc)
        with self.owner:
            self._drain_past_failures()

    def _drain_past_failures(self, *, commit: bool = False) -> None:
        """As the owner: :meth:`_drain` (after :meth:`_commit`, the events accepted into the
        journal, with ``commit``), each driver failure reported (rule 7) and the rest run.
        The journal's writer drains so under durable-first, where a failure used to print
        a traceback on the writer's thread and count for nothing; so does a command with a
        ``when`` before it is judged, which must not fail for an earlier event's driver."""
        while True:  # each failure took its event off the queue: this ends
            try:
                if commit:
                    self._commit()
                self._drain()
                return
            except StatectlError as exc:
                self._failed(exc)

    def _failed(self, exc: StatectlError) -> None:
        """Rule 7 for the live owner loop: an observer (a driver) that raised during a step
        fails that event only; the run goes on, and the devices with events left are
        visited again."""
        for callback in self.on_failure:
            callback(exc)
        self._ready.extend(s for s in self.subjects.values() if s.queued)

    # -- asyncio (rule 5) ---------------------------------------------------------------------

    async def records(self, maxsize: int = 10_000) -> AsyncIterator[Record]:
        """Every device's records as they happen, until the consumer stops iterating: the
        owner hands each step over as one :class:`StepRecord`, whose typed records are built
        here, as they are iterated. A consumer that falls ``maxsize`` steps behind loses the
        oldest (never a stalled owner)."""
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[StepRecord] = asyncio.Queue(maxsize)

        def put(step: StepRecord) -> None:
            if queue.full():
                queue.get_nowait()
            queue.put_nowait(step)

        def listener(step: StepRecord) -> None:
            loop.call_soon_threadsafe(put, step)

        offs = [s.listen_steps(listener) for s in self.subjects.values()]
        try:
            while True:
                step = await queue.get()
                for record in step.records:
                    yield record
        finally:
            for off in offs:
                off()

    def start_owner(self, *, paced: bool = True) -> Callable[[], None]:
        """Run :meth:`serve` on a daemon thread; returns the function that stops it."""
        stop = threading.Event()
        thread = threading.Thread(
            target=self.serve,
            args=(stop,),
            kwargs={"paced": paced},
            daemon=True,
            name="statectl-system",
        )
        thread.start()

        def halt() -> None:
            stop.set()
            self.wake.set()
            if thread is not threading.current_thread():
                thread.join()

        return halt

    def close(self) -> None:
        """Commit what the journal holds, then stop the devices and the clock.

        Accepted events not yet processed stay in the journal for ``--resume``.
        """
        self._live = False
        with self.owner:
            try:
                if self.journal is not None:
                    self.journal.close()
            finally:
                for s in self.subjects.values():
                    s.close()
                if isinstance(self.clock, WallClock):
                    self.clock.stop()
