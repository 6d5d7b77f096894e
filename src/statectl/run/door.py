"""The System's one front door (DESIGN.md, "One door") and the :class:`Submitted` it hands back.

Rules:
1. :class:`Door` is the part of :class:`~statectl.run.system.System` every event enters
   by (system.py rule 8): :meth:`Door.submit`, and :meth:`Door.post` / :meth:`Door.send`
   over it, checks the origin against the commands policy (:meth:`Door.admit`), the
   queue bound and a cell's ``when``, hands the event to the journal or the device,
   and decides, in :meth:`Door._run_here` alone, whether the calling thread runs the
   step now (also for a channel's own work on a device's owner, :meth:`Door.call_soon`).
   A cell's link events, drivers' completions, state timeouts and monitors' faults
   pass the same check (:meth:`Door._pass_link`, :meth:`Door._reporter`), each with
   the run's own origin (``link``, ``driver``, ``timer``, ``monitor``); a refused one
   is dropped with one log line and journalled as refused.
2. :meth:`Door.submit` returns a :class:`Submitted` for an event it
   let in: the device, the event, the journal's :class:`~statectl.run.journal.Ticket` when
   the System has a journal (None without one), and, once the device's step on that
   event has run, its :class:`~statectl.kernel.semantics.Outcome` (``HANDLED`` or why
   nothing happened). A refused event gets no handle: the door raises.
3. It is resolved on the owner, right after that step and before the device's next
   event, by the Subject's ``then`` hook: the owner never waits for anyone.
4. Like a ``concurrent.futures.Future``: :meth:`Submitted.done`,
   :meth:`Submitted.result` (blocks, with a timeout) and
   :meth:`Submitted.add_done_callback`; and awaitable from asyncio (``await handle``),
   which hands the outcome to the awaiting loop with ``call_soon_threadsafe`` (no hop
   when the step ran on the loop's own thread).
5. Cheap when nobody waits: no lock of its own (the GIL orders its few writes); a waiter's
   event is made only when someone blocks. A callback that raises is logged: the owner
   that resolved the handle goes on with the devices.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections import deque
from collections.abc import Callable, Generator, Iterable
from typing import Any

from statectl.cell.explore.enforce import CellRules
from statectl.kernel.errors import StatectlError, did_you_mean
from statectl.kernel.semantics import Outcome
from statectl.run.commands import INTERNAL, CommandRefused, Commands, Origin
from statectl.run.journal import Guarantee, Journal, JournalledDevice, Ticket
from statectl.run.runtime import Monitor, Subject

__all__ = ["Door", "QueueFull", "Submitted"]

_LOG = logging.getLogger("statectl.run.system")
#: What the log line says was dropped when the policy refuses the run's own (rule 1).
_DROPPED = {
    "driver": "driver completion",
    "timer": "timeout",
    "monitor": "monitor fault",
}


class QueueFull(StatectlError):
    """A device's queue holds ``max_queue`` events: the producer outruns it (system rule 4)."""


