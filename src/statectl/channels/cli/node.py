"""``statectl node CELL --node NAME``: one node of a cell spread over processes, on Zenoh.

Rules:
1. The node runs the devices its ``nodes:`` entry lists, in one
   :class:`~statectl.channels.distributed.NodeSystem` on the wall clock, with drivers as
   ``statectl run`` chooses them (``--config``, ``--driver``, else twins). Links to
   devices on other nodes go over Zenoh (:mod:`statectl.channels.distributed.wire`).
2. ``--journal DB`` journals this node's devices and the link events it sent and
   received; ``--resume`` brings this node back from it, whatever the others do.
3. Event lines ``DEVICE: EVENT [DATA]`` on stdin are posted (a device on another
   node gets it forwarded); the end of stdin does not stop the node. SIGTERM or
   Ctrl-C stop it: it prints each device's final state and exits 0 (1 if an
   event line was bad or an event unknown, as ``statectl run``).
4. It prints which peers it sees as they come and go.
5. It holds the cell to what verify assumes, as ``statectl run CELL`` does, over
   what it sees (statectl.channels.distributed.system rule 6): a refused environment
   command (from stdin or forwarded) and an invariant it sees violated are
   reported and make it exit 1.
6. Its banner's second line says what a peer must prove to connect (the cell's
   ``security:``: mutual TLS, user/password, open on loopback, or insecure); a
   cell reachable off loopback without TLS does not load (V827).
   ``statectl dashboard --as NAME`` is a station of the cell's ``security:
   stations`` (its certificate); its ``--connect`` follows V827's rule.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from statectl.kernel.errors import DiagnosticError, StatectlError, did_you_mean
from statectl.kernel.exits import OK, PROBLEMS, USAGE

if TYPE_CHECKING:  # imported where used: every command's start imports this module
    from statectl.channels.cli.problems import Problems

__all__ = ["dashboard_main", "node_main", "register"]


def register(sub: Any) -> None:
    """Add ``node`` and ``dashboard`` to the CLI's subparsers (``sub``)."""
    s = sub.add_parser(
        "node",
        help="run one node of a cell whose devices are spread over processes (Zenoh)",
        description="Runs the devices the cell file's nodes: section puts on NAME; links to "
        "devices on other nodes travel over Zenoh (peer mode, the endpoints the cell file "
        "gives, no multicast). Event lines 'DEVICE: EVENT [DATA]' come from stdin; SIGTERM "
        "or Ctrl-C stop it (docs/distributed.md).",
    )
    s.add_argument("file", metavar="CELL", help="cell file with a nodes: section")
    s.add_argument("--node", required=True, help="which node of the cell this process runs")
    s.add_argument("--driver", help="driver for every device (default: simulated twins)")
    s.add_argument("--config", help="run configuration YAML: drivers, dashboard settings")
    s.add_argument("--journal", metavar="DB", help="journal this node to this SQLite file")
    s.add_argument("--resume", action="store_true", help="resume this node from its journal")
    s.add_argument("--fresh", action="store_true", help="set an existing journal aside first")
    s.add_argument(
        "--guarantee",
        default="prompt",
        help="when a journalled event reaches its device: prompt or durable-first",
    )
    s.add_argument("--dashboard", action="store_true", help="serve the whole cell's dashboard")
    s.add_argument("--host", help="dashboard address (default: loopback)")
    s.add_argument("--port", type=int, help="dashboard port (default: any free)")
    s.add_argument("--token", help="dashboard token (default: as statectl run)")
    s.add_argument("--quiet", action="store_true", help="do not print every device record")
    s.set_defaults(func=_cmd_node)

    s = sub.add_parser(
        "dashboard",
        help="serve the live dashboard of a cell whose nodes run elsewhere (operator station)",
        description="Connects to the nodes' Zenoh endpoints (the cell file's listen endpoints, "
        "or --connect) with no devices of its own and serves the whole cell's dashboard: "
        "states live from Zenoh, events posted with the token go to the device's node.",
    )
    s.add_argument("file", metavar="CELL", help="cell file with a nodes: section")
    s.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="Zenoh endpoint to connect to (repeatable; default: every node's listen endpoints)",
    )
    s.add_argument("--config", help="run configuration YAML: its dashboard: section")
    s.add_argument(
        "--as",
        dest="station",
        metavar="NAME",
        help="this station's name among the cell's security: stations (its certificate)",
    )
    s.add_argument("--host", help="dashboard address (default: loopback)")
    s.add_argument("--port", type=int, help="dashboard port (default: any free)")
    s.add_argument("--token", help="dashboard token (default: as statectl run)")
    s.set_defaults(func=_cmd_dashboard)


