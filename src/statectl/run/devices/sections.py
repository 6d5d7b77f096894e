"""The ``dashboard:`` and ``ship:`` sections of a run config (rules 5 and 7 of
:mod:`statectl.run.devices.config`), apart as the ``opcua:`` section is: each reads
one mapping and reports its own codes (D510, D530).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import yaml

from statectl.run.devices.urls import url_problem

__all__ = [
    "DASHBOARD_KEYS",
    "MAX_STREAMS",
    "MIN_TOKEN",
    "SHIP_KEYS",
    "DashboardConfig",
    "ShipConfig",
    "parse_dashboard",
    "parse_ship",
]

#: The keys of the dashboard section (the JSON Schema, out/schema.py, reads them).
DASHBOARD_KEYS = ("host", "port", "token", "streams")
#: The most event streams a config file may allow (each holds a socket and a buffer).
MAX_STREAMS = 100_000

#: The shortest dashboard token a config file may set: a short one can be guessed.
MIN_TOKEN = 16


@dataclass(frozen=True, slots=True)
class DashboardConfig:
    """The ``dashboard:`` section: each field None where the file says nothing."""

    host: str | None = None
    port: int | None = None
    token: str | None = None
    streams: int | None = None


@dataclass(frozen=True, slots=True)
class ShipConfig:
    """The ``ship:`` section (rule 6): where the journal goes, and how often."""

    to: str
    source: str | None = None
    interval: float = 0.5
    retry: float = 5.0
    batch: int = 5000


def parse_dashboard(
    node: yaml.Node,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: Callable[[str, int | None, str, str], None],
) -> DashboardConfig:
    """The ``dashboard:`` section (rule 5); every problem is a D510 error."""
    if not isinstance(node, yaml.MappingNode):
        error("D510", line_of(node), "'dashboard' must be a mapping",
              "write 'dashboard: {port: 8765, token: ...}'")  # fmt: skip
        return DashboardConfig()
    fields: dict[str, Any] = {}
    for k, v in node.value:
        name, val, line = value(k), value(v), line_of(v)
        if name not in DASHBOARD_KEYS:
            error("D510", line_of(k), f"dashboard: unknown key {name!r}",
                  f"the dashboard has {', '.join(DASHBOARD_KEYS)}")  # fmt: skip
        elif name == "host" and not (isinstance(val, str) and val):
            error("D510", line, f"dashboard: host must be an address (got {val!r})",
                  "write 'host: 127.0.0.1' (the default, loopback only)")  # fmt: skip
        elif name == "port" and not (
            isinstance(val, int) and not isinstance(val, bool) and 0 <= val <= 65535
        ):
            error("D510", line, f"dashboard: port must be a number 0-65535 (got {val!r})",
                  "0 takes any free port")  # fmt: skip
        elif name == "streams" and not (
            isinstance(val, int) and not isinstance(val, bool) and 1 <= val <= MAX_STREAMS
        ):
            error("D510", line,
                  f"dashboard: streams must be a number 1-{MAX_STREAMS} (got {val!r})",
                  "the most pages that may follow the run at once; 1000 by default")  # fmt: skip
        elif name == "token" and not (isinstance(val, str) and len(val) >= MIN_TOKEN):
            shown = "a shorter text" if isinstance(val, str) else repr(val)  # never echo a secret
            error(
                "D510",
                line,
                f"dashboard: token must be text of {MIN_TOKEN} characters or more (got {shown})",
                "make one: python -c 'import secrets; print(secrets.token_urlsafe(18))'",
            )
        else:
            fields[name] = val
    return DashboardConfig(**fields)


SHIP_KEYS = ("to", "source", "interval", "retry", "batch")


def parse_ship(
    node: yaml.Node,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: Callable[[str, int | None, str, str], None],
) -> ShipConfig | None:
    """The ``ship:`` section (rule 7); every problem is a D530 error."""
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
