"""``statectl run DEVICE`` for real, and ``statectl journal show|replay|export``.

Rules:
1. A :class:`System` is devices on one clock with one owner at a time: whoever
   holds the owner lock (the thread in :meth:`System.serve`, a caller of
   :meth:`System.drain`, or the journal's writer) processes every device's
   events, run-to-completion, so devices never race each other.
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
3. Time: ``--realtime`` runs on a :class:`WallClock`; otherwise a
   :class:`SimClock`, which a live run (``--dashboard``) moves in step with the
   wall clock and a batch run (events from a file or stdin) moves only to let
   each event's consequences settle, so a batch run is deterministic.
4. A cell file runs the same way: one device per instance, on one clock and one
   owner, and the cell's links (:class:`~statectl.explore.replay.CellLinks`):
   after a device's step, each link it fired whose guard holds sends its event
   to the target, through the journal when there is one: the link events are
   journalled with the step that fired them, in one commit, so after a crash
   both are in the journal (the link event is redelivered if its target had not
   run it) or neither is (the step runs again on resume and fires them again).
   Each device's queue is first in, first out.
5. Events come as lines ``[DEVICE:] EVENT [DATA]`` (DATA in YAML flow style, e.g.
   ``Movement {amount: 10}``); ``+SECONDS`` lets simulated time pass; ``#``
   starts a comment. A bad line is reported with its number and skipped. A
   batch run reads them from stdin, and so does a live run without a dashboard.
6. Drivers: a ``--config`` file, else ``--driver`` for every device, else a
   :class:`~statectl.devices.SimTwin` with defaults for each device, derived
   from its tables (the banner says so), so every device reports its
   completions on the clock. A twin's notes appear in the trace as ``twin``.
7. The dashboard's host, port and token: the flags, else (the token) the
   ``STATECTL_DASHBOARD_TOKEN`` environment variable, else the config file's
   ``dashboard:`` section, else loopback, any free port and a new token, which
   is printed; a token from elsewhere is not echoed. A token shorter than 16
   characters is refused.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import heapq
import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

import yaml

from statectl.cell import Cell, load_cell
from statectl.devices import (
    MIN_TOKEN,
    DashboardConfig,
    DeviceDriver,
    RunConfig,
    SimTwin,
    TwinNote,
    connect,
    load_run_config,
    make_driver,
)
from statectl.errors import Diagnostic, DiagnosticError, Severity, StatectlError
from statectl.explore.replay import CellLinks
from statectl.journal import (
    Guarantee,
    Journal,
    JournalError,
    JournalledDevice,
    JournalReader,
    RecoveryRule,
    Sync,
    Ticket,
    export_jsonl,
    load_device,
    replay,
)
from statectl.model import Chart
from statectl.runtime import Clock, SimClock, Subject, TraceWriter, WallClock, format_data
from statectl.runtime.trace import format_record

__all__ = [
    "DeviceSetup",
    "System",
    "cell_setups",
    "is_cell",
    "journal_export",
    "journal_replay",
    "journal_show",
    "parse_event_line",
    "parse_time",
    "run",
]

OK, PROBLEMS, USAGE = 0, 1, 2
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


@dataclass(slots=True)
class System:
    """Devices on one clock with one owner; optionally journalled (rules 1-2)."""

    setups: Sequence[DeviceSetup]
    clock: Clock
    journal: Journal | None = None
    cell: Cell | None = None
    subjects: dict[str, Subject] = field(default_factory=dict)
    bound: dict[str, JournalledDevice] = field(default_factory=dict)
    wake: threading.Event = field(default_factory=threading.Event)
    owner: threading.RLock = field(default_factory=threading.RLock)
    links: CellLinks | None = None
    _live: bool = False  # started and not closing: the writer may drain

    def __post_init__(self) -> None:
        for d in self.setups:
            s = Subject(d.chart, clock=self.clock, name=d.name)
            self.subjects[d.name] = s
            if d.driver is not None:
                connect(s, d.driver)
            if self.journal is not None:
                self.bound[d.name] = JournalledDevice(s, self.journal, source=d.source)
        if self.cell is not None:
            links = self.links = CellLinks(self.cell, self.subjects)
            for name, s in self.subjects.items():
                s.listen(links.watch)
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
        for link in self.links.due():
            self.subjects[link.target].post(link.event)

    def _link_sends(self) -> list[tuple[JournalledDevice, str]]:
        """Rule 4 with a journal: the links a device's step fired, to journal with the step."""
        assert self.links is not None
        if not self._live:
            self.links.fired.clear()  # entering the initial states fires nothing
            return []
        return [(self.bound[k.target], k.event) for k in self.links.due()]

    def _committed(self) -> None:
        """On the writer after a commit (rule 2): drain now if nobody owns the devices."""
        if not self._live:
            return
        if self.owner.acquire(blocking=False):
            try:
                self._drain()
            finally:
                self.owner.release()
        else:
            self.wake.set()

    def listen(self, callback: Callable[[Any], None]) -> None:
        for s in self.subjects.values():
            s.listen(callback)

    def start(self, *, resume: bool = False) -> dict[str, bool]:
        """Start every device, or resume it from the journal; which ones were resumed."""
        resumed: dict[str, bool] = {}
        if resume and self.journal is None:
            raise StatectlError("--resume needs --journal DB")
        if resume and self.journal is not None:
            self.journal.flush()
            with JournalReader(self.journal.path) as reader:
                for d in self.setups:
                    resumed[d.name] = self.bound[d.name].resume(reader, d.rules)
        else:
            for d in self.setups:
                if d.name in self.bound:
                    self.bound[d.name].start()
                else:
                    self.subjects[d.name].start()
                resumed[d.name] = False
        if self.links is not None:
            self.links.fired.clear()  # entering the initial or restored states fires nothing
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
            raise StatectlError(f"no device {name!r}; devices: {', '.join(self.subjects)}")
        return name

    def post(self, device: str | None, event: str, data: Any = None) -> Ticket | None:
        """Accept an event from outside (any thread); with a journal the ticket says when."""
        name = self.device(device)
        bound = self.bound.get(name)
        if bound is not None:
            ticket = bound.post(event, data)
            if bound.journal.guarantee is Guarantee.PROMPT:
                self.wake.set()  # the device has it now; durable-first: the writer wakes
            return ticket
        self.subjects[name].post(event, data)
        self.wake.set()
        return None

    def drain(self) -> int:
        """Be the owner once: process every device's queue until all are empty."""
        with self.owner:
            return self._drain()

    def _drain(self) -> int:
        total = 0
        while True:
            n = sum(s.run_until_idle() for s in self.subjects.values())
            total += n
            if n == 0 and not any(s.queued for s in self.subjects.values()):
                return total

    def advance(self, seconds: float) -> None:
        """On a SimClock: let ``seconds`` pass as the owner, draining after every timer."""
        clock = self.clock
        if not isinstance(clock, SimClock):
            raise StatectlError("advance() needs a SimClock; a WallClock moves by itself")
        with self.owner:  # timers touch the clock and the devices: the owner's work
            self._drain()
            clock.advance(seconds, settle=self._drain)
            self._drain()

    def settle(self, limit: float = SETTLE_LIMIT) -> None:
        """On a SimClock: let time pass until the work in flight is done (or ``limit`` seconds).

        Work is every timer but the background ones: a monitor polls for as long as
        its state is active, so waiting for it would always run to the limit. Polls
        that fall due meanwhile still run, in time order.
        """
        clock = self.clock
        with self.owner:
            if not isinstance(clock, SimClock):
                self._drain()
                return
            end = clock.now() + limit
            self._drain()
            while True:
                self._commit()
                due = clock.next_deadline(work_only=True)
                if due is None or due > end:
                    break
                clock.run_until(due, settle=self._drain)
                self._drain()

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
        """
        last = time.monotonic()
        sim = paced and isinstance(self.clock, SimClock)
        while not stop.is_set():
            self.wake.wait(_TICK)
            self.wake.clear()
            if sim:
                now = time.monotonic()
                self.advance(now - last)
                last = now
            else:
                self.drain()

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


def parse_event_line(line: str) -> tuple[str | None, str, Any] | float | None:
    """``[DEVICE:] EVENT [DATA]`` -> (device, event, data); ``+S`` -> seconds; blank -> None."""
    text = line.split("#", 1)[0].strip()
    if not text:
        return None
    if text.startswith("+"):
        try:
            return float(text[1:])
        except ValueError:
            raise StatectlError(f"'+' needs seconds, e.g. '+1.5' (got {text!r})") from None
    device = None
    head, colon, rest = text.partition(":")
    if colon and "{" not in head and "[" not in head and rest.startswith(" "):
        device, text = head.strip(), rest.strip()
    data: Any = None
    brace = min((i for i in (text.find("{"), text.find("[")) if i >= 0), default=-1)
    if brace >= 0:
        try:
            data = yaml.safe_load(text[brace:])
        except yaml.YAMLError as exc:
            raise StatectlError(f"event data is not YAML flow style ({exc})") from None
        text = text[:brace]
    event = " ".join(text.split())
    if not event:
        raise StatectlError("no event name")
    return device, event, data


def parse_time(text: str) -> float:
    """Seconds since the epoch, or an ISO 8601 date-time (local time if it has no zone)."""
    try:
        return float(text)
    except ValueError:
        pass
    try:
        return dt.datetime.fromisoformat(text).timestamp()
    except ValueError:
        raise StatectlError(
            f"not a time: {text!r}; give seconds since the epoch or ISO 8601 (2024-05-01T12:00:00)"
        ) from None


def _drivers(
    devices: Sequence[DeviceSetup], driver: str | None, config: str | None, table: RunConfig
) -> dict[str, DeviceDriver]:
    """Rule 6: the config file's drivers, else ``driver`` for all, else a twin for each."""
    names = [d.name for d in devices]
    if table.drivers is not None:
        drivers = table.drivers
        missing = [n for n in names if n not in drivers]
        if missing:
            raise StatectlError(f"{config}: no driver for device(s) {missing}")
        return {d.name: make_driver(*drivers[d.name], chart=d.chart) for d in devices}
    return {d.name: make_driver(driver or "sim-twin", chart=d.chart) for d in devices}


