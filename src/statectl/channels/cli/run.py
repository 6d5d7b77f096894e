"""``statectl run DEVICE|CELL`` for real: one System fed event lines, optionally journalled.

The command's own concerns (drivers, dashboard settings, the journal it opens,
the feed of lines, what is printed and the exit code); the library under it is
:mod:`statectl.run.system` and :mod:`statectl.run.runner`.

Rules:
1. A run is a :class:`~statectl.run.system.System` (devices on one clock and one
   owner; journalled, a cell; see :mod:`statectl.run.system` for its own rules).
2. An existing journal is checked before the run uses it (journal/check.py): one
   that cannot be trusted is refused and nothing starts, unless ``--fresh`` sets it
   aside (renamed with a timestamp) for a new one. A journal that stops taking
   writes (a full disk) stops the run with a message; nothing more is accepted.
3. Time: ``--realtime`` runs on a :class:`WallClock`; otherwise a
   :class:`SimClock`, which a live run (``--dashboard``) moves in step with the
   wall clock and a batch run (events from a file or stdin) moves only to let
   each event's consequences settle, so a batch run is deterministic. A bus
   driver (``realtime``: cia402, cia402-sim, modbus) runs on wall time, so a batch
   run with one is refused (usage): it needs ``--realtime``.
4. A cell file runs the same way, its links sent by the System.
5. Events come as lines ``[DEVICE:] EVENT [DATA]`` (DATA in YAML flow style, e.g.
   ``Movement {amount: 10}``); ``+SECONDS`` lets simulated time pass; ``#``
   starts a comment. A bad line is reported with its number and skipped. A
   batch run reads them from stdin, and so does a live run without a dashboard.
6. Drivers: a ``--config`` file, else ``--driver`` for every device, else a
   :class:`~statectl.run.devices.SimTwin` with defaults for each device, derived
   from its tables (the banner says so), so every device reports its
   completions on the clock. A twin's notes appear in the trace as ``twin``.
7. The dashboard's host, port and token: the flags, else (the token) the
   ``STATECTL_DASHBOARD_TOKEN`` environment variable, else the config file's
   ``dashboard:`` section, else loopback, any free port and a new token, which
   is printed; a token from elsewhere is not echoed. A token shorter than 16
   characters is refused.
8. The config file's ``ship:`` section ships the journal to PostgreSQL while
   the run goes on (journal/ship.py): a thread of its own, woken by each
   commit; a server that is down is reported and retried, never waited for.
   At the end what was committed is shipped for a few seconds at most.
9. A run goes on past a bad event line (reported with its number and skipped),
   an event its device does not know, or one rejected under the ``error``
   policy, but then exits 1 with a line saying how many, so a batch run can be
   trusted in CI. A driver that lacks an observer method its chart calls is
   refused before anything runs (devices/base.py rule 6). A live run ends with
   the final-state line(s) too, and exits 1 when a driver says a bus outage left
   its device part-way (``unfinished()``: a write given up, a command cut off).
10. ``--driver none`` runs the model alone: no driver, so nothing but the events
    given happens (no completions, no monitors, no API calls); its invokes are
    still issued and shown. ``--json`` writes one JSON object per event line
    instead of the trace (cli/steps.py), the banners going to stderr; it steps a
    batch run, so it cannot go with a live one.
11. A driver named ``package.module:Class`` (``--driver`` or the config file) is
    imported from the Python path, else from beside the model file or the config
    file (their directories are searched after the path, so they never shadow an
    installed package); a module found in neither is refused with what to do.
10. A cell's environment command whose ``when`` is false is refused with the
   reason, and an invariant that turns false is written into the trace as
   ``VIOLATED`` (and sends its ``on_violation`` events); both make the run exit 1
   (system.py rule 6), so ``run`` enforces what ``verify`` assumed.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace
from typing import Any, TextIO

from statectl.cell.explore.enforce import Refused
from statectl.cell.model import Cell
from statectl.channels.cli.lifecycle import Ending, say_resumed
from statectl.channels.cli.outputs import output, wrote
from statectl.channels.cli.problems import Problems, verdict
from statectl.channels.cli.run_journal import (
    JOURNAL_NAME,
    new_journal,
    open_journal,
    undone_on_failure,
)
from statectl.channels.cli.run_options import RunOptions
from statectl.channels.cli.run_setup import (
    NO_DRIVER,
    dashboard_settings,
    drivers_for,
    load_cell_setups,
    load_device_setups,
    search_beside,
    show_notes,
)
from statectl.channels.cli.settle import unsettled_note
from statectl.channels.cli.steps import StepLog
from statectl.channels.opcua.config import OpcuaConfig
from statectl.channels.runconfig import RunConfig, run_config
from statectl.front.kinds import is_cell
from statectl.kernel.errors import (
    DiagnosticError,
    MissingExtra,
    StatectlError,
    did_you_mean,
)
from statectl.kernel.exits import PROBLEMS, USAGE
from statectl.run.commands import Origin
from statectl.run.devices import DeviceDriver
from statectl.run.journal import (
    Journal,
    JournalError,
)
from statectl.run.journal.ship_config import ShipConfig
from statectl.run.runner.events import parse_event_line
from statectl.run.runtime import Clock, SimClock, TraceWriter, WallClock
from statectl.run.system import DeviceSetup, System

#: Event lines typed or piped in come from the operator at the console (run/commands.py).
STDIN = Origin("stdin", "operator")


def _feed(
    system: System,
    lines: Iterable[str],
    err: TextIO,
    *,
    batch: bool,
    problems: Problems | None = None,
    steps: StepLog | None = None,
    early: list[int] | None = None,
) -> None:
    """Post each event line; a batch run settles after each (rule 3); count bad lines (rule 9).

    ``steps`` (a :class:`~statectl.channels.cli.steps.StepLog`, ``--json``) writes what each
    line did;
    ``early`` gets the event lines a batch run posted while work outlasting its settle
    limit was still in flight (cli/settle.py).
    """
    for number, line in enumerate(lines, 1):
        try:
            parsed = parse_event_line(line)
            if parsed is None:
                continue
            if isinstance(parsed, float):
                if isinstance(system.clock, SimClock) and batch:
                    system.advance(parsed)
                    system.quiesce()
                elif parsed > threading.TIMEOUT_MAX:  # time.sleep would overflow, killing the feed
                    raise StatectlError(
                        f"'+' waits at most {threading.TIMEOUT_MAX:.0f} s in a live run "
                        f"(got {parsed:g})"
                    )
                else:
                    time.sleep(parsed)
                if steps is not None:
                    steps.advance(number, parsed)
                continue
            device, event, data = parsed
            unknown = _unknown_event(system, device, event)
            if unknown is not None:  # posted still: the trace and the exit status say it too
                err.write(f"line {number}: {unknown}\n")
            if batch and early is not None and system.work_pending():
                early.append(number)
            ticket = system.submit(device, event, data, origin=STDIN).ticket  # the one door
            if batch:
                if ticket is not None:
                    ticket.wait()
                system.quiesce()
            if steps is not None:
                steps.event(number, device, event, data)
        except JournalError as exc:  # nothing more can be accepted: stop, say where
            raise JournalError(f"line {number}: {exc}") from None
        except Refused as exc:  # rule 10: as verify assumes, with the reason
            err.write(f"line {number}: {exc}\n")
            if problems is not None:
                problems.refuse()
        except StatectlError as exc:
            err.write(f"line {number}: {exc}\n")
            if problems is not None:
                problems.bad_line()
            if steps is not None:
                steps.error(number, str(exc))


def _unknown_event(system: System, device: str | None, event: str) -> str | None:
    """An event the device's chart does not know, with the name it most likely meant."""
    try:
        name = system.device(device)
    except StatectlError:
        return None  # no such device: post says so
    names = system.subjects[name].chart.event_names
    if event in names:
        return None
    maybe = did_you_mean(event, names)
    return f"{name} has no event {event!r}; {maybe}its events: {', '.join(names)}"


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
    fresh: bool = False,
    sync: str = "normal",
    guarantee: str = "prompt",
    realtime: bool = False,
    opcua: str | None = None,
    settle_limit: float | None = None,
    events: TextIO | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
    stop: threading.Event | None = None,
    ready: Callable[[System, str | None], None] | None = None,
    as_json: bool = False,
) -> int:
    """The whole ``statectl run``; returns the exit code (0 ok, 1 problems, 2 usage).

    ``events`` (default: none in a live run, stdin in a batch run) feeds event
    lines. A live run (``dashboard`` or ``realtime``) serves until ``stop`` is set,
    stdin ends (without a dashboard) or Ctrl-C. ``ready(system, url)`` is called
    once everything runs (tests use it to find the dashboard's port).
    ``guarantee`` (``--guarantee``) is ``prompt`` or ``durable-first``: when a
    journalled event reaches its device (docs/journal.md). ``fresh`` (``--fresh``)
    sets an existing journal aside and starts a new one; with ``resume`` only a
    journal that cannot be trusted is set aside (docs/journal.md, "Faults").
    ``opcua`` (``--opcua [URL]``; ``""``: the config's endpoint or the default)
    serves the devices over OPC UA, as does an ``opcua:`` section (docs/opcua.md).
    ``driver="none"`` runs the model alone and ``as_json`` (``--json``) writes one
    JSON object per event line (rule 10).
    """
    opts = RunOptions(
        driver=driver,
        config=config,
        dashboard=dashboard,
        host=host,
        port=port,
        token=token,
        journal=journal,
        resume=resume,
        fresh=fresh,
        sync=sync,
        guarantee=guarantee,
        realtime=realtime,
        opcua=opcua,
        settle_limit=settle_limit,
        as_json=as_json,
    )
    problem = opts.usage_problem(path)
    if problem is not None:
        err.write(f"statectl run: {problem}\n")
        return USAGE
    cell: Cell | None = None
    try:
        if is_cell(path):
            cell, devices = load_cell_setups(path, err, journal is not None)
        else:
            devices = load_device_setups(path, err, journal is not None)
    except DiagnosticError as exc:
        for d in exc.diagnostics:
            err.write(f"{d}\n")
        return PROBLEMS
    return _Run(path, opts, cell, devices, events, out, err).go(stop, ready)


