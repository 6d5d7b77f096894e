"""The server's own certificate: made on first run, kept, reused (Basic256Sha256 needs one)."""

from __future__ import annotations

import os
import socket
from pathlib import Path

from statectl.kernel.errors import StatectlError

__all__ = ["APP_URI", "default_directory", "ensure_certificate"]

#: The application URI the certificate names and the server announces.
APP_URI = "urn:statectl:opcua:server"


def default_directory() -> Path:
    """``$XDG_STATE_HOME/statectl/opcua``, else ``~/.local/state/statectl/opcua``."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "statectl" / "opcua"


async def ensure_certificate(directory: Path) -> tuple[Path, Path]:
    """``(certificate.der, key.pem)`` in ``directory``, generated when missing or expired.

    The key file is written owner-only (0600); the directory is made 0700.
    """
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    try:
        directory.mkdir(parents=True, exist_ok=True, mode=0o700)
    except OSError as exc:
        raise StatectlError(f"opcua: cannot create the certificate directory: {exc}") from None
    cert, key = directory / "server-cert.der", directory / "server-key.pem"
    old = os.umask(0o077)  # the key must never be readable by others, not even for a moment
    try:
        await setup_self_signed_certificate(
            key,
            cert,
            APP_URI,
            socket.gethostname(),
            [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
            {"commonName": "statectl OPC UA server", "organizationName": "statectl"},
        )
    except (OSError, ValueError) as exc:
        raise StatectlError(
            f"opcua: cannot make the server certificate in {directory}: {exc}"
        ) from None
    finally:
        os.umask(old)
    return cert, key
