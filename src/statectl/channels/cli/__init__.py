"""The ``statectl`` command: parse, call one function, print, exit code.

Exit codes (:mod:`statectl.kernel.exits`): 0 success, 1 problems found (diagnostics, a
failed run), 2 usage error.
Every command takes ``argv`` so tests call :func:`main` in-process. Imports of the
pipeline happen inside each command so ``statectl --help`` stays fast.

This module parses arguments and runs :func:`main` (missing files, errors that
reach the top, a reader that went away); the commands themselves are in
:mod:`statectl.channels.cli.commands`, whose names the parser looks up here.
"""

from __future__ import annotations

import argparse
import os
import select
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from statectl.channels.cli.commands import (
    _print_diagnostics,
    cmd_build,
    cmd_check,
    cmd_codegen,
    cmd_demo,
    cmd_journal,
    cmd_observers,
    cmd_render,
    cmd_run,
    cmd_scxml_export,
    cmd_scxml_import,
    cmd_scxml_run,
    cmd_tables,
    cmd_verify,
    input_exists,
)
from statectl.channels.cli.extras import check_extras
from statectl.kernel.errors import DiagnosticError, MissingExtra, StatectlError
from statectl.kernel.exits import BROKEN_PIPE, INTERRUPTED, PROBLEMS, USAGE

__all__ = ["main"]


class _Parser(argparse.ArgumentParser):
    """argparse that exits with 2 and a one-line hint instead of printing usage twice."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.print_usage(sys.stderr)
        self.exit(USAGE, f"{self.prog}: error: {message}\n")


# -- commands -------------------------------------------------------------------------------


# -- parser -------------------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="statectl",
        description="State control for industrial robot devices: device tables -> statechart "
        "-> observers -> runtime.",
    )
    from statectl import __version__

    p.add_argument("--version", action="version", version=f"statectl {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    _add_device_commands(sub)
    _add_verify(sub)
    _add_run(sub)
    _add_journal(sub)
    _add_scxml(sub)
    from statectl.out.testgen.commands import register as register_testgen

    register_testgen(sub)  # testgen, coverage (src/statectl/out/testgen/commands.py)
    from statectl.channels.cli.profiles import register as register_profiles

    register_profiles(sub)  # profiles, new (src/statectl/channels/cli/profiles.py)
    from statectl.channels.cli.node import register as register_node

    register_node(sub)  # node, dashboard (src/statectl/channels/cli/node.py; docs/distributed.md)
    from statectl.channels.cli.editors import register as register_editors

    register_editors(sub)  # schema, lsp (src/statectl/channels/cli/editors.py; docs/editors.md)
    return p


# build_parser's subcommands, one function per family so each reads as its --help does.


def _add_device_commands(sub: Any) -> None:
    """The commands over one device file: demo, check, build, observers, render, tables,
    codegen."""
    s = sub.add_parser("demo", help="run the paper's Motor case study on a simulated motor")
    s.add_argument(
        "--driver",
        default="sim-motor",
        help="driver for the Motor (sim-motor, sim-stepper, cia402-sim, or package.module:Class)",
    )
    s.add_argument("--config", help="driver configuration YAML (overrides --driver)")
    s.set_defaults(func=cmd_demo)

    s = sub.add_parser("check", help="report every problem in device files")
    s.add_argument("files", nargs="*", metavar="FILE")
    s.add_argument(
        "--explain",
        metavar="CODE",
        help="say what a diagnostic code means and where it is documented",
    )
    s.add_argument("--json", action="store_true", help="machine-readable diagnostics")
    s.add_argument("--strict", action="store_true", help="warnings fail the check too")
    s.add_argument("-v", "--verbose", action="store_true", help="also show info (merges)")
    s.set_defaults(func=cmd_check)

    s = sub.add_parser("build", help="build the statechart and show it with the merges made")
    s.add_argument("file", metavar="FILE")
    s.set_defaults(func=cmd_build)

    s = sub.add_parser("observers", help="print the Subject, observers and invoke numbers")
    s.add_argument("file", metavar="FILE")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_observers)

    s = sub.add_parser("render", help="draw the statechart")
    s.add_argument("file", metavar="FILE")
    s.add_argument(
        "--format", default="mermaid", choices=("mermaid", "dot", "plantuml", "svg", "md")
    )
    s.add_argument("--out", help="write to this file instead of standard output")
    s.set_defaults(func=cmd_render)

    s = sub.add_parser("tables", help="convert device tables between YAML, CSV, XLSX, Markdown")
    s.add_argument("file", metavar="FILE")
    s.add_argument("--to", required=True, choices=("yaml", "csv", "xlsx", "md"))
    s.add_argument("--out", help="output file or directory (the CSV pair: a directory or NAME)")
    s.set_defaults(func=cmd_tables)

    s = sub.add_parser("codegen", help="generate C++17 for a device (no heap, flat tables)")
    s.add_argument("file", metavar="FILE")
    s.add_argument("--target", default="cpp", help="code generation target (cpp)")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--progress", action="store_true", help="show progress even when piped")
    s.add_argument(
        "--harness",
        action="store_true",
        help="also write DEVICE_harness.cpp, the program testgen's suites drive "
        "(pytest --statectl-impl cpp:PROGRAM)",
    )
    s.set_defaults(func=cmd_codegen)


def _add_verify(sub: Any) -> None:
    """``verify``: a cell's global states, or its Promela export."""
    s = sub.add_parser("verify", help="explore every reachable global state of a cell")
    s.add_argument("cell", metavar="CELL")
    s.add_argument("--json", action="store_true", help="one JSON report on standard output")
    s.add_argument(
        "--max-states",
        type=int,
        help="bound the search (default 20,000,000; 0: none); the report then says incomplete",
    )
    s.add_argument(
        "--no-symmetry",
        action="store_true",
        help="store every global state, not one per orbit of interchangeable devices",
    )
    s.add_argument("--export", choices=("promela",), help="write the composed model instead")
    s.add_argument("-o", "--output", help="where --export writes (default: standard output)")
    s.add_argument("--traces", metavar="DIR", help="write each counterexample (json, mmd, puml)")
    s.add_argument(
        "--diagrams",
        choices=("mermaid", "plantuml"),
        help="print each counterexample as a sequence diagram",
    )
    s.add_argument("--progress", action="store_true", help="show progress even when piped")
    s.add_argument(
        "--no-por",
        action="store_true",
        help="no partial-order reduction: store every reachable global state",
    )
    s.set_defaults(func=cmd_verify)