#: The environment variable that may hold the dashboard's token (rule 7).
TOKEN_VARIABLE = "STATECTL_DASHBOARD_TOKEN"


def _dashboard_settings(
    host: str | None, port: int | None, token: str | None, config: str | None, dash: DashboardConfig
) -> tuple[str, int, str | None, str]:
    """Rule 7: flags, then the environment (token), then the config file, then the defaults.

    Returns host, port, token (None: the dashboard makes one) and where the token came from.
    """
    where = "--token"
    if token is None and os.environ.get(TOKEN_VARIABLE):
        token, where = os.environ[TOKEN_VARIABLE], TOKEN_VARIABLE
    if token is None and dash.token is not None:
        token, where = dash.token, str(config)
    if token is not None and len(token) < MIN_TOKEN:
        raise StatectlError(
            f"the dashboard token from {where} is shorter than {MIN_TOKEN} characters, "
            "so it could be guessed; make one with "
            "python -c 'import secrets; print(secrets.token_urlsafe(18))'"
        )
    host = host if host is not None else dash.host or "127.0.0.1"
    port = port if port is not None else dash.port or 0
    return host, port, token, where


def _show_notes(drivers: Mapping[str, DeviceDriver], out: TextIO, width: int) -> None:
    """Rule 6: a twin's notes (what it did not report, and why) go into the trace."""

    def writer(name: str) -> Callable[[TwinNote], None]:
        def write(note: TwinNote) -> None:
            out.write(f"t={note.time:7.2f}  {name:<{width}}  {'twin':<8} {note}\n")

        return write

    for name, d in drivers.items():
        if isinstance(d, SimTwin):
            d.on_note = writer(name)


