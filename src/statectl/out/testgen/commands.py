"""The ``statectl testgen`` and ``statectl coverage`` commands, registered on the CLI's parser.

:func:`register` is the CLI's one hook into this package: it adds both
subcommands to the ``statectl`` parser. Each command is thin: parse, call one
function, print, exit code (0 ok, 1 bad input or a check failed, 2 usage).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, TextIO

from statectl.kernel.exits import OK, PROBLEMS, USAGE

__all__ = ["cmd_coverage", "cmd_testgen", "register"]

CRITERIA = ("rows", "transitions", "states", "pairs")  # testgen.cases.CRITERIA, kept light


def cmd_testgen(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.out.testgen.generator import (
        export_graphwalker,
        export_xstate,
        generate,
        generate_hypothesis,
    )

    if Path(args.out).exists() and not Path(args.out).is_dir():  # as statectl new says it
        err.write(f"statectl testgen: --out {args.out}: not a directory; nothing was written\n")
        return USAGE
    if _is_cell(args.file):
        return _cell_testgen(args, out, err)
    if args.xstate:
        out.write(f"wrote {export_xstate(args.file, args.out)}\n")
        return OK
    if args.graphwalker:
        out.write(f"wrote {export_graphwalker(args.file, args.out)}\n")
        return OK
    if args.hypothesis:
        out.write(f"wrote {generate_hypothesis(args.file, args.out)}\n")
        return OK
    from statectl.cell.explore.progress import CountProgress

    show = err.isatty() if not args.progress else True  # as verify --progress
    printer = CountProgress("testgen", "nodes explored", err) if show else None
    made = generate(args.file, args.criterion, args.out, progress=printer)
    if printer is not None:
        printer.done()
    out.write(
        f"wrote {made.path}: {made.tests} tests ({len(made.suite.cases)} cases, "
        f"{len(made.suite.tables)} unhandled-event tables), {made.steps} events sent"
        + (f"; {made.probes} more through the implementation\n" if made.probes else "\n")
    )
    for note in made.suite.notes:
        out.write(f"note: {note}\n")
    return OK


def _is_cell(path: str) -> bool:
    """A YAML file with a ``devices`` section and no ``states`` table is a cell file."""
    from statectl.front.tables import safeyaml
    from statectl.front.tables.inputs import read_input_text

    if Path(path).suffix.lower() not in (".yaml", ".yml"):
        return False
    try:
        data = safeyaml.load_value(read_input_text(path))
    except (OSError, UnicodeDecodeError, safeyaml.YamlRefused):
        return False  # loaded as a device file, whose loader says what is wrong
    return isinstance(data, dict) and "devices" in data and "states" not in data


def _cell_testgen(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.out.testgen.cellgen import generate_cell, generate_cell_hypothesis

    if args.xstate or args.graphwalker:
        err.write(
            f"statectl testgen: {args.file} is a cell; --xstate and --graphwalker export one "
            "device: give one of its device files\n"
        )
        return USAGE
    if args.hypothesis:
        out.write(f"wrote {generate_cell_hypothesis(args.file, args.out)}\n")
        return OK
    made = generate_cell(args.file, args.criterion, args.out)
    for d in made.devices:
        more = f"; {d.probes} more through the implementation" if d.probes else ""
        out.write(f"wrote {d.path}: {d.tests} tests, {d.steps} events sent{more}\n")
    out.write(f"wrote {made.links}: {len(made.cases)} link tests\n")
    for note in made.notes:
        out.write(f"note: {note}\n")
    return OK


def cmd_coverage(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.front.builder.build import load_chart
    from statectl.out.testgen.coverage import (
        coverage_table,
        journal_coverage,
        load_tally,
        mermaid,
        svg,
    )

    if not Path(args.journal).exists():
        err.write(f"statectl coverage: {args.journal}: no such file\n")
        return USAGE
    chart = load_chart(args.file)
    if args.journal.endswith(".json"):  # written by pytest --statectl-coverage
        report = load_tally(args.journal, chart)
    else:
        report = journal_coverage(args.journal, chart, args.device)
    if args.format == "svg":
        text = svg(report)  # a missing Graphviz is a StatectlError: the CLI prints the hint
    elif args.format == "mermaid":
        text = mermaid(report)
    else:
        text = coverage_table(report, args.journal)
    out.write(text)
    return PROBLEMS if report.mismatches else OK


def register(sub: Any) -> None:
    """Add ``testgen`` and ``coverage`` to the CLI's subparsers (``sub``)."""
    s = sub.add_parser(
        "testgen",
        help="write a pytest module that tests a device against its tables",
        description="Explores the chart from its default state and writes one test per "
        "row (or transition, state, pair of transitions), plus each state's unhandled "
        "events, into DIR. The tests run on the simulated twin unless a conftest.py "
        "overrides the statectl_driver fixture (docs/testing.md).",
    )
    s.add_argument(
        "file",
        metavar="FILE_OR_CELL",
        help="device file, or cell file (each device's module plus the links' module)",
    )
    s.add_argument("--criterion", default="rows", choices=CRITERIA)
    s.add_argument("--progress", action="store_true", help="show progress even when piped")
    s.add_argument("--out", required=True, metavar="DIR", help="directory to write into")
    what = s.add_mutually_exclusive_group()
    what.add_argument(
        "--hypothesis",
        action="store_true",
        help="write a Hypothesis state machine over the chart's events instead",
    )
    what.add_argument(
        "--graphwalker",
        action="store_true",
        help="write the state graph as a GraphWalker JSON model instead",
    )
    what.add_argument(
        "--xstate",
        action="store_true",
        help="write the chart as an XState machine config (for @xstate/graph) instead",
    )
    s.set_defaults(func=cmd_testgen)

    s = sub.add_parser(
        "coverage",
        help="which rows, states and transitions a journalled run or a test run exercised",
    )
    s.add_argument(
        "journal",
        metavar="JOURNAL",
        help="the run's SQLite journal, or the .json a pytest run wrote with --statectl-coverage",
    )
    s.add_argument("file", metavar="FILE", help="the device file the run used")
    s.add_argument("--device", help="only this journalled device (default: all of FILE's chart)")
    s.add_argument("--format", default="table", choices=("table", "mermaid", "svg"))
    s.set_defaults(func=cmd_coverage)