class _Run:
    """One ``statectl run`` whose flags and model were read: set up, feed or serve, end.

    Its state is what the parts share: the options as the config file completed them
    (an ``opcua:`` section makes a live run; the journal's path as written), what it
    started (``ending``: stopped however the run leaves) and the problems it counted.
    """

    def __init__(
        self,
        path: str,
        opts: RunOptions,
        cell: Cell | None,
        devices: tuple[DeviceSetup, ...],
        events: TextIO | None,
        out: TextIO,
        err: TextIO,
    ) -> None:
        self.path, self.cell, self.devices = path, cell, devices
        self.events, self.out, self.err = events, out, err
        self.opts = opts
        self.info = err if opts.as_json else out  # rule 10: --json writes nothing else
        self.problems = Problems()
        self.ending = Ending("run", err)
        self.server: Any = None  # the dashboard
        self.plant: Any = None  # the OPC UA server (cli/opcua.py)
        self.steps: StepLog | None = None
        self.token_from = ""  # where the dashboard's token came from (rule 7)

    def go(
        self, stop: threading.Event | None, ready: Callable[[System, str | None], None] | None
    ) -> int:
        """Set up, start, then feed a batch or serve a live run; the exit code."""
        try:
            search_beside(self.path, self.opts.config)  # rule 11
            table = self._config()
            drivers = drivers_for(self.devices, self.opts.driver, self.opts.config, table)
            walled = [n for n, d in drivers.items() if getattr(d, "realtime", False)]
            if walled and not self.opts.live:  # rule 3: a bus on wall time never settles
                self.err.write(
                    f"statectl run: the driver of {', '.join(walled)} runs on the bus's wall "
                    "time; a batch run on simulated time would end before it reports: "
                    "add --realtime\n"
                )
                return USAGE
            system = self._system(table, drivers)
            url = self._attach(system, table, drivers)
            self._start(system, url)
            if ready is not None:
                ready(system, url)
            if not self.opts.live:
                return self._batch(system)
            return self._serve(system, drivers, stop)
        except (BrokenPipeError, MissingExtra):
            raise  # the reader went away: quietly; an extra missing (a config's section): exit 2
        except (StatectlError, OSError) as exc:
            return self.ending.fail(exc)
        finally:
            self.ending.close()

    def _config(self) -> RunConfig:
        """The ``--config`` file's sections; an ``opcua:`` section serves OPC UA (live)."""
        config = self.opts.config
        table = run_config(config)
        if self.opts.opcua is None and table.opcua != OpcuaConfig():
            self.opts = replace(self.opts, opcua="")
            if self.opts.as_json:
                raise StatectlError(f"{config}: its opcua: section makes a live run; not --json")
        return table

    def _system(self, table: RunConfig, drivers: Mapping[str, DeviceDriver]) -> System:
        """The System on its clock, journalled as asked, shipping as its config says."""
        opts = self.opts
        host, port, token, token_from = dashboard_settings(
            opts.host, opts.port, opts.token, opts.config, table.dashboard
        )
        self.opts = replace(opts, host=host, port=port, token=token)
        self.token_from = token_from
        setups = tuple(replace(d, driver=drivers.get(d.name)) for d in self.devices)
        clock: Clock = WallClock() if opts.realtime else SimClock()
        store, made = self._journal()
        opts = self.opts  # the journal's path as written (a directory given: the file in it)
        with undone_on_failure(store, opts.journal if store is not None and made else None):
            system = System(setups, clock, store, self.cell, commands=table.commands)
        self.ending.system = system
        if table.ship is not None:
            self.ending.after_close(_start_shipping(table.ship, store, opts.config, self.err).stop)
        if opts.settle_limit is not None:
            system.settle_limit = opts.settle_limit
        system.hold_time = opts.driver == NO_DRIVER and opts.config is None  # +S lines only
        if opts.driver is None and opts.config is None:
            self.info.write(f"no driver configured: simulated twins for {', '.join(drivers)}\n")
        elif not drivers:
            self.info.write("no driver (--driver none): the model alone, only the events given\n")
        return system

    def _journal(self) -> tuple[Journal | None, bool]:
        """The journal opened (rule 2) and whether this run made it; (None, False) without."""
        opts = self.opts
        if opts.journal is None:
            return None, False
        with output(opts.journal, JOURNAL_NAME, existing=False) as target:  # cli/outputs.py
            self.opts = opts = replace(opts, journal=str(target))
            journal = str(target)
            read = (self.path, opts.config, *(d.source for d in self.devices))
            made = new_journal(journal, resume=opts.resume, fresh=opts.fresh)
            mode, promise = opts.modes
            store = open_journal(
                journal,
                mode,
                promise,
                resume=opts.resume,
                fresh=opts.fresh,
                out=self.info,
                inputs=read,
            )
        return store, made

    def _attach(
        self, system: System, table: RunConfig, drivers: Mapping[str, DeviceDriver]
    ) -> str | None:
        """The trace (or --json), the problem counts, the dashboard and OPC UA; the page's URL."""
        width = max(len(n) for n in system.subjects)
        if self.opts.as_json:
            self.steps = StepLog(system, self.out)
        else:
            system.listen_steps(TraceWriter(self.out, device_width=width).step)
            show_notes(drivers, self.out, width)
        system.listen_steps(self.problems.step)
        shown = self.out if self.steps is None else self.info
        system.on_violation.append(self.problems.violation(shown, width))
        system.on_failure.append(self.problems.failure(self.err))  # system.py rule 7
        url = self._dashboard(system, table) if self.opts.dashboard else None
        if self.opts.opcua is not None:
            from statectl.channels.cli.opcua import serve_opcua

            self.plant = serve_opcua(
                system, self.opts.opcua, table.opcua, self.opts.config, self.out
            )
            self.ending.started(self.plant.stop)
        return url

    def _dashboard(self, system: System, table: RunConfig) -> str:
        """The live dashboard (rule 7), started; its URL."""
        try:
            from statectl.channels.web.app import Limits  # optional at run time
            from statectl.channels.web.server import Dashboard
        except ImportError:
            raise MissingExtra("the dashboard", "aiohttp", "dashboard") from None
        streams = table.dashboard.streams
        self.server = Dashboard(
            system.subjects.values(),
            post=self.problems.counting(system.post, self.err),
            token=self.opts.token,
            limits=Limits() if streams is None else Limits(streams=streams),
            origin=Origin("dashboard", "token"),  # its token is checked before it posts
            token_from=self.token_from,
        )
        self.ending.started(self.server.stop)
        url: str = self.server.start(self.opts.host, self.opts.port)
        return url

    def _start(self, system: System, url: str | None) -> None:
        """Start the devices (resuming them from the journal), and say what is running."""
        resumed = system.start(resume=self.opts.resume)
        if self.plant is not None:
            self.plant.refresh()
        say_resumed(system, resumed, self.info)
        if self.server is not None:
            token = self.opts.token
            shown = self.server.token if token is None else f"(from {self.token_from})"
            self.out.write(f"dashboard: {url}\ntoken: {shown}\n")
        self.out.flush()

    def _batch(self, system: System) -> int:
        """Rule 3: feed every line, each settled on the simulated clock, then the verdict."""
        if self.events is None and sys.stdin.isatty():
            self.err.write(
                "reading event lines '[DEVICE:] EVENT [DATA]' or '+SECONDS' from the "
                "terminal; end with Ctrl-D\n"
            )
        lines = self.events if self.events is not None else sys.stdin
        if self.steps is not None:
            self.steps.begin()  # what the start did is not a line's
        early: list[int] = []
        problems = self.problems
        _feed(system, lines, self.err, batch=True, problems=problems, steps=self.steps, early=early)
        system.quiesce()
        problems.unsettled = unsettled_note(system, early, system.work_pending())
        _final_states(system, self.info, self.cell is None, self.opts.journal)
        return verdict(problems, self.err)

    def _serve(
        self, system: System, drivers: Mapping[str, DeviceDriver], stop: threading.Event | None
    ) -> int:
        """A live run: serve until stopped, fed by stdin when no page is (rule 5)."""
        halt = stop or threading.Event()
        events = self.events
        if events is None and self.server is None:
            events = sys.stdin  # rule 5: without a dashboard, stdin is the operator
        if events is not None:
            alone = self.server is None and self.plant is None
            feeder = threading.Thread(
                target=_feed_then_stop,
                args=(system, events, self.err, halt, alone, self.problems),
                daemon=True,
            )
            feeder.start()
        with contextlib.suppress(KeyboardInterrupt):
            system.serve(halt)
        if system.journal is not None:
            system.journal.flush()  # a write that failed meanwhile fails the run
        _final_states(system, self.out, self.cell is None, self.opts.journal)
        self.problems.partway = _partway(drivers, self.err)
        return verdict(self.problems, self.err)


