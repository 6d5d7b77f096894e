"""A device's inbox: the queue of events and owner work, and who is told of new items.

Any thread puts; only the owner takes (the Subject's rule 1). Putting never blocks:
it appends, wakes a worker waiting on :attr:`Inbox.wake` (made only when an owner loop
first needs it), and tells the host's hook (a System's ready list).
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import Any

__all__ = ["Inbox", "Item"]

#: A queued event ``(name, data, then)`` (``then(outcome)`` once it ran, or None), or
#: ``(None, None, fn)`` to run ``fn`` on the owner.
Item = tuple[str | None, Any, Callable[..., object] | None]


class Inbox:
    """The queue of one device, its worker's wake-up event and its host's hook."""

    __slots__ = ("hook", "items", "owner", "wake")

    def __init__(self, owner: object) -> None:
        self.owner = owner  # what the hook is given: the Subject
        self.items: deque[Item] = deque()
        self.wake: threading.Event | None = None
        self.hook: Callable[[Any], object] | None = None

    def put(self, item: Item) -> None:
        """Queue ``item`` last, from any thread."""
        self.items.append(item)
        self._told()

    def put_first(self, item: Item) -> None:
        """Queue ``item`` before anything queued (the owner only, who will take it: nobody
        is told)."""
        self.items.appendleft(item)

    def _told(self) -> None:
        wake = self.wake
        if wake is not None:
            wake.set()
        hook = self.hook
        if hook is not None:
            hook(self.owner)

    def waker(self) -> threading.Event:
        """The worker's wake-up event, made when an owner loop first needs it.

        A put that found no event queued its item first, so an inbox that is not
        empty here sets the new event and nothing put is slept through.
        """
        wake = self.wake
        if wake is None:
            wake = self.wake = threading.Event()
            if self.items:
                wake.set()
        return wake