def _cmd_dashboard(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    return dashboard_main(
        args.file,
        connect=args.connect,
        config=args.config,
        as_station=args.station,
        host=args.host,
        port=args.port,
        token=args.token,
        out=out,
        err=err,
    )


def dashboard_main(
    path: str,
    *,
    connect: list[str] | None = None,
    config: str | None = None,
    as_station: str | None = None,
    host: str | None = None,
    port: int | None = None,
    token: str | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
    stop: threading.Event | None = None,
) -> int:
    """``statectl dashboard CELL``: the operator station (docs/distributed.md)."""
    from statectl.cell.model import load_cell
    from statectl.channels.cli import run_setup
    from statectl.channels.distributed.dashboard import station
    from statectl.channels.runconfig import run_config

    if not Path(path).exists():
        err.write(f"statectl dashboard: {path}: no such file\n")
        return USAGE
    if _bad_usage("dashboard", port, connect or (), err):
        return USAGE
    if _not_a_cell(path, err):
        return PROBLEMS
    cell, diags = load_cell(path)
    if cell is None:
        for d in diags:
            err.write(f"{d}\n")
        return PROBLEMS
    if cell.nodes is None and not connect:
        err.write(f"statectl dashboard: {path}: the cell has no nodes: section\n")
        return PROBLEMS
    if _plain_off_loopback(cell, connect or (), err):
        return PROBLEMS
    halt = stop or threading.Event()
    try:
        table = run_config(config)
        host, port, token, where = run_setup.dashboard_settings(
            host, port, token, config, table.dashboard
        )
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, lambda *_: halt.set())
        with contextlib.suppress(KeyboardInterrupt):
            return station(
                cell,
                connect=connect,
                settings=(host, port, token),
                token_from=where,
                out=out,
                stop=halt,
                streams=table.dashboard.streams,
                station=as_station,
            )
        return OK
    except (StatectlError, OSError) as exc:
        err.write(f"statectl dashboard: {exc}\n")
        return PROBLEMS
    except Exception as exc:  # Zenoh's own errors (an endpoint it cannot use), as node's
        if type(exc).__name__ != "ZError":
            raise
        err.write(f"statectl dashboard: Zenoh: {exc}\n")
        return PROBLEMS


