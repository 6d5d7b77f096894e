"""``statectl journal ship DB --to postgresql://...``: copy a journal's committed rows.

One pass ships everything committed and exits; ``--follow`` keeps shipping
what a running node commits until Ctrl-C. The rows, marks and exactly-once
rule are journal/ship.py's; this module parses, reports and picks exit codes.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import threading
from pathlib import Path
from typing import Any, TextIO

from statectl.kernel.exits import OK, PROBLEMS, USAGE

__all__ = ["journal_ship", "register"]


def register(jsub: Any) -> None:
    """Add ``ship`` to the ``statectl journal`` subcommands."""
    s = jsub.add_parser("ship", help="copy committed journal rows into PostgreSQL, exactly once")
    s.add_argument("db", metavar="DB", help="the SQLite journal")
    s.add_argument("--to", required=True, metavar="URL", help="postgresql://user@host:port/db")
    s.add_argument("--source", help="this journal's name in the database (default: host:path)")
    s.add_argument("--batch", type=int, default=5000, help="rows per table per transaction")
    s.add_argument("--follow", action="store_true", help="keep shipping new rows until Ctrl-C")
    s.add_argument(
        "--interval", type=float, default=0.5, help="--follow: seconds between looks (0.5)"
    )
    s.set_defaults(func=_cmd)


def _cmd(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    return journal_ship(
        args.db, args.to, source=args.source, batch=args.batch, follow=args.follow,
        interval=args.interval, out=out, err=err,
    )  # fmt: skip


def journal_ship(
    path: str,
    url: str,
    *,
    source: str | None = None,
    batch: int = 5000,
    follow: bool = False,
    interval: float = 0.5,
    stop: threading.Event | None = None,
    out: TextIO = sys.stdout,
    err: TextIO = sys.stderr,
) -> int:
    """The whole command; 0 shipped, 1 could not (server, journal, refusal), 2 usage."""
    from statectl.run.journal.check import check_journal
    from statectl.run.journal.format import JournalError
    from statectl.run.journal.pg import is_pg_url
    from statectl.run.journal.ship import Shipper, ShipRefused

    if not is_pg_url(url):
        err.write(f"statectl journal ship: --to must be a postgresql:// URL (got {url!r})\n")
        return USAGE
    if batch < 1 or interval <= 0:
        err.write("statectl journal ship: --batch must be >= 1 and --interval > 0\n")
        return USAGE
    if not Path(path).is_file():
        err.write(f"statectl journal ship: no journal at {path}\n")
        return USAGE
    try:  # a file that is no journal, or a damaged one, is refused before anything is shipped
        check_journal(path, reader=False)
    except JournalError as exc:
        err.write(f"statectl journal ship: {exc}\n")
        return PROBLEMS
    shipper = Shipper(path, url, source=source, batch=batch)
    halt = stop or threading.Event()
    total_inbox = total_steps = 0
    try:
        while True:
            r = shipper.ship_all(halt.is_set)
            total_inbox += r.inbox
            total_steps += r.steps
            if not follow or halt.wait(interval):
                break
    except KeyboardInterrupt:
        pass
    except ShipRefused as exc:
        err.write(f"statectl journal ship: {exc}\n")
        return PROBLEMS
    except JournalError as exc:
        err.write(f"statectl journal ship: {exc}; nothing is lost: run it again to go on\n")
        return PROBLEMS
    finally:
        with contextlib.suppress(Exception):
            shipper.close()
    out.write(
        f"shipped {total_inbox} accepted event(s) and {total_steps} step(s) of {path} to "
        f"{shipper.where} as source {shipper.source!r}\n"
    )
    return OK
