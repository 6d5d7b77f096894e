"""A throwaway PostgreSQL server for tests and bench/ship.py: Debian's binaries, as postgres.

PostgreSQL refuses to run as root, so when the tests run as root the server runs as
the ``postgres`` user through ``runuser``, on a temporary data directory owned by it,
listening on a free port of 127.0.0.1 only. :func:`start` returns None (the caller
skips) when the binaries or ``runuser`` are missing.
"""

from __future__ import annotations

import contextlib
import os
import pwd
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

BIN_DIRS = sorted(Path("/usr/lib/postgresql").glob("*/bin"), reverse=True)


def _binary(name: str) -> str | None:
    for d in BIN_DIRS:
        if (d / name).exists():
            return str(d / name)
    return shutil.which(name)


@dataclass
class PgServer:
    url: str
    port: int
    data: Path
    proc: subprocess.Popen[bytes]

    def stop(self) -> None:
        """Stop the server by its PID (fast shutdown), then remove its directory."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        shutil.rmtree(self.data.parent, ignore_errors=True)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def why_not() -> str | None:
    """Why no server can be started here, or None."""
    if _binary("initdb") is None or _binary("postgres") is None:
        return "PostgreSQL's initdb/postgres are not installed"
    if os.geteuid() == 0 and shutil.which("runuser") is None:
        return "running as root without runuser"
    if os.geteuid() == 0:
        try:
            pwd.getpwnam("postgres")
        except KeyError:
            return "running as root and there is no postgres user to run the server as"
    return None


def start(*, durable: bool = False) -> PgServer | None:
    """A running server with database ``postgres`` and user ``postgres`` (trust on loopback).

    ``durable``: PostgreSQL's default fsync and synchronous commit (benchmarks);
    tests turn both off, which changes no result, only the time.
    """
    if why_not() is not None:
        return None
    initdb, postgres = _binary("initdb"), _binary("postgres")
    assert initdb and postgres
    root = Path(tempfile.mkdtemp(prefix="statectl-pg-"))
    data = root / "data"
    as_user: list[str] = []
    if os.geteuid() == 0:
        shutil.chown(root, "postgres")
        root.chmod(0o700)
        as_user = ["runuser", "-u", "postgres", "--"]
    subprocess.run(
        [*as_user, initdb, "-D", str(data), "-U", "postgres", "-A", "trust", "--no-sync"],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    port = _free_port()
    fast = [] if durable else ["-c", "fsync=off", "-c", "synchronous_commit=off"]
    proc = subprocess.Popen(
        [*as_user, postgres, "-D", str(data), "-p", str(port), "-h", "127.0.0.1",
         "-k", str(root), *fast],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    url = f"postgresql://postgres@127.0.0.1:{port}/postgres"
    server = PgServer(url, port, data, proc)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
            time.sleep(0.2)  # accepting connections: give it a moment to finish start-up
            return server
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    server.stop()
    raise RuntimeError(f"PostgreSQL did not start on port {port}")