def _add_run(sub: Any) -> None:
    """``run``: a device or cell live or batch, with its journal, dashboard and OPC UA."""
    s = sub.add_parser(
        "run",
        help="run a device or a cell on simulated twins or drivers (events from stdin)",
        description="Runs a device file or a cell file on its drivers (by default a simulated "
        "twin per device, derived from its tables). Event lines '[DEVICE:] EVENT [DATA]' or "
        "'+SECONDS' come from stdin, on a simulated clock unless --realtime or --dashboard. "
        "A cell can instead take a seeded random walk (--walk N) or replay a trace written by "
        "verify --traces (--replay).",
    )
    s.add_argument("file", metavar="FILE", help="device file or cell file")
    s.add_argument(
        "--driver",
        help="driver for every device: sim-twin (the default), sim-motor, "
        "sim-stepper, package.module:Class, or none (the model alone: only the events given)",
    )
    s.add_argument(
        "--json",
        action="store_true",
        help="one JSON object per event line (state after, handled or why not, invokes), "
        "instead of the trace",
    )
    s.add_argument("--config", help="run configuration YAML: drivers, dashboard settings")
    s.add_argument("--dashboard", action="store_true", help="serve the live dashboard")
    s.add_argument("--host", help="dashboard address (default: the config's, else loopback)")
    s.add_argument("--port", type=int, help="dashboard port (default: the config's, else any free)")
    s.add_argument(
        "--token",
        help="token that allows sending events from the dashboard "
        "(default: $STATECTL_DASHBOARD_TOKEN, the config's, else a new one printed)",
    )
    s.add_argument("--journal", metavar="DB", help="journal every event to this SQLite file")
    s.add_argument(
        "--resume",
        action="store_true",
        help="resume from the journal first; "
        "a journal that cannot be trusted is refused (see --fresh)",
    )
    s.add_argument(
        "--fresh",
        action="store_true",
        help="start a new journal, the old one set "
        "aside with a timestamp suffix; with --resume only if it cannot be trusted",
    )
    s.add_argument(
        "--sync",
        default="normal",
        choices=("normal", "full"),
        help="journal durability: normal (process crash) or full (power loss)",
    )
    s.add_argument(
        "--guarantee",
        default="prompt",
        choices=("prompt", "durable-first"),
        help="when a journalled event reaches its device: prompt = at once, "
        "acknowledged once durable; durable-first = only after its commit",
    )
    s.add_argument("--realtime", action="store_true", help="run on the wall clock")
    s.add_argument(
        "--settle-limit",
        type=float,
        metavar="SECONDS",
        help="batch runs: simulated seconds each event may take to settle (default 60); "
        "a run that stops settling there says so and exits 1",
    )
    s.add_argument(
        "--opcua",
        nargs="?",
        const="",
        metavar="URL",
        help="serve the devices over OPC UA (default opc.tcp://127.0.0.1:4840; docs/opcua.md)",
    )
    s.add_argument("--replay", metavar="TRACE", help="cells: a .trace.json from verify --traces")
    s.add_argument("--walk", type=int, metavar="N", help="cells: a seeded random walk of N steps")
    s.add_argument("--seed", type=int, default=0, help="cells: random-walk seed")
    s.set_defaults(func=cmd_run)