class Submitted:
    """An event the door let in; resolves with the outcome of its device's step (rules 2-5)."""

    __slots__ = ("_callbacks", "_error", "_outcome", "_waiter", "device", "event", "ticket")
    _making = threading.Lock()  # a waiter's event is made once, whoever asks first

    def __init__(self, device: str, event: str) -> None:
        self.device = device
        self.event = event
        #: the journal's ticket (when the inbox row is durable); None without a journal
        self.ticket: Ticket | None = None
        self._outcome: Outcome | None = None
        self._error: StatectlError | None = None  # no outcome will come (fail)
        self._waiter: threading.Event | None = None
        self._callbacks: list[Callable[[Submitted], object]] = []

    def __repr__(self) -> str:
        state = "pending" if self._outcome is None else self._outcome.value
        return f"<Submitted {self.device}: {self.event} {state}>"

    def resolve(self, outcome: Outcome) -> None:
        """Rule 3, on the owner right after the step: the outcome; later calls do nothing."""
        self._settle(outcome, None)

    def fail(self, error: StatectlError) -> None:
        """No outcome will come here (the device runs on another node): result() raises."""
        self._settle(Outcome.UNKNOWN_EVENT, error)  # an outcome marks it done; never read

    def _settle(self, outcome: Outcome, error: StatectlError | None) -> None:
        """Rule 5 without a lock: the outcome is set before the waiter and the callbacks are
        read, and they are set before the outcome is read (each list pop is atomic), so
        whichever side comes second sees the other; each callback is popped once."""
        if self._outcome is not None:
            return
        self._error = error
        self._outcome = outcome
        waiter = self._waiter
        if waiter is not None:
            waiter.set()
        self._call_back()

    def _call_back(self) -> None:
        callbacks = self._callbacks
        while callbacks:
            try:
                fn = callbacks.pop(0)
            except IndexError:  # the other side took the last one
                return
            try:  # on the owner: a callback's error must not stop the devices
                fn(self)
            except Exception:
                _LOG.exception("a Submitted callback for %s: %s raised", self.device, self.event)

    def done(self) -> bool:
        """Whether the device's step on the event has run (or :meth:`fail` said none will)."""
        return self._outcome is not None

    def result(self, timeout: float | None = None) -> Outcome:
        """The step's outcome, waiting at most ``timeout`` seconds (None: as long as it takes).

        Someone must own the devices meanwhile (``System.serve``, ``start_owner``), unless
        the door ran the step on the submitting thread."""
        if self._outcome is None:
            with self._making:
                waiter = self._waiter
                if waiter is None:
                    waiter = self._waiter = threading.Event()
            if self._outcome is None and not waiter.wait(timeout):
                raise TimeoutError(
                    f"{self.device}: {self.event} did not run within {timeout} s; is anything "
                    "owning the devices (System.serve, start_owner)?"
                )
        if self._error is not None:
            raise self._error
        assert self._outcome is not None
        return self._outcome

    def add_done_callback(self, fn: Callable[[Submitted], object]) -> None:
        """Call ``fn(self)`` once resolved: on the owner, or now if it is already."""
        self._callbacks.append(fn)
        if self._outcome is not None:
            self._call_back()

    def __await__(self) -> Generator[Any, None, Outcome]:
        """Rule 4: ``await handle`` in a coroutine returns the outcome."""
        if self._outcome is not None:
            return self.result()
        loop = asyncio.get_running_loop()
        future: asyncio.Future[Outcome] = loop.create_future()
        here = threading.get_ident()

        def hand_over(done: Submitted) -> None:
            if threading.get_ident() == here:
                _hand(future, done)
                return
            with contextlib.suppress(RuntimeError):  # the loop closed: stopping
                loop.call_soon_threadsafe(_hand, future, done)

        self.add_done_callback(hand_over)
        return (yield from future.__await__())


def _hand(future: asyncio.Future[Outcome], done: Submitted) -> None:
    if future.done():  # the awaiting task may have been cancelled
        return
    if done._error is not None:
        future.set_exception(done._error)
    else:
        assert done._outcome is not None
        future.set_result(done._outcome)