def is_cell(path: str) -> bool:
    """A YAML file with a ``devices`` section and no ``states`` table is a cell file."""
    if Path(path).suffix.lower() not in (".yaml", ".yml"):
        return False
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    return isinstance(data, dict) and "devices" in data and "states" not in data


def _feed(system: System, lines: Iterable[str], err: TextIO, *, batch: bool) -> None:
    """Post each event line; a batch run settles after each (rule 3)."""
    for number, line in enumerate(lines, 1):
        try:
            parsed = parse_event_line(line)
            if parsed is None:
                continue
            if isinstance(parsed, float):
                if isinstance(system.clock, SimClock) and batch:
                    system.advance(parsed)
                    system.quiesce()
                else:
                    time.sleep(parsed)
                continue
            device, event, data = parsed
            ticket = system.post(device, event, data)
            if batch:
                if ticket is not None:
                    ticket.wait()
                system.quiesce()
        except StatectlError as exc:
            err.write(f"line {number}: {exc}\n")


#: Recovery warnings matter only when there is a journal to recover from.
JOURNAL_ONLY_WARNINGS = frozenset({"J606", "J608"})


def _warn(warnings: Iterable[Diagnostic], err: TextIO | None, journalled: bool) -> None:
    if err is None:
        return
    for d in warnings:
        if journalled or d.code not in JOURNAL_ONLY_WARNINGS:
            err.write(f"{d}\n")


