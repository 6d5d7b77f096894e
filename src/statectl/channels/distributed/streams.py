"""Once and in order per link stream: numbering, acknowledgement and deduplication.

No I/O here: :mod:`statectl.channels.distributed.node` moves the messages. A *stream* is
every link event one node sends to one device on another node.

Rules:
1. The sender numbers a stream's events 1, 2, 3, ... within an *epoch* (a name
   the sending node picks when it starts fresh and keeps in its journal, so a
   resumed node goes on counting where its journal left off).
2. The sender keeps every event until it is acknowledged (``Outbound``); an
   acknowledgement is cumulative (everything up to ``n``).
3. The receiver applies ``n`` only if it is the next one of the epoch
   (``Inbound.offer``): an older one is a duplicate (a resend after a reconnect)
   and is dropped; a newer one means a gap and asks the sender to resend from the
   one after the last applied.
4. An epoch changes only through the hello exchange: a sender's ``hello`` names
   its epoch (:meth:`Inbound.announce`), and an epoch the receiver has not seen
   is taken only once announced, starting at whatever comes first (a sender
   resends from its oldest unacknowledged event). Any other epoch, and a number
   outside 1 .. :data:`MAX_NUMBER`, is refused: nothing is applied and the
   stream's position is kept, so old numbers cannot be replayed by switching
   epochs and the real sender's once-only delivery holds.
"""

from __future__ import annotations

import enum
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

__all__ = ["MAX_NUMBER", "Inbound", "Outbound", "Verdict"]

#: The highest number of a stream's event (JSON's exact integers).
MAX_NUMBER = 2**53


class Verdict(enum.Enum):
    APPLY = "apply"
    DUPLICATE = "duplicate"
    GAP = "gap"
    REFUSED = "refused"  # rule 4: an epoch never announced, or a number out of range


@dataclass(slots=True)
class Outbound:
    """One stream's sending side (rules 1-2); its lock orders numbering and sending."""

    device: str  # the target device
    node: str  # the node it runs on
    epoch: str
    sent: int = 0  # the last number given out
    acked: int = 0  # everything up to here is acknowledged
    unacked: deque[tuple[int, str, Any]] = field(default_factory=deque)
    lock: threading.Lock = field(default_factory=threading.Lock)
    last_send: float = 0.0  # monotonic time of the last (re)send, for the resend timer
    #: the receiver acknowledged a hello since the peer came up: its epoch is known
    #: there, so events may be put as they come (rule 4)
    greeted: bool = False
    hello_at: float = 0.0  # monotonic time of the last hello, to say it again if unheard

    def add(self, event: str, data: Any) -> int:
        """Under ``lock``: number the next event and keep it until acknowledged."""
        self.sent += 1
        self.unacked.append((self.sent, event, data))
        self.last_send = time.monotonic()
        return self.sent

    def ack(self, upto: int) -> None:
        """Under ``lock``: forget everything up to ``upto``."""
        unacked = self.unacked
        while unacked and unacked[0][0] <= upto:
            unacked.popleft()
        if upto > self.acked:
            self.acked = upto


@dataclass(slots=True)
class Inbound:
    """Every stream's receiving side (rule 3): the last number applied per stream and epoch."""

    last: dict[tuple[str, str], tuple[str, int]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    #: per stream, the epoch its sender's last hello named (rule 4)
    announced: dict[tuple[str, str], str] = field(default_factory=dict)

    def announce(self, node: str, device: str, epoch: str) -> None:
        """Under ``lock``: a hello named ``epoch`` for this stream (rule 4)."""
        self.announced[node, device] = epoch

    def offer(self, node: str, device: str, epoch: str, n: int) -> tuple[Verdict, int]:
        """Under ``lock``: what to do with event ``n``, and the last applied number after it."""
        key = (node, device)
        seen = self.last.get(key)
        if not 1 <= n <= MAX_NUMBER:
            return Verdict.REFUSED, seen[1] if seen is not None else 0
        if seen is None or seen[0] != epoch:
            if self.announced.get(key) != epoch:
                return Verdict.REFUSED, seen[1] if seen is not None else 0
            self.last[key] = (epoch, n)
            return Verdict.APPLY, n
        last = seen[1]
        if n == last + 1:
            self.last[key] = (epoch, n)
            return Verdict.APPLY, n
        return (Verdict.DUPLICATE if n <= last else Verdict.GAP), last

    def applied(self, node: str, device: str, epoch: str) -> int | None:
        """The last number applied in ``epoch``, or None when the epoch is new here."""
        seen = self.last.get((node, device))
        return seen[1] if seen is not None and seen[0] == epoch else None
