"""``statectl profiles`` and ``statectl new``: the shipped standard profiles (docs/profiles.md).

:func:`register` is the CLI's one hook into this module. ``profiles`` lists what
ships; ``new NAME --profile P`` writes a device file to start from, atomically and
never over an existing file (exit 1 then, 2 for a usage error such as an unknown
profile or a name that is not a file name).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, TextIO

from statectl.channels.cli.outputs import output, wrote
from statectl.kernel.errors import did_you_mean
from statectl.kernel.exits import OK, PROBLEMS, USAGE

__all__ = ["cmd_new", "cmd_profiles", "register"]

FORMATS = ("yaml", "csv", "xlsx", "md")


def cmd_profiles(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.front.builder.build import build
    from statectl.front.profiles import PROFILES, profile_tables
    from statectl.kernel.model import StateKind

    rows: list[dict[str, Any]] = []
    for p in PROFILES:
        chart, _ = build(profile_tables(p))
        states = (
            sum(1 for s in chart.states if s.kind is StateKind.ATOMIC) if chart is not None else 0
        )
        rows.append(
            {"name": p.name, "standard": p.standard, "states": states, "summary": p.summary}
        )
    if args.json:
        out.write(json.dumps({"profiles": rows}, indent=2) + "\n")
        return OK
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        out.write(f"{r['name']:<{width}}  {r['states']:>2} states  {r['standard']}\n")
        out.write(f"{'':<{width}}  {r['summary']}\n")
    out.write("start from one: statectl new NAME --profile PROFILE [--format yaml|csv|xlsx|md]\n")
    return OK


def cmd_new(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    from statectl.front.profiles import PROFILES, find, new_device
    from statectl.front.tables import Format, write_files

    profile = find(args.profile)
    if profile is None:
        names = [p.name for p in PROFILES]
        maybe = did_you_mean(args.profile, names)
        err.write(
            f"statectl new: unknown profile {args.profile!r}; {maybe}shipped: {', '.join(names)}\n"
        )
        return USAGE
    name = args.name.strip()
    if not name or name != args.name or name.startswith(".") or any(c in name for c in "/\\\0"):
        err.write(
            f"statectl new: {args.name!r} is not a usable device name: it names the file too; "
            "use letters, digits, spaces, '-' and '_'\n"
        )
        return USAGE
    folder = Path(args.out)
    if folder.exists() and not folder.is_dir():
        err.write(f"statectl new: --out {args.out}: not a directory\n")
        return USAGE
    files = new_device(profile, name, Format(args.format))
    targets = {folder / file: content for file, content in files.items()}
    taken = [str(t) for t in targets if t.exists()]
    if taken:
        err.write(
            f"statectl new: {', '.join(taken)} already exists; nothing was written "
            "(choose another NAME or --out DIR, or remove the file)\n"
        )
        return PROBLEMS
    with output(args.out, directory=True):  # cli/outputs.py: the one output rule
        write_files(dict(targets))
    for target in targets:
        wrote(out, target)
    first = next(iter(targets))
    out.write(f"next: statectl check {first}\n")
    return OK


def register(sub: Any) -> None:
    """Add ``profiles`` and ``new`` to the CLI's subparsers (``sub``)."""
    s = sub.add_parser("profiles", help="list the standard device profiles statectl ships")
    s.add_argument("--json", action="store_true", help="one JSON document")
    s.set_defaults(func=cmd_profiles)

    s = sub.add_parser(
        "new",
        help="write a device file to start from, from a shipped profile",
        description="Writes NAME's device file in DIR from a shipped profile (statectl "
        "profiles lists them); never over an existing file.",
    )
    s.add_argument("name", metavar="NAME", help="the device's name (and the file's)")
    s.add_argument("--profile", required=True, metavar="PROFILE", help="a shipped profile")
    s.add_argument("--format", default="yaml", choices=FORMATS)
    s.add_argument("--out", default=".", metavar="DIR", help="directory to write into (.)")
    s.set_defaults(func=cmd_new)