def cell_setups(
    cell: Cell, err: TextIO | None = None, *, journalled: bool = True
) -> tuple[DeviceSetup, ...]:
    """One setup per device instance of ``cell``, with its device file's recovery rules.

    Raises one :class:`DiagnosticError` for every device file whose rules do not
    load; warnings go to ``err`` (recovery warnings only for a ``journalled`` run).
    """
    setups: list[DeviceSetup] = []
    problems: list[Diagnostic] = []
    for ref in cell.devices:
        try:
            dev = load_device(ref.path)
        except DiagnosticError as exc:
            problems.extend(exc.diagnostics)
            continue
        _warn(dev.warnings, err, journalled)
        setups.append(DeviceSetup(ref.name, ref.chart, dev.rules, ref.path))
    if problems:
        raise DiagnosticError(problems)
    return tuple(setups)


def _load_cell(path: str, err: TextIO, journalled: bool) -> tuple[Cell, tuple[DeviceSetup, ...]]:
    cell, diags = load_cell(path)
    if cell is None:
        raise DiagnosticError([d for d in diags if d.severity is not Severity.INFO])
    return cell, cell_setups(cell, err, journalled=journalled)


def _load_device(path: str, err: TextIO, journalled: bool) -> tuple[DeviceSetup, ...]:
    device = load_device(path)
    _warn(device.warnings, err, journalled)
    chart = device.chart
    return (DeviceSetup(chart.name, chart, device.rules, os.path.abspath(path)),)