def _final_states(system: System, out: TextIO, one: bool, journal: str | None) -> None:
    """The line(s) a run ends with, batch or live: each device's configuration, and the
    journal it wrote (cli/outputs.py rule 4)."""
    for name, subject in system.subjects.items():
        final = ", ".join(sorted(subject.configuration))
        out.write(f"final state {final}\n" if one else f"final {name}: {final}\n")
    if journal is not None:
        wrote(out, journal)


def _partway(drivers: Mapping[str, DeviceDriver], err: TextIO) -> int:
    """Devices a bus outage left part-way (a driver's ``unfinished()``), each said (rule 9)."""
    count = 0
    for name, d in drivers.items():
        unfinished = getattr(d, "unfinished", None)
        why = unfinished() if callable(unfinished) else None
        if why:
            err.write(f"statectl run: {name} was left part-way by a bus outage: {why}\n")
            count += 1
    return count


def _feed_then_stop(
    system: System,
    lines: TextIO,
    err: TextIO,
    halt: threading.Event,
    stop_at_end: bool,
    problems: Problems,
) -> None:
    try:
        _feed(system, lines, err, batch=False, problems=problems)
    except JournalError:
        halt.set()  # the owner's loop ends; run() reports the failure from flush()
        return
    if stop_at_end:
        halt.set()


def _start_shipping(
    ship: ShipConfig, store: Journal | None, config: str | None, err: TextIO
) -> Any:
    """The ``ship:`` section's shipper, woken by each journal commit (journal/ship.py rule 4)."""
    from statectl.run.journal.ship import Shipper, ShipThread

    if store is None:
        raise StatectlError(f"{config}: 'ship:' ships the journal: run with --journal DB")
    shipper = Shipper(store.path, ship.to, source=ship.source, batch=ship.batch)
    thread = ShipThread(
        shipper,
        interval=ship.interval,
        retry=ship.retry,
        report=lambda text: err.write(f"statectl run: {text}\n"),
    )
    store.after_commit(thread.wake)
    thread.start()
    return thread
