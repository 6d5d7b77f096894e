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
   ``max_queue`` a device whose queue holds that many events refuses more with
   :class:`QueueFull`, which tells a producer it outruns the device instead of
   letting memory grow.
5. asyncio: :meth:`System.send` posts and resolves once the device has
   processed the event (its outcome: ``handled`` or the
   :class:`~statectl.kernel.semantics.Unhandled` reason); :meth:`System.records` is an
   async iterator of every device's records. Both hand results to the event
   loop with ``call_soon_threadsafe``: the owner never waits for a coroutine.
6. A cell's rules hold at run time as verify assumed them (explore/enforce.py):
   an environment command whose every ``when`` is false is refused by
   :meth:`System.post` (:class:`~statectl.cell.explore.enforce.Refused`), judged as verify
   takes a command: once everything posted or accepted before it has run and its
   links have settled (the poster runs them as the owner if the owner has not yet);
   invariants
   are checked once a stimulus's cascade has settled (every link event it caused
   delivered, as verify takes a stimulus and its links as one move), each
   violation goes to the ``on_violation`` callbacks and sends the invariant's
   declared events (through the journal when there is one); link events carry
   their data; a device guard's ``In('other.State')`` reads the other device's
   state.
7. A row that fails while the owner drains (a guard or an assignment that raises,
   e.g. a linked event sent without the data its guard reads) refuses that event
   only: the device records it (``EventRejected``, guard error), the message goes
   to the ``on_failure`` callbacks (``statectl run`` prints it and exits 1), and
   the other devices and the device's later events go on. In the live owner loop
   (:meth:`System.serve`) an observer that raises a ``StatectlError`` (a driver
   refusing an event's data, ``Movement {amount: abc}``) fails the same way: the
   message goes to ``on_failure`` and the loop goes on; before, one bad event sent
   from the dashboard or typed into a ``--realtime`` run ended the whole run.
8. The door, :meth:`System.admit` (post and send): an event with an ``origin``
   (:mod:`statectl.run.commands`) enters if :attr:`System.commands` allows it, else
   ``CommandRefused``, journalled as a ``refused`` step that changes nothing. An event
   without one is the host's own (a driver, the Python API): one test.
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
from statectl.kernel.errors import StatectlError, did_you_mean
from statectl.kernel.model import Chart
from statectl.kernel.semantics.eventview import GuardError
from statectl.run.commands import Commands, Origin
from statectl.run.devices import DeviceDriver, connect
from statectl.run.journal import (
    Guarantee,
    Journal,
    JournalError,
    JournalledDevice,
    JournalReader,
    RecoveryRule,
    Ticket,
)
from statectl.run.runtime import Clock, Record, SimClock, StepRecord, Subject, WallClock
from statectl.run.runtime.eventdata import AssignError

__all__ = ["SETTLE_LIMIT", "DeviceSetup", "QueueFull", "System"]

#: Simulated seconds a batch run lets pass at most for one event to settle.
SETTLE_LIMIT = 60.0
_TICK = 0.02


class QueueFull(StatectlError):
    """A device's queue holds ``max_queue`` events: the producer outruns it (rule 4)."""


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
class System:
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
            if d.driver is not None:
                connect(s, d.driver)
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
        for send in self.links.sends(data):
            self.subjects[send.target].post(send.event, send.data)
        self._unchecked = self.rules is not None  # rule 6: once the cascade settles

    def _link_sends(self) -> list[tuple[JournalledDevice, str]]:
        """Rule 4 with a journal: the links a device's step fired, to journal with the step."""
        assert self.links is not None
        if not self._live:
            self.links.fired.clear()  # entering the initial states fires nothing
            return []
        self._unchecked = self.rules is not None  # rule 6: once the cascade settles
        return [(self.bound[k.target], k.event) for k in self.links.due()]

    def _settled_check(self) -> bool:
        """Rule 6 at the end of a cascade: report the invariants it broke and send their
        events (through the journal when the device is journalled); whether any was sent."""
        if not self._unchecked or (self.journal is not None and self.journal.queued):
            return False  # link events still wait in the journal: the cascade goes on
        self._unchecked = False
        sent = False
        for device, ev in self._violations():
            bound = self.bound.get(device)
            if bound is not None:
                bound.post(ev)
            else:
                self.subjects[device].post(ev)
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
        if self.owner.acquire(blocking=False):
            try:
                self._drain_past_failures()
            finally:
                self.owner.release()
        else:
            self.wake.set()

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

    def device(self, name: str | None) -> str:
        if name is None:
            if len(self.subjects) == 1:
                return next(iter(self.subjects))
            raise StatectlError(f"name the device: {', '.join(self.subjects)}")
        if name not in self.subjects:
            maybe = did_you_mean(name, list(self.subjects))
            raise StatectlError(f"no device {name!r}; {maybe}devices: {', '.join(self.subjects)}")
        return name

    def admit(
        self, device: str | None, event: str, data: Any = None, origin: Origin | None = None
    ) -> str:
        """The door (rules 4, 8): the device, once ``origin`` may send ``event`` and it has room."""
        name = self.device(device)
        if origin is not None and not self.commands.allows(origin, name, event):
            if (bound := self.bound.get(name)) is not None:
                with self.owner:  # between the device's steps: the row keeps their order
                    bound.refused(event, data, str(origin))
            raise self.commands.refusal(origin, name, event)
        limit = self.max_queue
        if limit is not None and self.subjects[name].queued >= limit:
            raise QueueFull(
                f"{name}: {limit} events are queued already (max_queue); the producer "
                "outruns the device: slow down, or retry once it has caught up"
            )
        return name

    def post(
        self, device: str | None, event: str, data: Any = None, *, origin: Origin | None = None
    ) -> Ticket | None:
        """Accept an event from outside (any thread); with a journal the ticket says when.

        Never blocks; a full device raises :class:`QueueFull` (rule 4); ``origin``: rule 8.
        """
        name = self.admit(device, event, data, origin)
        if self.rules is not None and self.rules.guarded(name, event):
            with self.owner:  # the global state once what came before has settled (rule 6)
                if not self._draining:  # (a post from a step: the drain running is the owner)
                    self._drain_past_failures(commit=True)  # what came before: run, links too
                self.rules.admit(name, event)  # Refused when every 'when' is false
        bound = self.bound.get(name)
        if bound is not None:
            ticket = bound.post(event, data)
            if bound.journal.guarantee is Guarantee.PROMPT:
                self.wake.set()  # the device has it now; durable-first: the writer wakes
            return ticket
        self.subjects[name].post(event, data)
        wake = self.wake
        if not wake.is_set():  # set already: the owner clears it before it drains
            wake.set()
        return None

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

    async def send(
        self, device: str | None, event: str, data: Any = None, *, origin: Origin | None = None
    ) -> str:
        """Post ``event`` and wait until its device has processed it; returns the outcome,
        ``"handled"`` or the :class:`~statectl.kernel.semantics.Unhandled` reason. Something
        must own the devices meanwhile (:meth:`serve` on a thread, :meth:`start_owner`). A
        journalled System accepts through its journal: use :meth:`post` and the ticket."""
        if self.journal is not None:
            why = "send() runs on a System without a journal; with one, post() and wait"
            raise StatectlError(f"{why} for the ticket")
        name = self.admit(device, event, data, origin)
        subject = self.subjects[name]
        loop = asyncio.get_running_loop()
        done: asyncio.Future[str] = loop.create_future()
        subject.post(
            event, data, then=lambda outcome: loop.call_soon_threadsafe(_resolve, done, outcome)
        )
        self.wake.set()
        return await done

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


def _resolve(future: asyncio.Future[str], result: str) -> None:
    if not future.done():  # the awaiting task may have been cancelled
        future.set_result(result)
