"""The ``statectl`` commands: each takes parsed arguments, prints, and returns an exit code.

Exit codes live here (0 success, 1 problems, 2 usage) with the printing of
diagnostics, so library modules return values or raise and the CLI alone
decides what a user sees. Argument parsing and :func:`statectl.channels.cli.main` are
in the package's ``__init__``."""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from statectl.channels.cli.outputs import output, wrote
from statectl.kernel.errors import Diagnostic, Severity, StatectlError, has_errors
from statectl.kernel.exits import OK, PROBLEMS, USAGE

if TYPE_CHECKING:  # the pipeline is imported inside each command, to keep --help fast
    from statectl.kernel.model import Chart


def input_exists(path: Path) -> bool:
    """The file exists, or ``NAME.csv`` names a CSV pair (imported on use: start-up stays cheap)."""
    from statectl.front.tables.csv_io import input_exists as exists

    return exists(path)


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
    from statectl.front.builder.build import load_and_build
    from statectl.front.kinds import cell_instead

    chart, diags = load_and_build(path)
    if chart is None or has_errors(diags):
        diags = cell_instead(path, diags)  # C415: a cell file given for a device file
        _print_diagnostics([d for d in diags if d.severity is not Severity.INFO], err, False)
        err.write(f"{path}: not loaded: {_summary(diags)}\n")
        return None
    return chart


