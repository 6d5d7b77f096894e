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
import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, TextIO
from urllib.parse import urlparse

from statectl.cell.explore.enforce import Refused
from statectl.cell.model import Cell, load_cell
from statectl.channels.cli.commands import input_exists
from statectl.channels.cli.outputs import output, wrote
from statectl.channels.cli.problems import Problems, verdict
from statectl.channels.cli.run_journal import (
    JOURNAL_NAME,
    new_journal,
    open_journal,
    undone_on_failure,
)
from statectl.channels.cli.settle import unsettled_note
from statectl.channels.cli.steps import StepLog
from statectl.front.kinds import is_cell
from statectl.kernel.errors import (
    DiagnosticError,
    MissingExtra,
    Severity,
    StatectlError,
    did_you_mean,
)
from statectl.kernel.exits import PROBLEMS, USAGE
from statectl.run.commands import Origin
from statectl.run.devices import (
    MIN_TOKEN,
    DashboardConfig,
    DeviceDriver,
    OpcuaConfig,
    RunConfig,
    SimTwin,
    TwinNote,
    load_run_config,
    make_driver,
)
from statectl.run.devices.config import ShipConfig
from statectl.run.journal import (
    Guarantee,
    Journal,
    JournalError,
    Sync,
    load_device,
)
from statectl.run.runner.cells import load_setups, relevant_warnings
from statectl.run.runner.events import parse_event_line
from statectl.run.runtime import Clock, SimClock, TraceWriter, WallClock
from statectl.run.system import DeviceSetup, System


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
    if driver == NO_DRIVER:
        return {}  # rule 10: the model alone
    return {d.name: make_driver(driver or "sim-twin", chart=d.chart) for d in devices}


def _search_beside(*files: str | None) -> None:
    """Rule 11: a driver module may sit beside the model or config file (searched last)."""
    for f in files:
        if f is not None:
            folder = str(Path(f).resolve().parent)
            if folder not in sys.path:
                sys.path.append(folder)


#: ``--driver none``: no driver at all, the model alone (rule 10).
NO_DRIVER = "none"

#: The highest TCP port number (``--port``).
MAX_PORT = 65535

#: The environment variable that may hold the dashboard's token (rule 7).
TOKEN_VARIABLE = "STATECTL_DASHBOARD_TOKEN"
#: Event lines typed or piped in come from the operator at the console (run/commands.py).
STDIN = Origin("stdin", "operator")


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
            ticket = system.post(device, event, data, origin=STDIN)
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


def _load_cell(
    path: str, err: TextIO, journalled: bool, node: str | None = None
) -> tuple[Cell, tuple[DeviceSetup, ...]]:
    """The cell and its setups; the warnings printed are those of ``node``'s own devices
    when one is named (``statectl node``: the others run on other nodes)."""
    cell, diags = load_cell(path)
    if cell is None:
        raise DiagnosticError([d for d in diags if d.severity is not Severity.INFO])
    only = None
    if node is not None and cell.nodes is not None:
        names = {n.name for n in cell.nodes.nodes}
        only = cell.nodes.node(node).devices if node in names else ()
    setups, warnings = load_setups(cell, journalled=journalled, only=only)
    for d in warnings:
        err.write(f"{d}\n")
    return cell, setups


