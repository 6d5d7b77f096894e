"""The run config's ``ship:`` section: the run's journal shipped to PostgreSQL as it is committed
(docs/journal.md, "Shipping to PostgreSQL"; the shipper is :mod:`statectl.run.journal.ship`).

Rules:
1. The section is a mapping::

       ship: {to: postgresql://statectl@db.plant/cell, source: cell-a, interval: 0.5}

   ``to`` is required; ``source`` (default ``host:path``), ``interval`` (seconds
   between looks when nothing wakes the shipper), ``retry`` (seconds between
   attempts while the server is down) and ``batch`` (rows per transaction) are
   optional.
2. Every problem is a D530 error with its line; a password in ``to`` is never echoed.
3. Parsing only: no database driver is needed to read it. :mod:`statectl.channels.runconfig`
   reads the whole file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import yaml

from statectl.run.devices.urls import url_problem

__all__ = ["SHIP_KEYS", "ShipConfig", "parse_ship"]


@dataclass(frozen=True, slots=True)
class ShipConfig:
    """The ``ship:`` section (rule 1): where the journal goes, and how often."""

    to: str
    source: str | None = None
    interval: float = 0.5
    retry: float = 5.0
    batch: int = 5000


SHIP_KEYS = ("to", "source", "interval", "retry", "batch")


def parse_ship(
    node: yaml.Node,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: Callable[[str, int | None, str, str], None],
) -> ShipConfig | None:
    """The ``ship:`` section (rule 1); every problem is a D530 error (rule 2)."""
    example = "write 'ship: {to: postgresql://user@host/db}'"
    if not isinstance(node, yaml.MappingNode):
        error("D530", line_of(node), "'ship' must be a mapping", example)
        return None
    fields: dict[str, Any] = {}
    bad = False
    for k, v in node.value:
        name, val, line = value(k), value(v), line_of(v)
        number = isinstance(val, int | float) and not isinstance(val, bool)
        problem = ""
        if name not in SHIP_KEYS:
            error("D530", line_of(k), f"ship: unknown key {name!r}",
                  f"the ship section has {', '.join(SHIP_KEYS)}")  # fmt: skip
            bad = True
            continue
        if name == "to" and not (
            isinstance(val, str) and val.startswith(("postgresql://", "postgres://"))
        ):
            shown = "a text that is not one" if isinstance(val, str) else repr(val)
            problem = f"ship: to must be a postgresql:// URL (got {shown})"  # may hold a password
        elif name == "to" and (why := url_problem(val)) is not None:
            problem = f"ship: to is not a valid URL ({why})"  # the URL itself is not shown
        elif name == "source" and not (isinstance(val, str) and val):
            problem = f"ship: source must be a name (got {val!r})"
        elif name in ("interval", "retry") and not (number and 0.01 <= val <= 3600):
            problem = f"ship: {name} must be seconds from 0.01 to 3600 (got {val!r})"
        elif name == "batch" and not (number and isinstance(val, int) and 1 <= val <= 1_000_000):
            problem = f"ship: batch must be a number of rows 1-1000000 (got {val!r})"
        if problem:
            error("D530", line, problem, example)
            bad = True
        else:
            fields[name] = val
    if "to" not in fields:
        if not bad:
            error("D530", line_of(node), "ship: no 'to'", example)
        return None
    return None if bad else ShipConfig(**fields)