class Door:
    """The System's one front door (rule 1); :class:`~statectl.run.system.System` is one."""

    __slots__ = ()
    # what the door reads of its System (statectl.run.system.System's fields)
    subjects: dict[str, Subject]
    bound: dict[str, JournalledDevice]
    journal: Journal | None
    commands: Commands
    rules: CellRules | None
    max_queue: int | None
    owner: threading.RLock
    wake: threading.Event
    _live: bool
    _draining: bool
    _ready: deque[Subject]
    _unchecked: bool

    def _drain_past_failures(self, *, commit: bool = False) -> None:
        raise NotImplementedError  # the System's (system.py rule 7)

    def _failed(self, exc: StatectlError) -> None:
        raise NotImplementedError  # the System's (system.py rule 7)

    def _as_owner(self, step: Callable[[], object]) -> None:
        raise NotImplementedError  # the System's (system.py rule 1)

    def device(self, name: str | None) -> str:
        """The device ``name`` names (None: the only one), or what to write instead."""
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
        name = device if device in self.subjects else self.device(device)
        if origin is not None and not self.commands.allows(origin, name, event):
            if (bound := self.bound.get(name)) is not None:
                with self.owner:  # between the device's steps: the row keeps their order
                    bound.refused(event, data, str(origin))
            raise self.commands.refusal(origin, name, event)
        limit = self.max_queue
        inside = origin is not None and origin.channel in INTERNAL
        if limit is not None and not inside and self.subjects[name].queued >= limit:
            raise QueueFull(
                f"{name}: {limit} events are queued already (max_queue); the producer "
                "outruns the device: slow down, or retry once it has caught up"
            )
        return name

    def submit(
        self,
        device: str | None,
        event: str,
        data: Any = None,
        *,
        origin: Origin | None,
        note: tuple[str, str] | None = None,
    ) -> Submitted:
        """The one front door (rule 8): ``event`` for ``device`` from ``origin``; the handle
        resolves with the outcome of the device's step on it (run/door.py).

        Raises ``CommandRefused`` (journalled), :class:`QueueFull` or another
        ``StatectlError`` when the event does not get in. ``note``: a journal ``meta`` row
        committed with its inbox row (a Zenoh stream's position).
        """
        name = self.admit(device, event, data, origin)
        handle = Submitted(name, event)
        journal = self.journal
        if journal is None and (self.rules is None or not self.rules.guarded(name, event)):
            subject = self.subjects[name]  # no inbox row to write, no 'when' to judge first
            if self._run_here(lambda: self._step_here(subject, event, data, handle)):
                return handle
            self._let_in(name, event, data, handle.resolve, None, True)
            return handle
        here = journal is None or journal.guarantee is Guarantee.PROMPT  # else: the writer's
        handle.ticket = self._let_in(name, event, data, handle.resolve, note, not here)
        if here:
            self._run_here()  # it runs now, or wakes the owner
        return handle

    def post(
        self, device: str | None, event: str, data: Any = None, *, origin: Origin | None = None
    ) -> Ticket | None:
        """:meth:`submit` without a handle, never running the step here: it never blocks
        (rule 4); with a journal the ticket says when the event is durable."""
        return self._let_in(self.admit(device, event, data, origin), event, data, None, None, True)

    def _let_in(
        self,
        name: str,
        event: str,
        data: Any,
        then: Callable[[Outcome], object] | None,
        note: tuple[str, str] | None,
        wake: bool,
    ) -> Ticket | None:
        """Past the policy: a cell's ``when`` (rule 6), then the journal or the device; then
        ``wake`` the owner (submit does not when it is about to run the step itself).
        Called with positional arguments only: CPython 3.11 runs a call that names its
        arguments on its generic path (``Subject.post`` says the same)."""
        if self.rules is not None and self.rules.guarded(name, event):
            with self.owner:  # the global state once what came before has settled (rule 6)
                if not self._draining:  # (a post from a step: the drain running is the owner)
                    self._drain_past_failures(commit=True)  # what came before: run, links too
                self.rules.admit(name, event)  # Refused when every 'when' is false
        bound = self.bound.get(name)
        if bound is not None:
            ticket = bound.post(event, data, note=note, then=then)
            if wake and bound.journal.guarantee is Guarantee.PROMPT:
                self.wake.set()  # the device has it now; durable-first: the writer wakes
            return ticket
        self.subjects[name].post(event, data, then)
        if wake and not self.wake.is_set():  # set already: the owner clears it before it drains
            self.wake.set()
        return None

    def call_soon(self, device: str, fn: Callable[[], object]) -> None:
        """Run ``fn`` on ``device``'s owner, in order with its events (a channel's journal
        note after the steps before it: an OPC UA acknowledgement); as for :meth:`submit`,
        the door decides whether the calling thread runs it now."""
        self.subjects[self.device(device)].call_soon(fn)
        self._run_here()

    def _run_here(self, step: Callable[[], object] | None = None) -> bool:
        """Rule 8, the one place that decides it: the calling thread runs ``step`` and the
        devices' queued work now when the System is live and nobody owns the devices (it
        owns them meanwhile, rule 7 for failures); the owner running a step goes on with
        its drain. Else it does nothing (without ``step``: it wakes the owner)."""
        if self._live and self.owner.acquire(blocking=False):
            try:
                if not self._draining:
                    if step is not None:
                        self._as_owner(step)  # a submit from within it waits for the drain
                    if step is None or self._ready or self._unchecked:
                        self._drain_past_failures()  # what the step queued (links), or all
                    return True
            finally:
                self.owner.release()
        if step is None:
            self.wake.set()
        return False

    def _step_here(self, subject: Subject, event: str, data: Any, handle: Submitted) -> None:
        """As the owner: the device runs ``event`` now, after what it had queued (the
        Subject's ``dispatch``, no queue in between). A failure in the step is rule 7's;
        one before it (the event's data refused) is the submitter's, as a post's is."""
        try:
            subject.dispatch(event, data, then=handle.resolve)
        except StatectlError as exc:
            if not handle.done():
                raise
            self._failed(exc)

    def _reporter(
        self, device: str, channel: str = "driver", hand: Callable[..., None] | None = None
    ) -> Callable[..., None]:
        """What the run's own ``channel`` hands ``device``'s events to (rule 1): a driver's
        completions and a monitor's faults queued as before (``hand``, by default the
        Subject's ``post``: not run here, the driver may be on the owner mid-step), a
        timeout processed at once (``hand`` the Subject's ``deliver``, timers.py rule 2);
        never into the journal's inbox (the journal has the step). Refused by the policy:
        dropped, one log line, journalled as refused. Open to all (the default): ``hand``
        itself, nothing to ask per event."""
        origin = Origin(channel, device)
        give = self.subjects[device].post if hand is None else hand
        if self.commands.open_to_all(channel):
            return give
        what = _DROPPED[channel]

        def report(event: str, data: Any = None) -> None:
            try:
                self.admit(device, event, data, origin)
            except CommandRefused as exc:
                _LOG.warning("%s dropped: %s", what, exc)
                return
            give(event, data)

        return report

    def _route_own(self, device: str, monitors: Iterable[Monitor] = ()) -> None:
        """Rule 1: ``device``'s timers and ``monitors`` hand their events to the door."""
        subject = self.subjects[device]
        if subject.timers:
            timeout = self._reporter(device, "timer", subject.deliver)
            for t in subject.timers:
                t.report = timeout
        if monitors:
            fault = self._reporter(device, "monitor")
            for m in monitors:
                m.report = fault

    def _pass_link(self, source: str, target: str, event: str, data: Any) -> None:
        """Rule 1 for a cell's link event, on the owner after its source's step: queued
        for the target once the policy lets it in (:meth:`_link_admitted`)."""
        if self._link_admitted(source, target, event, data):
            self.subjects[target].post(event, data)

    def _send_own(self, device: str, event: str) -> None:
        """An event the run sends itself, on the owner (an invariant's declared event,
        system.py rule 6): through the journal when the device is journalled, else queued
        on it; the policy is not asked, as for the host's own (``origin=None``)."""
        bound = self.bound.get(device)
        if bound is not None:
            bound.post(event)
        else:
            self.subjects[device].post(event)

    def _link_admitted(self, source: str, target: str, event: str, data: Any) -> bool:
        """Rule 8 for a cell's link event (on the owner): whether the policy lets it in; a
        refused one is journalled as refused, dropped, and said in one log line."""
        if self.commands.open_to_all("link"):  # the default: no check to pay per link event
            return True
        try:
            self.admit(target, event, data, Origin("link", source))
        except CommandRefused as exc:
            _LOG.warning("link event dropped: %s", exc)
            return False
        return True

    async def send(
        self, device: str | None, event: str, data: Any = None, *, origin: Origin | None = None
    ) -> str:
        """``await`` :meth:`submit`: the outcome once its device processed the event,
        ``"handled"`` or the :class:`~statectl.kernel.semantics.Unhandled` reason; with or
        without a journal. Something owns the devices meanwhile (:meth:`serve`,
        :meth:`start_owner`) unless the door runs the step on the loop's thread."""
        return await self.submit(device, event, data, origin=origin)