def run(
    path: str,
    *,
    driver: str | None = None,
    config: str | None = None,
    dashboard: bool = False,
    host: str | None = None,
    port: int | None = None,
    token: str | None = None,
    journal: str | None = None,
    resume: bool = False,
    sync: str = "normal",
    guarantee: str = "prompt",
    realtime: bool = False,
    events: TextIO | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
    stop: threading.Event | None = None,
    ready: Callable[[System, str | None], None] | None = None,
) -> int:
    """The whole ``statectl run``; returns the exit code (0 ok, 1 problems, 2 usage).

    ``events`` (default: none in a live run, stdin in a batch run) feeds event
    lines. A live run (``dashboard`` or ``realtime``) serves until ``stop`` is set,
    stdin ends (without a dashboard) or Ctrl-C. ``ready(system, url)`` is called
    once everything runs (tests use it to find the dashboard's port).
    ``guarantee`` (``--guarantee``) is ``prompt`` or ``durable-first``: when a
    journalled event reaches its device (docs/journal.md).
    """
    if resume and journal is None:
        err.write("statectl run: --resume needs --journal DB\n")
        return USAGE
    if not Path(path).exists():
        err.write(f"statectl run: {path}: no such file\n")
        return USAGE
    try:
        mode = Sync(sync.lower())
    except ValueError:
        err.write(f"statectl run: --sync must be normal or full (got {sync!r})\n")
        return USAGE
    try:
        promise = Guarantee(guarantee.lower())
    except ValueError:
        err.write(
            f"statectl run: --guarantee must be prompt or durable-first (got {guarantee!r})\n"
        )
        return USAGE
    cell: Cell | None = None
    try:
        if is_cell(path):
            cell, devices = _load_cell(path, err, journal is not None)
        else:
            devices = _load_device(path, err, journal is not None)
    except DiagnosticError as exc:
        for d in exc.diagnostics:
            err.write(f"{d}\n")
        return PROBLEMS
    live = dashboard or realtime
    system: System | None = None
    server: Any = None
    try:
        table = RunConfig(None, DashboardConfig())
        if config is not None:
            table = load_run_config(config)
        drivers = _drivers(devices, driver, config, table)
        host, port, token, token_from = _dashboard_settings(
            host, port, token, config, table.dashboard
        )
        setups = tuple(replace(d, driver=drivers.get(d.name)) for d in devices)
        clock: Clock = WallClock() if realtime else SimClock()
        store = Journal(journal, sync=mode, guarantee=promise) if journal is not None else None
        system = System(setups, clock, store, cell)
        width = max(len(n) for n in system.subjects)
        if driver is None and config is None:
            out.write(f"no driver configured: simulated twins for {', '.join(drivers)}\n")
        system.listen(TraceWriter(out, device_width=width))
        _show_notes(drivers, out, width)
        url = None
        if dashboard:
            try:
                from statectl.web import Dashboard, Limits  # optional at run time
            except ImportError as exc:
                raise StatectlError(
                    f"the dashboard needs aiohttp ({exc}): pip install 'statectl[dashboard]'"
                ) from None
            streams = table.dashboard.streams
            limits = Limits() if streams is None else Limits(streams=streams)
            server = Dashboard(
                system.subjects.values(), post=system.post, token=token, limits=limits
            )
            url = server.start(host, port)
        resumed = system.start(resume=resume)
        for name, bound in system.bound.items():
            if resumed.get(name):
                taken = ", ".join(bound.recovered) or "none"
                out.write(
                    f"resumed {name} in {', '.join(sorted(system.subjects[name].configuration))}"
                    f"; recovery: {taken}; {bound.redelivered} accepted event(s) redelivered\n"
                )
        if server is not None:
            shown = server.token if token is None else f"(from {token_from})"
            out.write(f"dashboard: {url}\ntoken: {shown}\n")
        out.flush()
        if ready is not None:
            ready(system, url)
        if not live:
            if events is None and sys.stdin.isatty():
                err.write(
                    "reading event lines '[DEVICE:] EVENT [DATA]' or '+SECONDS' from the "
                    "terminal; end with Ctrl-D\n"
                )
            _feed(system, events if events is not None else sys.stdin, err, batch=True)
            system.quiesce()
            for name, subject in system.subjects.items():
                final = ", ".join(sorted(subject.configuration))
                out.write(f"final state {final}\n" if cell is None else f"final {name}: {final}\n")
            return OK
        halt = stop or threading.Event()
        if events is None and server is None:
            events = sys.stdin  # rule 5: without a dashboard, stdin is the operator
        if events is not None:
            feeder = threading.Thread(
                target=_feed_then_stop,
                args=(system, events, err, halt, server is None),
                daemon=True,
            )
            feeder.start()
        with contextlib.suppress(KeyboardInterrupt):
            system.serve(halt)
        return OK
    except (StatectlError, OSError) as exc:
        err.write(f"statectl run: {exc}\n")
        return PROBLEMS
    finally:
        if server is not None:
            server.stop()
        if system is not None:
            system.close()


def _feed_then_stop(
    system: System, lines: TextIO, err: TextIO, halt: threading.Event, stop_at_end: bool
) -> None:
    _feed(system, lines, err, batch=False)
    if stop_at_end:
        halt.set()


# -- statectl journal ------------------------------------------------------------------------


def _reader(path: str, err: TextIO) -> JournalReader | None:
    try:
        return JournalReader(path)
    except JournalError as exc:
        err.write(f"statectl journal: {exc}\n")
        return None


