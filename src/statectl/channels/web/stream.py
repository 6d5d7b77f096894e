"""Server-Sent Events fan-out on the dashboard's event loop.

Rules:
1. Everything here runs on the loop thread; the devices' owner threads only hand
   text over (see :meth:`statectl.channels.web.server.Dashboard.publish`).
2. Every message gets the next ``id:``; a batch of messages is framed once (one
   HTTP/1.1 chunk) and the same bytes are written to every stream's transport, so
   a message costs one ``transport.write`` per client and no task wake-up.
3. A stream either receives every message in order or is dropped: when the bytes
   queued for a client pass ``buffer`` (it reads slower than the devices write),
   its connection is aborted and its memory freed. The browser's EventSource
   reconnects by itself and starts again from a snapshot.
4. A stream holds a slot from the moment it is admitted, so the cap on streams
   is exact even while responses are being prepared.
5. A client that takes nothing does not hold its slot forever on a quiet device:
   at each heartbeat a stream with bytes still waiting for it (the kernel's buffer is
   full) is noted, and one found so at every heartbeat for ``stall`` seconds is
   dropped.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Iterable

__all__ = ["Fanout", "Stream", "chunk"]

#: Comment sent to every stream when nothing else was: proves the client is still there.
IDLE = b": idle\n\n"


def chunk(data: bytes) -> bytes:
    """``data`` as one HTTP/1.1 chunk (the stream's response is chunked)."""
    return b"%x\r\n%s\r\n" % (len(data), data)


class Stream:
    """One SSE connection: its transport once the headers are out, and its end."""

    __slots__ = ("backed_up_since", "closed", "limit", "transport")

    def __init__(self, limit: int, loop: asyncio.AbstractEventLoop) -> None:
        self.transport: asyncio.BaseTransport | None = None
        self.limit = limit
        self.closed: asyncio.Future[str] = loop.create_future()
        #: Loop time since which bytes have waited for this client at every check (rule 5).
        self.backed_up_since: float | None = None

    def send(self, data: bytes) -> bool:
        """Write ``data``; False (and the stream ends) when the client is gone or behind."""
        transport = self.transport
        if transport is None:  # not started: its first write takes the log instead
            return True
        if transport.is_closing() or not isinstance(transport, asyncio.WriteTransport):
            self.end("gone")
            return False
        transport.write(data)
        if transport.get_write_buffer_size() > self.limit:
            transport.abort()  # rule 3: free the buffer now, never slow the others
            self.end("behind")
            return False
        return True

    def end(self, why: str) -> None:
        if not self.closed.done():
            self.closed.set_result(why)


class Fanout:
    """The streams, the recent log for new pages and the message numbering."""

    def __init__(self, *, streams: int, buffer: int, log_size: int) -> None:
        self.cap = streams
        self.buffer = buffer
        self.streams: set[Stream] = set()
        self.log: deque[bytes] = deque(maxlen=log_size)
        self.seq = 0
        self.dropped = 0

    def admit(self, loop: asyncio.AbstractEventLoop) -> Stream | None:
        """A slot for a new stream, or None when ``cap`` streams are open (rule 4)."""
        if len(self.streams) >= self.cap:
            return None
        stream = Stream(self.buffer, loop)
        self.streams.add(stream)
        return stream

    def start(self, stream: Stream, transport: asyncio.BaseTransport, first: bytes) -> None:
        """Send ``first`` (the snapshot) and the log, then live messages, to ``stream``."""
        stream.transport = transport
        stream.send(chunk(first + b"".join(self.log)))

    def leave(self, stream: Stream) -> None:
        stream.end("left")
        self.streams.discard(stream)

    def publish(self, texts: Iterable[str]) -> None:
        """Number ``texts``, keep them in the log and write them to every stream (rule 2)."""
        frames = []
        for text in texts:
            self.seq += 1
            frames.append(b"id: %d\ndata: %s\n\n" % (self.seq, text.encode()))
        if not frames:
            return
        self.log.extend(frames)
        self._send(chunk(b"".join(frames)))

    def heartbeat(self, now: float, stall: float) -> None:
        """Send a comment to every stream and drop those backed up for ``stall`` s (rule 5)."""
        self._send(chunk(IDLE))
        for stream in tuple(self.streams):
            transport = stream.transport
            if not isinstance(transport, asyncio.WriteTransport):
                continue
            if transport.get_write_buffer_size() == 0:
                stream.backed_up_since = None
            elif stream.backed_up_since is None:
                stream.backed_up_since = now
            elif now - stream.backed_up_since >= stall:
                transport.abort()
                stream.end("stalled")
                self.streams.discard(stream)
                self.dropped += 1

    def drop_all(self, why: str) -> None:
        for stream in tuple(self.streams):
            transport = stream.transport
            if isinstance(transport, asyncio.WriteTransport) and not transport.is_closing():
                transport.abort()
            stream.end(why)
            self.streams.discard(stream)

    def _send(self, data: bytes) -> None:
        for stream in tuple(self.streams):
            if not stream.send(data):
                self.streams.discard(stream)
                self.dropped += 1