def _add_journal(sub: Any) -> None:
    """``journal``: show, export, replay and ship a run's journal."""
    journal = sub.add_parser("journal", help="read a run's journal")
    jsub = journal.add_subparsers(dest="journal_command", required=True, parser_class=_Parser)
    for name, text in (
        ("show", "print journalled events and state changes"),
        ("export", "write the journal as JSON Lines"),
        ("replay", "rerun the journal on the model; exit 1 if a state disagrees"),
    ):
        s = jsub.add_parser(name, help=text)
        s.add_argument("db", metavar="DB")
        s.add_argument("--device", help="only this device")
        if name != "replay":
            s.add_argument("--since", help="epoch seconds or ISO 8601")
            s.add_argument("--until", help="epoch seconds or ISO 8601")
        if name == "export":
            s.add_argument(
                "-o",
                "--out",
                metavar="FILE",
                help="write to FILE (whole or not at all) instead of standard output",
            )
        s.set_defaults(func=cmd_journal)
    from statectl.channels.cli.ship import register as register_ship

    register_ship(jsub)  # journal ship (src/statectl/channels/cli/ship.py)


def _add_scxml(sub: Any) -> None:
    """``scxml``: run, import and export SCXML documents."""
    scxml = sub.add_parser("scxml", help="SCXML documents")
    ssub = scxml.add_subparsers(dest="scxml_command", required=True, parser_class=_Parser)
    s = ssub.add_parser("run", help="run a document; print 'final: <id>' at a top-level final")
    s.add_argument("file", metavar="FILE")
    s.add_argument(
        "--timeout", type=float, default=10.0, help="stop after S wall-clock seconds (exit 1)"
    )
    s.add_argument(
        "--allow-src",
        action="store_true",
        help="let a safe/null document read <data src> files in its own directory",
    )
    s.add_argument("--verbose", action="store_true", help="print <log> and error events")
    s.set_defaults(func=cmd_scxml_run)
    s = ssub.add_parser("import", help="convert SCXML to a device file when it fits the tables")
    s.add_argument("file", metavar="FILE")
    s.add_argument("--out", help="device file to write (.yaml, .md, .xlsx, .csv)")
    s.set_defaults(func=cmd_scxml_import)
    s = ssub.add_parser("export", help="write a device file as SCXML")
    s.add_argument("file", metavar="FILE")
    s.add_argument("--out", help="write to this file instead of standard output")
    s.set_defaults(func=cmd_scxml_export)


def _command(args: argparse.Namespace) -> str:
    name = getattr(args, "func", None)
    return (
        name.__name__.lstrip("_").removeprefix("cmd_").replace("_", " ") if name is not None else ""
    )


