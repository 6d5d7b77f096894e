"""``statectl run --opcua``: the settings from flag, environment and config, then the server.

Rules:
1. The endpoint: the ``--opcua URL``, else the config's ``opcua: endpoint``, else
   ``opc.tcp://127.0.0.1:4840`` (loopback: another host must be configured).
2. The user who may call methods: ``$STATECTL_OPCUA_USER`` and
   ``$STATECTL_OPCUA_PASSWORD``, else the config's ``user`` and ``password``; the
   banner says where they came from, never the password. Without one, no one may
   call a method (browsing and subscribing stay open).
3. Security policies: the config's ``security``, else Basic256Sha256
   SignAndEncrypt only; the certificate lives in the config's ``certificates``
   directory, else :func:`statectl.channels.opcua.certs.default_directory`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, TextIO

from statectl.channels.opcua.config import MIN_PASSWORD, OpcuaConfig
from statectl.kernel.errors import StatectlError, require
from statectl.run.system import System

__all__ = ["DEFAULT_ENDPOINT", "PASSWORD_VARIABLE", "USER_VARIABLE", "serve_opcua"]

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840"
USER_VARIABLE = "STATECTL_OPCUA_USER"
PASSWORD_VARIABLE = "STATECTL_OPCUA_PASSWORD"


def serve_opcua(
    system: System, flag: str, section: OpcuaConfig, config: str | None, out: TextIO
) -> Any:
    """Start the OPC UA server for ``system`` (rules 1-3); returns it (``stop()`` it)."""
    require("asyncua", "opcua", "--opcua")  # the server imports it when it starts
    from statectl.channels.opcua.server import OpcuaServer, OpcuaSettings

    user, password, where = section.user, section.password, str(config)
    env_user, env_password = os.environ.get(USER_VARIABLE), os.environ.get(PASSWORD_VARIABLE)
    if env_user or env_password:
        if not (env_user and env_password):
            raise StatectlError(f"set both {USER_VARIABLE} and {PASSWORD_VARIABLE}, or neither")
        if len(env_password) < MIN_PASSWORD:
            raise StatectlError(
                f"{PASSWORD_VARIABLE} is shorter than {MIN_PASSWORD} characters, so it could "
                "be guessed; make one with "
                "python -c 'import secrets; print(secrets.token_urlsafe(18))'"
            )
        user, password, where = env_user, env_password, "the environment"
    settings = OpcuaSettings(
        endpoint=flag or section.endpoint or DEFAULT_ENDPOINT,
        user=user,
        password=password,
        security=section.security or ("Basic256Sha256",),
        certificates=Path(section.certificates) if section.certificates else None,
    )
    server = OpcuaServer(system, settings)
    url = server.start()
    who = f"user {user!r} (from {where})" if user else "nobody (configure a user)"
    out.write(f"opcua: {url} security {', '.join(settings.security)}; methods: {who}\n")
    return server
