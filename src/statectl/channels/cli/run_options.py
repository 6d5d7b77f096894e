"""What ``statectl run`` was asked besides the model's path: its flags, checked before anything
loads (exit 2 for a flag that cannot be; cli/run.py's rules say what each one does)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlparse

from statectl.channels.cli.commands import input_exists
from statectl.run.journal import Guarantee, Sync

__all__ = ["MAX_PORT", "RunOptions"]

#: The highest TCP port a ``--port`` may name (0: any free port).
MAX_PORT = 65535


@dataclass(frozen=True, slots=True)
class RunOptions:
    """The flags of one ``statectl run``, as :func:`statectl.channels.cli.run.run` takes them."""

    driver: str | None = None
    config: str | None = None
    dashboard: bool = False
    host: str | None = None
    port: int | None = None
    token: str | None = None
    journal: str | None = None
    resume: bool = False
    fresh: bool = False
    sync: str = "normal"
    guarantee: str = "prompt"
    realtime: bool = False
    opcua: str | None = None
    settle_limit: float | None = None
    as_json: bool = False

    @property
    def live(self) -> bool:
        """A live run serves until stopped (rule 3); otherwise it feeds a batch and ends."""
        return self.dashboard or self.realtime or self.opcua is not None

    def usage_problem(self, path: str) -> str | None:
        """The first flag that cannot be, said as the command says it; None when all fit."""
        if self.as_json and self.live:
            return "--json steps a batch run; not with --dashboard, --realtime or --opcua"
        if (self.resume or self.fresh) and self.journal is None:
            return f"{'--resume' if self.resume else '--fresh'} needs --journal DB"
        if not input_exists(Path(path)):
            return f"{path}: no such file"
        if self.settle_limit is not None and not self.settle_limit > 0:
            return f"--settle-limit must be more than 0 seconds (got {self.settle_limit})"
        if self.port is not None and not 0 <= self.port <= MAX_PORT:
            return f"--port must be 0 (any free port) to {MAX_PORT} (got {self.port})"
        opcua = self.opcua
        if opcua and not (opcua.startswith("opc.tcp://") and urlparse(opcua).hostname):
            return f"--opcua must be an opc.tcp://HOST:PORT URL (got {opcua!r})"
        if self.sync.lower() not in {s.value for s in Sync}:
            return f"--sync must be normal or full (got {self.sync!r})"
        if self.guarantee.lower() not in {g.value for g in Guarantee}:
            return f"--guarantee must be prompt or durable-first (got {self.guarantee!r})"
        return None

    @property
    def modes(self) -> tuple[Sync, Guarantee]:
        """``--sync`` and ``--guarantee`` as the journal takes them (checked by usage_problem)."""
        return Sync(self.sync.lower()), Guarantee(self.guarantee.lower())
