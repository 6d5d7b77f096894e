"""The ``statectl`` command: parse, call one function, print, exit code.

Exit codes: 0 success, 1 problems found (diagnostics, a failed run), 2 usage error.
Every command takes ``argv`` so tests call :func:`main` in-process. Imports of the
pipeline happen inside each command so ``statectl --help`` stays fast.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from statectl.errors import Diagnostic, DiagnosticError, Severity, StatectlError, has_errors

if TYPE_CHECKING:  # the pipeline is imported inside each command, to keep --help fast
    from statectl.model import Chart

__all__ = ["main"]

OK, PROBLEMS, USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse that exits with 2 and a one-line hint instead of printing usage twice."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.print_usage(sys.stderr)
        self.exit(USAGE, f"{self.prog}: error: {message}\n")


def _print_diagnostics(diags: Sequence[Diagnostic], out: TextIO, as_json: bool) -> None:
    if as_json:
        json.dump([d.to_json() for d in diags], out, indent=2)
        out.write("\n")
        return
    for d in diags:
        out.write(f"{d}\n")


def _summary(diags: Sequence[Diagnostic]) -> str:
    n_err = sum(d.severity is Severity.ERROR for d in diags)
    n_warn = sum(d.severity is Severity.WARNING for d in diags)
    return f"{n_err} error(s), {n_warn} warning(s)"


def _load_chart(path: str, err: TextIO) -> Chart | None:
    """Load and build a device file; print every diagnostic on failure."""
    from statectl.build import load_and_build

    chart, diags = load_and_build(path)
    if chart is None or has_errors(diags):
        _print_diagnostics([d for d in diags if d.severity is not Severity.INFO], err, False)
        err.write(f"{path}: not loaded: {_summary(diags)}\n")
        return None
    return chart


# -- commands -------------------------------------------------------------------------------


def cmd_check(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.rules import check_paths

    for p in args.files:
        if not Path(p).exists():
            err.write(f"statectl check: {p}: no such file\n")
            return USAGE
    diags = check_paths(args.files)
    shown = [d for d in diags if args.verbose or d.severity is not Severity.INFO]
    _print_diagnostics(shown, out, args.json)
    failed = has_errors(diags) or (
        args.strict and any(d.severity is Severity.WARNING for d in diags)
    )
    if not args.json:
        verdict = "problems found" if failed else "ok"
        out.write(f"{len(args.files)} file(s) checked: {_summary(diags)}: {verdict}\n")
    return PROBLEMS if failed else OK


def cmd_build(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.build import load_and_build

    chart, diags = load_and_build(args.file)
    _print_diagnostics(diags, err if chart is None else out, False)
    if chart is None or has_errors(diags):
        err.write(f"{args.file}: not built: {_summary(diags)}\n")
        return PROBLEMS
    out.write(
        f"chart {chart.name}: {len(chart.states)} states, "
        f"{len(chart.transitions)} transitions, initial {', '.join(chart.initial)}\n"
    )
    for t in chart.transitions:
        out.write(f"  {t.source} + {t.label} = {' '.join(t.targets) or '(targetless)'}\n")
    return OK


def cmd_observers(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.observers import extract

    chart = _load_chart(args.file, err)
    if chart is None:
        return PROBLEMS
    model = extract(chart)
    if args.json:
        json.dump(model.to_json(), out, indent=2)
        out.write("\n")
        return OK
    out.write(f"Subject: {model.subject} (notifies the observer registered for an invoke number)\n")
    out.write("Invoke enumeration:\n")
    for i in model.invokes:
        out.write(f"  {i.name} = {i.number}\n")
    out.write("Observers (device + API):\n")
    for api in model.apis:
        inv = model.invoke_for_method(api.method)
        out.write(
            f"  {api.method}()  <- invoke {inv.name} ({inv.number}); "
            f"events: {', '.join(api.events)}\n"
        )
    out.write("Notifications (events whose transition calls the device):\n")
    for event, number in model.notifying:
        out.write(f"  {event} -> invoke {number}\n")
    out.write("Monitors (run while the state is active):\n")
    if not model.monitors:
        out.write("  none\n")
    for m in model.monitors:
        out.write(f"  {m.state}: raises {', '.join(m.raises) or '(nothing)'}\n")
    return OK


def cmd_render(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.render import render

    chart = _load_chart(args.file, err)
    if chart is None:
        return PROBLEMS
    text = render(chart, args.format)
    _emit(text, args.out, out)
    return OK


def cmd_tables(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.tables import dump, load, save

    tables, diags = load(args.file)
    if tables is None or has_errors(diags):
        _print_diagnostics([d for d in diags if d.severity is not Severity.INFO], err, False)
        err.write(f"{args.file}: not converted: {_summary(diags)}; nothing written\n")
        return PROBLEMS
    if args.out is None:
        if args.to in ("csv", "xlsx"):
            err.write(f"statectl tables: --to {args.to} writes files: give --out PATH\n")
            return USAGE
        text = dump(tables, args.to)
        assert isinstance(text, str)
        out.write(text)
        return OK
    written = save(tables, args.out, args.to)
    for p in written or [args.out]:
        out.write(f"wrote {p}\n")
    return OK


def cmd_demo(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.demo import run_demo

    run_demo(out, driver=args.driver, config=args.config)
    return OK


#: Seconds past ``--timeout`` after which ``scxml run`` exits even if the run is stuck
#: in one long operation the cooperative deadline cannot interrupt (trusted python code).
SCXML_WATCHDOG_GRACE = 2.0


def cmd_scxml_run(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    import os
    import threading

    from statectl.scxml import SessionTimeout, run_file

    if not 0 < args.timeout <= 1e6:  # also refuses nan and inf
        err.write("statectl scxml run: --timeout must be a number of seconds in (0, 1e6]\n")
        return USAGE

    def watchdog() -> None:
        err.write(
            f"statectl scxml run: stopped: still running {SCXML_WATCHDOG_GRACE:g} s after "
            f"--timeout {args.timeout:g} s\n"
        )
        err.flush()
        os._exit(PROBLEMS)  # last resort: the run is stuck where no deadline check reaches

    timer = threading.Timer(args.timeout + SCXML_WATCHDOG_GRACE, watchdog)
    timer.daemon = True
    timer.start()
    try:
        final = run_file(
            str(Path(args.file).resolve()),
            args.timeout,
            verbose=args.verbose,
            allow_src=args.allow_src,
        )
    except SessionTimeout:
        err.write(f"statectl scxml run: stopped: --timeout {args.timeout:g} s passed\n")
        return PROBLEMS
    finally:
        timer.cancel()
    if final is None:
        err.write(f"statectl scxml run: no top-level final state within {args.timeout} s\n")
        return PROBLEMS
    out.write(f"final: {final}\n")
    out.flush()
    return OK


def cmd_codegen(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.codegen import run_codegen

    return run_codegen(args.file, args.out, args.target, out, err)


def cmd_verify(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.explore.verify import verify_main

    return verify_main(
        args.cell,
        as_json=args.json,
        max_states=args.max_states,
        export=args.export,
        output=args.output,
        traces=args.traces,
        diagrams=args.diagrams,
        progress=True if args.progress else None,
        out=out,
        err=err,
    )


def cmd_run(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.runner import is_cell, run

    if args.replay is not None or args.walk is not None:
        if not is_cell(args.file):
            err.write("statectl run: --replay and --walk take a cell file\n")
            return USAGE
        from statectl.explore.replay import run_main

        return run_main(
            args.file, replay=args.replay, walk=args.walk or 0, seed=args.seed, out=out, err=err
        )
    return run(
        args.file,
        driver=args.driver,
        config=args.config,
        dashboard=args.dashboard,
        host=args.host,
        port=args.port,
        token=args.token,
        journal=args.journal,
        resume=args.resume,
        fresh=args.fresh,
        sync=args.sync,
        guarantee=args.guarantee,
        realtime=args.realtime,
        out=out,
        err=err,
    )


def cmd_journal(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.runner import journal_export, journal_replay, journal_show

    if args.journal_command == "replay":
        return journal_replay(args.db, device=args.device, out=out, err=err)
    if args.journal_command == "export":
        return journal_export(
            args.db, device=args.device, since=args.since, until=args.until, to=args.out,
            out=out, err=err,
        )  # fmt: skip
    return journal_show(
        args.db, device=args.device, since=args.since, until=args.until, out=out, err=err
    )


def cmd_scxml_import(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.scxml_io import import_file

    result, diags = import_file(args.file, args.out)
    if isinstance(result, str):
        _print_diagnostics(diags, err, False)
        err.write(f"{args.file}: kept as SCXML (it does not fit the table form); nothing written\n")
        return OK
    for p in result:
        out.write(f"wrote {p}\n")
    return OK


def cmd_scxml_export(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.scxml_io import export_file

    text = export_file(args.file)
    _emit(text, args.out, out)
    return OK


def _emit(text: str, path: str | None, out: TextIO) -> None:
    """Write a command's text to ``path`` atomically, or to standard output."""
    if path:
        _write_atomic(Path(path), text)
        out.write(f"wrote {path}\n")
    else:
        out.write(text if text.endswith("\n") else text + "\n")


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


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

    s = sub.add_parser("demo", help="run the paper's Motor case study on a simulated motor")
    s.add_argument(
        "--driver",
        default="sim-motor",
        help="driver for the Motor (sim-motor, sim-stepper, or package.module:Class)",
    )
    s.add_argument("--config", help="driver configuration YAML (overrides --driver)")
    s.set_defaults(func=cmd_demo)

    s = sub.add_parser("check", help="report every problem in device files")
    s.add_argument("files", nargs="+", metavar="FILE")
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
    s.add_argument("--out", help="output path (a directory or NAME for the CSV pair)")
    s.set_defaults(func=cmd_tables)

    s = sub.add_parser("codegen", help="generate C++17 for a device (no heap, flat tables)")
    s.add_argument("file", metavar="FILE")
    s.add_argument("--target", default="cpp", help="code generation target (cpp)")
    s.add_argument("--out", required=True, help="output directory")
    s.set_defaults(func=cmd_codegen)

    s = sub.add_parser("verify", help="explore every reachable global state of a cell")
    s.add_argument("cell", metavar="CELL")
    s.add_argument("--json", action="store_true", help="one JSON report on standard output")
    s.add_argument("--max-states", type=int, help="bound the search; the report says incomplete")
    s.add_argument("--export", choices=("promela",), help="write the composed model instead")
    s.add_argument("-o", "--output", help="where --export writes (default: standard output)")
    s.add_argument("--traces", metavar="DIR", help="write each counterexample (json, mmd, puml)")
    s.add_argument(
        "--diagrams",
        choices=("mermaid", "plantuml"),
        help="print each counterexample as a sequence diagram",
    )
    s.add_argument("--progress", action="store_true", help="show progress even when piped")
    s.set_defaults(func=cmd_verify)

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
        "sim-stepper or package.module:Class",
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
    s.add_argument("--replay", metavar="TRACE", help="cells: a .trace.json from verify --traces")
    s.add_argument("--walk", type=int, metavar="N", help="cells: a seeded random walk of N steps")
    s.add_argument("--seed", type=int, default=0, help="cells: random-walk seed")
    s.set_defaults(func=cmd_run)

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

    from statectl.testgen.commands import register as register_testgen

    register_testgen(sub)  # testgen, coverage (src/statectl/testgen/commands.py)
    return p


