"""The run config's ``dashboard:`` section: where the live dashboard listens, its token and
how many pages may follow a run.

Rules:
1. The section is a mapping::

       dashboard: {host: 127.0.0.1, port: 8765, token: <16 or more characters>, streams: 1000}

   so a token need not be typed on a command line (where ``ps`` shows it). The flags,
   then ``$STATECTL_DASHBOARD_TOKEN``, then this section, then the defaults, decide
   (:func:`statectl.channels.cli.run_setup.dashboard_settings`).
2. Every problem is a D510 error with its line; a token is never shown in a message.
3. Parsing only: the server (:mod:`statectl.channels.web.server`) reads the values; this
   module needs neither aiohttp nor the network. :mod:`statectl.channels.runconfig`
   reads the whole file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import yaml

__all__ = ["DASHBOARD_KEYS", "MAX_STREAMS", "MIN_TOKEN", "DashboardConfig", "parse_dashboard"]

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


def parse_dashboard(
    node: yaml.Node,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: Callable[[str, int | None, str, str], None],
) -> DashboardConfig:
    """The ``dashboard:`` section (rule 1); every problem is a D510 error (rule 2)."""
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
