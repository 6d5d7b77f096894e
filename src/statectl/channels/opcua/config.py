"""The run config's ``opcua:`` section: where the OPC UA server listens and who may command.

Rules:
1. The section is a mapping::

       opcua:
         endpoint: opc.tcp://127.0.0.1:4840     # default; loopback unless configured
         user: operator                         # who may call methods (or $STATECTL_OPCUA_USER)
         password: <12 or more characters>      # (or $STATECTL_OPCUA_PASSWORD); never echoed
         security: [Basic256Sha256]             # add None only to allow unencrypted sessions
         certificates: /var/lib/statectl/opcua  # where the server's certificate is kept

2. Every problem is a D520 error with its line; a password is never shown in a
   message, only that it is too short or not text.
3. Parsing only: the server (:mod:`statectl.channels.opcua`) reads the values; this module
   needs neither asyncua nor the network.
"""

from __future__ import annotations

import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import yaml

from statectl.run.devices.urls import url_problem

__all__ = ["MIN_PASSWORD", "POLICIES", "OpcuaConfig", "endpoint_problem", "parse_opcua"]

#: The security policies a config may list (OPC UA names).
POLICIES = ("Basic256Sha256", "None")
#: The shortest password the section accepts: a short one is guessed.
MIN_PASSWORD = 12
OPCUA_KEYS = ("endpoint", "user", "password", "security", "certificates")


@dataclass(frozen=True, slots=True)
class OpcuaConfig:
    """The ``opcua:`` section: each field None where the file says nothing."""

    endpoint: str | None = None
    user: str | None = None
    password: str | None = None
    security: tuple[str, ...] | None = None
    certificates: str | None = None

    def __repr__(self) -> str:  # the password never reaches a log or a traceback
        shown = None if self.password is None else "***"
        return (
            f"OpcuaConfig(endpoint={self.endpoint!r}, user={self.user!r}, password={shown}, "
            f"security={self.security!r}, certificates={self.certificates!r})"
        )


def endpoint_problem(url: Any) -> str | None:
    """Why ``url`` is no ``opc.tcp://HOST:PORT`` endpoint a server can bind, or None."""
    if not (isinstance(url, str) and url.startswith("opc.tcp://")):
        return f"endpoint must be an opc.tcp:// URL (got {url!r})"
    problem = url_problem(url)
    if problem is not None:
        return f"endpoint {url!r} is not an opc.tcp://HOST:PORT URL ({problem})"
    if not urllib.parse.urlsplit(url).hostname:
        return f"endpoint {url!r} names no host: write opc.tcp://HOST:PORT"
    return None


def parse_opcua(
    node: yaml.Node,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: Callable[[str, int | None, str, str], None],
) -> OpcuaConfig:
    """The ``opcua:`` section (rule 1); every problem is a D520 error (rule 2)."""
    if not isinstance(node, yaml.MappingNode):
        error("D520", line_of(node), "'opcua' must be a mapping",
              "write 'opcua: {endpoint: opc.tcp://127.0.0.1:4840}'")  # fmt: skip
        return OpcuaConfig()
    fields: dict[str, Any] = {}
    given: set[str] = set()
    for k, v in node.value:
        name, val, line = value(k), value(v), line_of(v)
        given.add(name)
        if name not in OPCUA_KEYS:
            error("D520", line_of(k), f"opcua: unknown key {name!r}",
                  f"the opcua section has {', '.join(OPCUA_KEYS)}")  # fmt: skip
        elif name == "endpoint" and (why := endpoint_problem(val)):
            error("D520", line, f"opcua: {why}",
                  "write 'endpoint: opc.tcp://127.0.0.1:4840' (loopback only)")  # fmt: skip
        elif name in ("user", "certificates") and not (isinstance(val, str) and val):
            error("D520", line, f"opcua: {name} must be text (got {val!r})", "")
        elif name == "password" and not (isinstance(val, str) and len(val) >= MIN_PASSWORD):
            shown = "a shorter text" if isinstance(val, str) else type(val).__name__
            error(
                "D520",
                line,
                f"opcua: password must be text of {MIN_PASSWORD} characters or more (got {shown})",
                "make one: python -c 'import secrets; print(secrets.token_urlsafe(18))'",
            )
        elif name == "security":
            listed = [val] if isinstance(val, str) else val
            if not (
                isinstance(listed, list)
                and listed
                and all(isinstance(p, str) and p in POLICIES for p in listed)
            ):
                error("D520", line,
                      f"opcua: security must list {' and/or '.join(POLICIES)} (got {val!r})",
                      "the default is [Basic256Sha256] (SignAndEncrypt)")  # fmt: skip
            else:
                fields[name] = tuple(dict.fromkeys(listed))
        else:
            fields[name] = val
    if ("user" in given) != ("password" in given):
        error("D520", line_of(node), "opcua: give both user and password, or neither",
              "or set STATECTL_OPCUA_USER and STATECTL_OPCUA_PASSWORD")  # fmt: skip
    return OpcuaConfig(**fields)
