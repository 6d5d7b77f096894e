"""A device's inbox: the queue of events and owner work, and who is told of new items.

Any thread appends; only the owner takes (the Subject's rule 1). Appending never
blocks; :meth:`Inbox.told` then wakes a worker waiting on :attr:`Inbox.wake` (made only
when an owner loop first needs it) and tells the host's hook (a System's ready list).
The inbox keeps no reference to its Subject (the Subject hands itself to
:meth:`Inbox.told`): a device's parts then form no reference cycle, so a device dropped
is freed at once instead of waiting for the cyclic collector.
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


class Inbox(deque[Item]):
    """The queue of one device (a deque: the owner pops it), its worker's wake-up event
    and its host's hook (slots: a post reads both, about 60 ns less than class defaults
    looked up through the instance)."""

    __slots__ = ("hook", "wake")

    def __init__(self) -> None:
        super().__init__()
        self.wake: threading.Event | None = None
        self.hook: Callable[[Any], object] | None = None

    def told(self, owner: object) -> None:
        """After an item was appended, from any thread: wake the worker, tell the host
        (``hook(owner)``, the Subject).

        The Subject appends, marks itself not idle, then calls this only when there is
        a worker or a host to tell (runtime/subject.py, ``post``)."""
        wake = self.wake
        if wake is not None:
            wake.set()
        hook = self.hook
        if hook is not None:
            hook(owner)

    def waker(self) -> threading.Event:
        """The worker's wake-up event, made when an owner loop first needs it.

        An append that found no event queued its item first, so an inbox that is not
        empty here sets the new event and nothing appended is slept through.
        """
        wake = self.wake
        if wake is None:
            wake = self.wake = threading.Event()
            if self:
                wake.set()
        return wake