def _reader_in_window(
    command: str, path: str, since: str | None, until: str | None, err: TextIO
) -> tuple[JournalReader, float | None, float | None] | None:
    """The journal and the time window a ``journal show|export`` asks for; None: usage error."""
    try:
        lo = parse_time(since) if since is not None else None
        hi = parse_time(until) if until is not None else None
    except StatectlError as exc:
        err.write(f"statectl journal {command}: {exc}\n")
        return None
    reader = _reader(path, err)
    return None if reader is None else (reader, lo, hi)


def journal_show(
    path: str,
    *,
    device: str | None = None,
    since: str | None = None,
    until: str | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
) -> int:
    """``statectl journal show``: one line per accepted event and step, in order."""
    opened = _reader_in_window("show", path, since, until, err)
    if opened is None:
        return USAGE
    reader, lo, hi = opened

    def accepted() -> Iterator[tuple[float, int, str]]:
        for r in reader.inbox(device, lo, hi):
            data = "" if r.data is None else " " + format_data(r.data)
            yield r.wall, 0, f"#{r.seq:<6} {r.device}  accepted  {r.event}{data}"

    def steps() -> Iterator[tuple[float, int, str]]:
        for s in reader.steps(device, lo, hi):
            what = s.event or ""
            if s.data is not None:
                what += " " + format_data(s.data)
            via = f" (#{s.inbox})" if s.inbox else ""
            state = ", ".join(sorted(s.snapshot.active))
            text = f"step {s.id:<4} {s.device}  {s.kind.value:<8} {what}{via} -> [{state}]"
            if s.outcome and s.outcome != "handled":
                text += f"  {s.outcome}"
            yield s.wall, 1, text

    with reader:
        # Both come in journal order, which is wall-clock order: merged as they stream, so
        # a journal of millions of rows is shown without being held in memory.
        for wall, _, text in heapq.merge(accepted(), steps(), key=lambda x: (x[0], x[1])):
            stamp = dt.datetime.fromtimestamp(wall).isoformat(timespec="milliseconds")
            out.write(f"{stamp}  {text}\n")
    return OK


def journal_export(
    path: str,
    *,
    device: str | None = None,
    since: str | None = None,
    until: str | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
) -> int:
    """``statectl journal export``: JSON Lines (accepted events, then steps)."""
    opened = _reader_in_window("export", path, since, until, err)
    if opened is None:
        return USAGE
    reader, lo, hi = opened
    with reader:
        export_jsonl(reader, out, device=device, since=lo, until=hi)
    return OK


def journal_replay(
    path: str,
    *,
    device: str | None = None,
    model: Mapping[str, str] | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
) -> int:
    """``statectl journal replay``: rerun the journal on the model; 1 if it disagrees.

    The charts come from the device files the journal names, or ``model``
    (device -> file) where given.
    """
    reader = _reader(path, err)
    if reader is None:
        return USAGE
    with reader:
        charts: dict[str, Chart] = {}
        for d in reader.devices():
            if device is not None and d.name != device:
                continue
            source = (model or {}).get(d.name, d.source)
            try:
                charts[d.name] = load_device(source).chart
            except DiagnosticError as exc:
                err.write(f"statectl journal replay: {d.name}: cannot load {source}\n")
                for diag in exc.diagnostics:
                    err.write(f"{diag}\n")
                return PROBLEMS
        width = max((len(n) for n in charts), default=0)
        try:
            result = replay(
                reader,
                charts,
                device=device,
                listener=lambda r: print(format_record(r, device_width=width), file=out),
            )
        except JournalError as exc:
            err.write(f"statectl journal replay: {exc}\n")
            return PROBLEMS
    for m in result.mismatches:
        out.write(f"MISMATCH {m}\n")
    for name, snap in sorted(result.final.items()):
        out.write(f"final {name}: {', '.join(sorted(snap.active))}\n")
    out.write(f"{result.steps} step(s) replayed; {len(result.mismatches)} mismatch(es)\n")
    return OK if result.ok else PROBLEMS