def _paths(args: argparse.Namespace, attrs: Sequence[str]) -> list[str]:
    """The paths the parsed command line holds under ``attrs`` (one each, or a list)."""
    paths: list[str] = []
    for attr in attrs:
        value = getattr(args, attr, None)
        if isinstance(value, str):
            paths.append(value)
        elif isinstance(value, list):
            paths.extend(v for v in value if isinstance(v, str))
    return paths


def _missing_input(args: argparse.Namespace) -> str | None:
    """The first input file named on the command line that does not exist (exit 2)."""
    paths = _paths(args, ("file", "files", "cell", "config"))
    return next((p for p in paths if not input_exists(Path(p))), None)


def _overwritten_input(args: argparse.Namespace) -> str | None:
    """The output file (``--out``/``-o``) that is one of the input files, if any (exit 2).

    Writing there would replace the input with the command's output (a device file with
    its SCXML or its diagram, a commented file with its regenerated form): data lost
    without a word.
    """
    inputs = _paths(args, ("file", "files", "cell", "config", "journal", "replay", "db"))
    for target in _paths(args, ("out", "output")):
        if not os.path.isfile(target):
            continue
        for source in inputs:
            try:
                if os.path.isfile(source) and os.path.samefile(source, target):
                    return target
            except OSError:
                continue
    return None


def main(
    argv: Sequence[str] | None = None, out: TextIO | None = None, err: TextIO | None = None
) -> int:
    out = out or sys.stdout
    err = err or sys.stderr
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code) if isinstance(exc.code, int) else USAGE
    missing = _missing_input(args)
    if missing is not None:
        err.write(f"statectl {_command(args)}: {missing}: no such file\n")
        return USAGE
    overwritten = _overwritten_input(args)
    if overwritten is not None:
        err.write(
            f"statectl {_command(args)}: {overwritten} is an input of this command; writing "
            "the output there would replace it: name another file\n"
        )
        return USAGE
    try:
        check_extras(args)  # extras.py: a missing extra is said before anything starts
        code: int = args.func(args, out, err)
    except MissingExtra as exc:
        words = (args.command, *(getattr(args, f"{args.command}_command", None),))
        err.write(f"statectl {' '.join(w for w in words if w)}: {exc}\n")
        return USAGE
    except DiagnosticError as exc:
        _print_diagnostics(exc.diagnostics, err, False)
        return PROBLEMS
    except StatectlError as exc:
        err.write(f"statectl: {exc}\n")
        return PROBLEMS
    except (RecursionError, MemoryError) as exc:  # last resort: the loaders bound both first
        what = "too deeply nested" if isinstance(exc, RecursionError) else "too large"
        err.write(
            f"statectl {_command(args)}: the input is {what} to handle; "
            "see docs/limits.md for the limits\n"
        )
        return PROBLEMS
    except KeyboardInterrupt:
        err.write("statectl: interrupted\n")
        return INTERRUPTED
    except BrokenPipeError as exc:
        if not _reader_gone(out):  # another pipe (a driver's): an error like any other
            err.write(f"statectl: {exc}\n")
            return PROBLEMS
        return _broken_pipe(out)
    except OSError as exc:  # last resort: a file a command could not read or write
        where = f"{exc.filename}: " if exc.filename else ""
        err.write(f"statectl {_command(args)}: {where}{exc.strerror or exc}\n")
        return PROBLEMS
    return code


def _reader_gone(out: TextIO) -> bool:
    """Whether our output's reader went away: its pipe reports an error or a hang-up.

    Without a file descriptor (tests' StringIO) or ``poll`` (Windows), the error is taken at
    its word.
    """
    try:
        fd = out.fileno()
        poll = select.poll()
    except (AttributeError, OSError, ValueError):
        return True
    poll.register(fd, select.POLLOUT)
    return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poll.poll(0))


def _broken_pipe(out: TextIO) -> int:
    """The reader of our output went away: stop quietly, as a command ended by SIGPIPE does.

    Python ignores SIGPIPE, so a write raises BrokenPipeError instead; what is still
    buffered for the closed pipe is pointed at /dev/null, or flushing it at exit
    would fail again and print "Exception ignored". SIGPIPE is not restored to its
    default instead: it would also end a run serving the dashboard when a browser's
    socket closes.
    """
    try:
        fd = out.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (tests): nothing buffered
        return BROKEN_PIPE
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)
    return BROKEN_PIPE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