def _cmd_node(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    return node_main(
        args.file,
        node=args.node,
        driver=args.driver,
        config=args.config,
        journal=args.journal,
        resume=args.resume,
        fresh=args.fresh,
        guarantee=args.guarantee,
        dashboard=args.dashboard,
        host=args.host,
        port=args.port,
        token=args.token,
        quiet=args.quiet,
        out=out,
        err=err,
    )


def node_main(
    path: str,
    *,
    node: str,
    driver: str | None = None,
    config: str | None = None,
    journal: str | None = None,
    resume: bool = False,
    fresh: bool = False,
    guarantee: str = "prompt",
    dashboard: bool = False,
    host: str | None = None,
    port: int | None = None,
    token: str | None = None,
    quiet: bool = False,
    events: TextIO | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
    stop: threading.Event | None = None,
) -> int:
    """The whole ``statectl node``; returns the exit code (0 ok, 1 problems, 2 usage)."""
    from statectl.channels.cli.lifecycle import Ending, say_resumed
    from statectl.channels.cli.problems import Problems, verdict
    from statectl.channels.distributed import Wire

    setup = _node_setup(path, node, journal, resume, fresh, guarantee, port, err)
    if isinstance(setup, int):
        return setup
    promise, cell, devices, mine = setup
    problems = Problems()
    ending = Ending("node", err)
    ending.after_close(out.flush)
    halt = stop or threading.Event()
    try:
        system, table, drivers, journal = _node_system(
            cell, devices, path, driver, config, journal, resume, fresh, promise, out
        )
        ending.system = system
        wire = Wire(
            cell,
            node,
            system,
            out=out,
            journal=Path(journal) if journal is not None else None,
            resume=resume,
        )
        ending.started(wire.close)
        _listen(system, wire, problems, drivers, quiet, out, err)
        _announce(cell, node, mine, wire, out)
        wire.open(states=dashboard)
        resumed = system.start(resume=resume)
        say_resumed(system, resumed, out)
        wire.listen()
        if dashboard:
            server, url, shown = _node_dashboard(
                cell, system, wire, host, port, token, config, table
            )
            ending.started(server.stop)
            wire.refresh()  # states put before the page listened
            out.write(f"dashboard: {url}\ntoken: {shown}\n")
        out.write(f"node {node}: running\n")
        out.flush()
        _serve(system, halt, events, problems, out, err)
        return verdict(problems, err, "node")
    except (StatectlError, OSError) as exc:
        return ending.fail(exc)
    except Exception as exc:  # Zenoh's own errors (a port in use, a bad endpoint)
        if type(exc).__name__ != "ZError":
            raise
        return ending.fail(exc, "Zenoh: ")
    finally:
        ending.close()


def _node_setup(
    path: str,
    node: str,
    journal: str | None,
    resume: bool,
    fresh: bool,
    guarantee: str,
    port: int | None,
    err: TextIO,
) -> int | tuple[Any, Any, tuple[Any, ...], Any]:
    """The exit code of a bad start (usage 2, problems 1), or what the node runs: the
    journal's promise, the cell, this node's device setups and their names."""
    from statectl.channels.cli import run_setup
    from statectl.run.journal import Guarantee

    if (resume or fresh) and journal is None:
        err.write(f"statectl node: {'--resume' if resume else '--fresh'} needs --journal DB\n")
        return USAGE
    if not Path(path).exists():
        err.write(f"statectl node: {path}: no such file\n")
        return USAGE
    if _bad_usage("node", port, (), err):
        return USAGE
    if _not_a_cell(path, err):
        return PROBLEMS
    try:
        promise = Guarantee(guarantee.lower())
    except ValueError:
        said = f"--guarantee must be prompt or durable-first (got {guarantee!r})"
        err.write(f"statectl node: {said}\n")
        return USAGE
    try:
        cell, devices = run_setup.load_cell_setups(path, err, journal is not None, node)
    except DiagnosticError as exc:
        for d in exc.diagnostics:
            err.write(f"{d}\n")
        return PROBLEMS
    if cell.nodes is None:
        err.write(f"statectl node: {path}: the cell has no nodes: section (docs/distributed.md)\n")
        return PROBLEMS
    names = [n.name for n in cell.nodes.nodes]
    if node not in names:
        err.write(
            f"statectl node: the cell has no node {node!r}; {did_you_mean(node, names)}"
            f"nodes: {', '.join(names)}\n"
        )
        return USAGE
    mine = cell.nodes.node(node).devices
    devices = tuple(d for d in devices if d.name in mine)
    return promise, cell, devices, mine


def _node_system(
    cell: Any,
    devices: tuple[Any, ...],
    path: str,
    driver: str | None,
    config: str | None,
    journal: str | None,
    resume: bool,
    fresh: bool,
    promise: Any,
    out: TextIO,
) -> tuple[Any, Any, Any, str | None]:
    """The node's System over its own devices, their drivers and journal; the run config
    it read and the journal's path (the output rule may complete it). A journal this
    start made is removed again if the System cannot start."""
    from statectl.channels.cli import run_setup
    from statectl.channels.cli.outputs import output
    from statectl.channels.cli.run_journal import (
        JOURNAL_NAME,
        new_journal,
        open_journal,
        undone_on_failure,
    )
    from statectl.channels.distributed import NodeSystem
    from statectl.channels.runconfig import run_config
    from statectl.run.journal import Sync
    from statectl.run.runtime import WallClock

    table = run_config(config)
    drivers = run_setup.drivers_for(devices, driver, config, table)
    setups = tuple(replace(d, driver=drivers.get(d.name)) for d in devices)
    store = None
    if journal is not None:
        with output(
            journal, JOURNAL_NAME, existing=False
        ) as target:  # cli/outputs.py: the output rule
            journal = str(target)
            read = (path, config, *(d.source for d in devices))
            made = new_journal(journal, resume=resume, fresh=fresh)
            store = open_journal(
                journal,
                Sync.NORMAL,
                promise,
                resume=resume,
                fresh=fresh,
                out=out,
                inputs=read,
            )
    with undone_on_failure(store, journal if store is not None and made else None):
        system = NodeSystem(setups, WallClock(), store, cell, commands=table.commands)
    return system, table, drivers, journal


def _listen(
    system: Any,
    wire: Any,
    problems: Problems,
    drivers: Any,
    quiet: bool,
    out: TextIO,
    err: TextIO,
) -> None:
    """Trace each step (unless quiet) and count what the verdict counts: problem steps,
    violations, failures and refused posts."""
    from statectl.channels.cli import run_setup
    from statectl.run.runtime import TraceWriter

    if system.subjects:
        width = max(len(n) for n in system.subjects)
        if not quiet:
            system.listen_steps(TraceWriter(out, device_width=width).step)
            run_setup.show_notes(drivers, out, width)
    system.listen_steps(problems.step)
    width = max((len(n) for n in system.subjects), default=4)
    system.on_violation.append(problems.violation(out, width))  # rule 5
    system.on_failure.append(problems.failure(err))
    wire.on_refused.append(lambda exc: problems.refuse())


def _announce(cell: Any, node: str, mine: Any, wire: Any, out: TextIO) -> None:
    """Say what this node holds and where it talks, before it connects."""
    from statectl.channels.distributed.trust import security_line

    me = cell.nodes.node(node)
    out.write(
        f"node {node}: devices {', '.join(mine) or 'none'}; listen "
        f"{', '.join(me.listen) or 'none'}; connect {', '.join(me.connect) or 'none'}; "
        f"lease {me.lease:g} s; key expressions under {wire.keys.root}/\n"
        f"node {node}: {security_line(cell)}\n"
    )


def _node_dashboard(
    cell: Any,
    system: Any,
    wire: Any,
    host: str | None,
    port: int | None,
    token: str | None,
    config: str | None,
    table: Any,
) -> tuple[Any, str, str]:
    """Serve the cell's dashboard over this node's view: the server, its URL, and the
    token to show (where it came from, when the user gave it)."""
    from statectl.channels.cli import run_setup
    from statectl.channels.distributed.dashboard import serve_cell

    host, port, token, where = run_setup.dashboard_settings(
        host, port, token, config, table.dashboard
    )
    server, url = serve_cell(
        cell,
        system.subjects,
        wire.on_state,
        system.post,
        (host, port, token),
        table.dashboard.streams,
    )
    shown = server.token if token is None else f"(from {where})"
    return server, url, shown


def _serve(
    system: Any,
    halt: threading.Event,
    events: TextIO | None,
    problems: Problems,
    out: TextIO,
    err: TextIO,
) -> None:
    """Run until ``halt`` (SIGTERM sets it) or Ctrl-C, events fed from ``events`` or stdin
    on their own thread; then say each device's final states."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, lambda *_: halt.set())
    lines = events if events is not None else sys.stdin
    feeder = threading.Thread(
        target=_feed, args=(system, lines, err, problems), daemon=True, name="statectl-feed"
    )
    feeder.start()
    with contextlib.suppress(KeyboardInterrupt):
        system.serve(halt)
    for name, subject in system.subjects.items():
        out.write(f"final {name}: {', '.join(sorted(subject.configuration))}\n")


def _bad_usage(command: str, port: int | None, connect: Sequence[str], err: TextIO) -> bool:
    """--port out of range, or a --connect that is no Zenoh endpoint: said as run says it."""
    from statectl.cell.nodes import endpoint_problem
    from statectl.channels.cli.run_options import MAX_PORT

    if port is not None and not 0 <= port <= MAX_PORT:
        err.write(
            f"statectl {command}: --port must be 0 (any free port) to {MAX_PORT} (got {port})\n"
        )
        return True
    for endpoint in connect:
        problem = endpoint_problem(endpoint, connect=True)
        if problem is not None:
            err.write(
                f"statectl {command}: --connect {endpoint!r} {problem}; "
                "write PROTOCOL/HOST:PORT, e.g. tcp/127.0.0.1:7447\n"
            )
            return True
    return False


def _plain_off_loopback(cell: Any, connect: Sequence[str], err: TextIO) -> bool:
    """V827's rule for a station's --connect: off loopback only over TLS or when insecure."""
    from statectl.cell.security import TLS_PROTOCOLS, is_loopback

    sec = cell.nodes.security if cell.nodes is not None else None
    for endpoint in connect:
        tls = endpoint.partition("/")[0] in TLS_PROTOCOLS
        if not tls and not is_loopback(endpoint) and not (sec is not None and sec.insecure):
            err.write(
                f"statectl dashboard: --connect {endpoint!r} is off loopback without TLS; "
                "give the cell security: {tls: ...} and a tls/ endpoint, or security: "
                "{insecure: true}\n"
            )
            return True
    return False


def _not_a_cell(path: str, err: TextIO) -> bool:
    """C416 (as verify says it) when ``path`` is a device file or SCXML, not a cell file."""
    from statectl.front.kinds import device_given_to_verify

    other = device_given_to_verify(path)
    if other is not None:
        err.write(f"{other}\n")
    return other is not None


def _feed(system: Any, lines: TextIO, err: TextIO, problems: Any) -> None:
    from statectl.channels.cli.run import _feed as feed

    with contextlib.suppress(Exception):
        feed(system, lines, err, batch=False, problems=problems)