def cmd_check(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.front.rules import check_paths

    if args.explain is not None:
        from statectl.kernel.codes import explain

        try:
            out.write(explain(args.explain))
        except StatectlError as exc:
            err.write(f"statectl check --explain: {exc}\n")
            return USAGE
        return OK if not args.files else cmd_check(_without_explain(args), out, err)
    if not args.files:
        err.write("statectl check: name at least one FILE (or --explain CODE)\n")
        return USAGE
    for p in args.files:
        if not input_exists(Path(p)):
            err.write(f"statectl check: {p}: no such file\n")
            return USAGE
    from statectl.front.kinds import cell_given_to_check

    found = {p: check_paths([p]) for p in args.files}
    cells = {  # C415; asked only of a file that does not load, so a device file is read once
        p: d for p, ds in found.items() if has_errors(ds) and (d := cell_given_to_check(p))
    }
    diags = [*cells.values(), *(d for p, ds in found.items() if p not in cells for d in ds)]
    shown = [d for d in diags if args.verbose or d.severity is not Severity.INFO]
    _print_diagnostics(shown, out, args.json)
    failed = has_errors(diags) or (
        args.strict and any(d.severity is Severity.WARNING for d in diags)
    )
    if not args.json:
        verdict = "problems found" if failed else "ok"
        out.write(f"{len(args.files)} file(s) checked: {_summary(diags)}: {verdict}\n")
    return PROBLEMS if failed else OK


def _without_explain(args: argparse.Namespace) -> argparse.Namespace:
    return argparse.Namespace(**{**vars(args), "explain": None})


def cmd_build(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.front.builder.build import load_and_build
    from statectl.front.kinds import cell_instead

    chart, diags = load_and_build(args.file)
    if chart is None:
        diags = cell_instead(args.file, diags)  # C415: a cell file given for a device file
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
    from statectl.front.observers import extract

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
    from statectl.out.render import render

    chart = _load_chart(args.file, err)
    if chart is None:
        return PROBLEMS
    text = render(chart, args.format)
    _emit(text, args.out, out, f"{_stem(chart.name)}.{RENDER_SUFFIX[args.format]}")
    return OK


#: The file name ``render --out DIR/`` writes, by format.
RENDER_SUFFIX = {"mermaid": "mmd", "dot": "dot", "plantuml": "puml", "svg": "svg", "md": "md"}


def _stem(device: str) -> str:
    """The file stem a device's outputs are named by (as ``tables`` and ``new`` name them)."""
    from statectl.front.tables.csv_io import file_stem

    return file_stem(device)


def cmd_tables(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.front.tables import dump, load, save

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
    name = None if args.to == "csv" else f"{_stem(tables.device)}.{args.to}"
    with output(args.out, name) as target:  # a directory: the device names the file(s)
        written = save(tables, target, args.to)
    for p in written or [target]:
        wrote(out, p)
    return OK


def cmd_demo(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.channels.cli.demo import run_demo

    run_demo(out, driver=args.driver, config=args.config)
    return OK


#: Seconds past ``--timeout`` after which ``scxml run`` exits even if the run is stuck
#: in one long operation the cooperative deadline cannot interrupt (trusted python code).
SCXML_WATCHDOG_GRACE = 2.0


def cmd_scxml_run(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    import threading

    from statectl.out.scxml import SessionTimeout, run_file

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
        err.write(f"statectl scxml run: no top-level final state within {args.timeout:g} s\n")
        return PROBLEMS
    out.write(f"final: {final}\n")
    out.flush()
    return OK


def cmd_codegen(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.channels.cli.codegen import run_codegen

    progress = True if args.progress else None
    return run_codegen(args.file, args.out, args.target, out, err, progress, harness=args.harness)


def cmd_verify(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.channels.cli.verify import verify_main

    return verify_main(
        args.cell,
        as_json=args.json,
        max_states=args.max_states,
        symmetry=not args.no_symmetry,
        export=args.export,
        output=args.output,
        traces=args.traces,
        diagrams=args.diagrams,
        progress=True if args.progress else None,
        por=not args.no_por,
        out=out,
        err=err,
    )


def cmd_run(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.channels.cli.run import run
    from statectl.run.runner import is_cell

    if args.replay is not None or args.walk is not None:
        if args.walk is not None and args.walk < 0:
            err.write(f"statectl run: --walk must be 0 or more steps (got {args.walk})\n")
            return USAGE
        if args.json or args.driver == "none":
            err.write(
                "statectl run: --json and --driver none step event lines, not --walk/--replay\n"
            )
            return USAGE
        if not is_cell(args.file):
            err.write("statectl run: --replay and --walk take a cell file\n")
            return USAGE
        if args.walk is not None and args.walk < 0:
            err.write(
                f"statectl run: --walk takes a number of steps, 0 or more (got {args.walk})\n"
            )
            return USAGE
        from statectl.channels.cli.replay import run_main

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
        opcua=args.opcua,
        settle_limit=args.settle_limit,
        out=out,
        err=err,
        as_json=args.json,
    )


def cmd_journal(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.channels.cli.journal import journal_export, journal_replay, journal_show

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
    from statectl.out.scxml.tables_io import import_file

    if args.out is None:
        result, diags = import_file(args.file)
    else:
        with output(args.out, f"{Path(args.file).stem}.yaml") as target:
            result, diags = import_file(args.file, target)
    if isinstance(result, str):
        _print_diagnostics(diags, err, False)
        err.write(f"{args.file}: kept as SCXML (it does not fit the table form); nothing written\n")
        return OK
    for p in result:
        wrote(out, p)
    return OK


def cmd_scxml_export(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.out.scxml.tables_io import export_file

    text = export_file(args.file)
    _emit(text, args.out, out, f"{Path(args.file).stem.split('.')[0]}.scxml")
    return OK


def _emit(text: str, path: str | None, out: TextIO, name: str) -> None:
    """Write a command's text to ``path`` atomically (``name`` in it if a directory), or
    to standard output.

    The one output rule (:mod:`statectl.channels.cli.outputs`); a file that cannot be
    written raises DiagnosticError (T110), which main() prints with exit 1; nothing is
    left half-written (:func:`statectl.front.tables.write_files`).
    """
    if path:
        from statectl.front.tables import write_files

        with output(path, name) as target:
            write_files({target: text})
        wrote(out, target)
    else:
        out.write(text if text.endswith("\n") else text + "\n")