def _command(args: argparse.Namespace) -> str:
    name = getattr(args, "func", None)
    return name.__name__.removeprefix("cmd_").replace("_", " ") if name is not None else ""


def _missing_input(args: argparse.Namespace) -> str | None:
    """The first input file named on the command line that does not exist (exit 2)."""
    paths: list[str] = []
    for attr in ("file", "files", "cell"):
        value = getattr(args, attr, None)
        if isinstance(value, str):
            paths.append(value)
        elif isinstance(value, list):
            paths.extend(v for v in value if isinstance(v, str))
    return next((p for p in paths if not _exists(Path(p))), None)


def _exists(path: Path) -> bool:
    """The file exists, or ``NAME.csv`` names a CSV pair whose states file exists."""
    if path.exists():
        return True
    if path.suffix.lower() != ".csv":
        return False
    from statectl.tables.csv_io import csv_paths

    pair = csv_paths(path)
    return pair is not None and pair.states.exists()


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
    try:
        code: int = args.func(args, out, err)
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
        return 130
    except BrokenPipeError as exc:
        if not _reader_gone(out):  # another pipe (a driver's): an error like any other
            err.write(f"statectl: {exc}\n")
            return PROBLEMS
        return _broken_pipe(out)
    return code


#: The exit status of a command whose reader went away (``statectl journal show DB | head``),
#: as if SIGPIPE had ended it: 128 + 13, what a shell reports for such a tool.
BROKEN_PIPE = 141


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