def _load_device(path: str, err: TextIO, journalled: bool) -> tuple[DeviceSetup, ...]:
    device = load_device(path)
    for d in relevant_warnings(device.warnings, journalled):
        err.write(f"{d}\n")
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
    if as_json and (dashboard or realtime or opcua is not None):
        err.write(
            "statectl run: --json steps a batch run; not with --dashboard, --realtime or --opcua\n"
        )
        return USAGE
    if (resume or fresh) and journal is None:
        err.write(f"statectl run: {'--resume' if resume else '--fresh'} needs --journal DB\n")
        return USAGE
    if not input_exists(Path(path)):
        err.write(f"statectl run: {path}: no such file\n")
        return USAGE
    if settle_limit is not None and not settle_limit > 0:
        err.write(
            f"statectl run: --settle-limit must be more than 0 seconds (got {settle_limit})\n"
        )
        return USAGE
    if port is not None and not 0 <= port <= MAX_PORT:
        err.write(f"statectl run: --port must be 0 (any free port) to {MAX_PORT} (got {port})\n")
        return USAGE
    if opcua and not (opcua.startswith("opc.tcp://") and urlparse(opcua).hostname):
        err.write(f"statectl run: --opcua must be an opc.tcp://HOST:PORT URL (got {opcua!r})\n")
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
    live = dashboard or realtime or opcua is not None
    problems = Problems()
    failed = ""  # what the run reported as its failure, if anything
    system: System | None = None
    server: Any = None
    plant: Any = None  # the OPC UA server (cli/opcua.py)
    shipping: Any = None  # a ShipThread (journal/ship.py) when the config has 'ship:'
    try:
        _search_beside(path, config)  # rule 11
        table = RunConfig(None, DashboardConfig())
        if config is not None:
            table = load_run_config(config)
        if opcua is None and table.opcua != OpcuaConfig():
            opcua, live = "", True  # an opcua: section serves it too
            if as_json:
                raise StatectlError(f"{config}: its opcua: section makes a live run; not --json")
        info = err if as_json else out  # rule 10: --json writes nothing else to stdout
        drivers = _drivers(devices, driver, config, table)
        walled = [n for n, d in drivers.items() if getattr(d, "realtime", False)]
        if walled and not live:  # rule 3: a bus on wall time never settles on a SimClock
            err.write(
                f"statectl run: the driver of {', '.join(walled)} runs on the bus's wall time; "
                "a batch run on simulated time would end before it reports: add --realtime\n"
            )
            return USAGE
        host, port, token, token_from = _dashboard_settings(
            host, port, token, config, table.dashboard
        )
        setups = tuple(replace(d, driver=drivers.get(d.name)) for d in devices)
        clock: Clock = WallClock() if realtime else SimClock()
        store = None
        if journal is not None:
            with output(
                journal, JOURNAL_NAME, existing=False
            ) as target:  # cli/outputs.py: the output rule
                journal = str(target)
                read = (path, config, *(d.source for d in devices))
                made = new_journal(journal, resume=resume, fresh=fresh)
                store = open_journal(
                    journal, mode, promise, resume=resume, fresh=fresh, out=info, inputs=read
                )
        with undone_on_failure(store, journal if store is not None and made else None):
            system = System(setups, clock, store, cell, commands=table.commands)
        if table.ship is not None:
            shipping = _start_shipping(table.ship, store, config, err)
        if settle_limit is not None:
            system.settle_limit = settle_limit
        system.hold_time = driver == NO_DRIVER and config is None  # time moves on +S lines only
        width = max(len(n) for n in system.subjects)
        if driver is None and config is None:
            info.write(f"no driver configured: simulated twins for {', '.join(drivers)}\n")
        elif not drivers:
            info.write("no driver (--driver none): the model alone, only the events given\n")
        steps = None
        if as_json:
            steps = StepLog(system, out)
        else:
            system.listen_steps(TraceWriter(out, device_width=width).step)
            _show_notes(drivers, out, width)
        system.listen_steps(problems.step)
        system.on_violation.append(problems.violation(out if steps is None else info, width))
        system.on_failure.append(problems.failure(err))  # system.py rule 7
        url = None
        if dashboard:
            try:
                from statectl.channels.web import Dashboard, Limits  # optional at run time
            except ImportError:
                raise MissingExtra("the dashboard", "aiohttp", "dashboard") from None
            streams = table.dashboard.streams
            limits = Limits() if streams is None else Limits(streams=streams)
            server = Dashboard(
                system.subjects.values(),
                post=problems.counting(system.post, err),
                token=token,
                limits=limits,
                origin=Origin("dashboard", "token"),  # its token is checked before it posts
                token_from=token_from,
            )
            url = server.start(host, port)
        if opcua is not None:
            from statectl.channels.cli.opcua import serve_opcua

            plant = serve_opcua(system, opcua, table.opcua, config, out)
        resumed = system.start(resume=resume)
        if plant is not None:
            plant.refresh()
        for name, bound in system.bound.items():
            if resumed.get(name):
                taken = ", ".join(bound.recovered) or "none"
                info.write(
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
            lines = events if events is not None else sys.stdin
            if steps is not None:
                steps.begin()  # what the start did is not a line's
            early: list[int] = []
            _feed(system, lines, err, batch=True, problems=problems, steps=steps, early=early)
            system.quiesce()
            problems.unsettled = unsettled_note(system, early, system.work_pending())
            _final_states(system, info, cell is None, journal)
            return verdict(problems, err)
        halt = stop or threading.Event()
        if events is None and server is None:
            events = sys.stdin  # rule 5: without a dashboard, stdin is the operator
        if events is not None:
            feeder = threading.Thread(
                target=_feed_then_stop,
                args=(system, events, err, halt, server is None and plant is None, problems),
                daemon=True,
            )
            feeder.start()
        with contextlib.suppress(KeyboardInterrupt):
            system.serve(halt)
        if system.journal is not None:
            system.journal.flush()  # a write that failed meanwhile fails the run
        _final_states(system, out, cell is None, journal)
        problems.partway = _partway(drivers, err)
        return verdict(problems, err)
    except (BrokenPipeError, MissingExtra):
        raise  # the reader went away: quietly; an extra missing (a config's section): exit 2
    except (StatectlError, OSError) as exc:
        failed = str(exc)
        err.write(f"statectl run: {exc}\n")
        return PROBLEMS
    finally:
        if server is not None:
            server.stop()
        if plant is not None:
            plant.stop()
        if system is not None:
            _close(system, err, failed)
        if shipping is not None:
            shipping.stop()  # what the journal committed goes too, for a few seconds at most


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


def _close(system: System, err: TextIO, failed: str) -> None:
    """Close the run; a journal failure not reported yet is reported (no traceback)."""
    try:
        system.close()
    except JournalError as exc:
        if str(exc) not in failed:
            err.write(f"statectl run: {exc}\n")
