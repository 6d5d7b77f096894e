"""The one check of a URL's syntax, for every URL a run config names.

The ``ship: to`` PostgreSQL URL (journal/ship_config.py, journal/pg.py) and the ``opcua:
endpoint`` (channels/opcua/config.py) are checked when the file loads, so a URL that
cannot be parsed is a line of the file, never a traceback when the run starts.
"""

from __future__ import annotations

import urllib.parse

__all__ = ["url_problem"]


def url_problem(url: str) -> str | None:
    """Why ``url`` cannot be split into its parts (an unclosed ``[`` of an IPv6 host, a
    port that is no number or out of range), or None. The text never holds the URL,
    which may hold a password."""
    try:
        urllib.parse.urlsplit(url).port  # noqa: B018  # the port is checked when read
    except ValueError as exc:
        return str(exc)
    return None
