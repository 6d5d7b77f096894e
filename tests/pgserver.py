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
from typing import Any

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
    argv: list[str]

    def crash(self) -> None:
        """Immediate shutdown (SIGQUIT): no checkpoint; the next start runs crash recovery."""
        self.signal(signal.SIGQUIT)
        if not self.wait_gone(20):
            raise RuntimeError("PostgreSQL did not stop on SIGQUIT")

    def restart(self) -> None:
        """Start the server again on its data directory and port."""
        self.proc = subprocess.Popen(
            self.argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        if not _listening(self.port, self.proc, 60):
            raise RuntimeError(f"PostgreSQL did not start again on port {self.port}")

    def pid(self) -> int | None:
        """The postmaster's PID (runuser's child), from its pid file."""
        try:
            return int((self.data / "postmaster.pid").read_text().split()[0])
        except (OSError, ValueError, IndexError):
            return None

    def signal(self, sig: int) -> None:
        """Signal the postmaster itself: runuser does not pass every signal on."""
        pid = self.pid()
        if pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)

    def wait_gone(self, timeout: float) -> bool:
        """Wait for the postmaster and runuser to end; False if they did not in time."""
        pid = self.pid()
        deadline = time.monotonic() + timeout
        while pid is not None and time.monotonic() < deadline:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.05)
        else:
            if pid is not None:
                return False
        try:
            self.proc.wait(max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            return False
        return True

    def stop(self) -> None:
        """Stop the server by its PID (fast shutdown), then remove its directory."""
        self.signal(signal.SIGINT)
        if not self.wait_gone(20):
            self.signal(signal.SIGKILL)
            self.proc.kill()
            self.wait_gone(10)
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
    argv = [*as_user, postgres, "-D", str(data), "-p", str(port), "-h", "127.0.0.1",
            "-k", str(root), *fast]  # fmt: skip
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"postgresql://postgres@127.0.0.1:{port}/postgres"
    server = PgServer(url, port, data, proc, argv)
    if _listening(port, proc, 30):
        return server
    server.stop()
    raise RuntimeError(f"PostgreSQL did not start on port {port}")


def _listening(port: int, proc: subprocess.Popen[bytes], timeout: float) -> bool:
    """Wait until the server accepts connections on ``port`` (False: it ended or timed out)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            with psycopg_connect(port):
                return True
        except Exception:  # starting up, or in crash recovery: not yet
            time.sleep(0.1)
    return False


def psycopg_connect(port: int) -> Any:
    import psycopg

    return psycopg.connect(f"postgresql://postgres@127.0.0.1:{port}/postgres", connect_timeout=2)
