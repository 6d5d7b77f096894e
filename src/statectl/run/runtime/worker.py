"""A Subject's owner loop on a thread of its own: serve, start a worker, stop.

Rule 1 of the Subject: one owner at a time. Either the caller is the owner
(``run_until_idle``, ``dispatch``, ``advance``) or a worker thread is, running
:meth:`Worker.serve_forever` until :meth:`Worker.stop`; processing from another
thread while a worker owns the device is refused (:meth:`Worker._check_owner`).
"""

from __future__ import annotations

import sys
import threading
import traceback
from collections import deque
from typing import Any

from statectl.kernel.errors import StatectlError
from statectl.kernel.semantics import Snapshot
from statectl.run.runtime.hooks import ErrorHandler
from statectl.run.runtime.recording import Recording

__all__ = ["Worker"]


def _print_error(exc: BaseException) -> None:
    traceback.print_exception(exc, file=sys.stderr)


class Worker(Recording):
    """The Subject's owner-loop half; the slots it writes live here, the rest on the Subject."""

    __slots__ = ("_fast", "_serving", "_stopping", "_wake", "_worker")

    _fast: bool
    _serving: bool
    _stopping: bool
    _wake: threading.Event | None
    _worker: threading.Thread | None
    _name: str
    _queue: deque[Any]
    _snapshot: Snapshot | None

    def start(self) -> None:
        raise NotImplementedError  # the Subject's

    def run_until_idle(self) -> int:
        raise NotImplementedError  # the Subject's

    def _refresh(self) -> None:
        raise NotImplementedError  # the Subject's

    def _ensure_wake(self) -> threading.Event:
        """The worker's wake-up event, made when an owner loop first needs it.

        A post that found no event queued its item first, so a queue that is not
        empty here sets the new event and nothing posted is slept through.
        """
        wake = self._wake
        if wake is None:
            wake = self._wake = threading.Event()
            if self._queue:
                wake.set()
        return wake

    def serve_forever(self, on_error: ErrorHandler = _print_error) -> None:
        """Be the owner on this thread until :meth:`stop`; errors go to ``on_error``."""
        if self._snapshot is None:
            self.start()
        wake = self._ensure_wake()
        self._serving = True
        self._fast = False
        try:
            while not self._stopping:
                wake.wait()
                wake.clear()
                while self._queue and not self._stopping:
                    try:
                        self.run_until_idle()
                    except Exception as exc:  # record + callback; a worker never dies of an event
                        on_error(exc)
        finally:
            self._serving = False
            self._stopping = False
            self._refresh()

    def start_worker(self, on_error: ErrorHandler = _print_error) -> threading.Thread:
        """Run :meth:`serve_forever` on a daemon thread, which becomes the owner."""
        if self._worker is not None:
            raise StatectlError(f"{self._name} has a worker already")
        self._ensure_wake()
        self._serving = True  # so a stop() before the thread runs is not lost
        self._fast = False
        self._worker = threading.Thread(
            target=self.serve_forever, args=(on_error,), name=f"statectl-{self._name}", daemon=True
        )
        self._worker.start()
        return self._worker

    def stop(self, timeout: float | None = 1.0) -> None:
        """Stop the owner loop after the event in progress; queued events stay queued."""
        if self._serving:
            self._stopping = True
            self._ensure_wake().set()
        worker = self._worker
        if worker is not None and worker is not threading.current_thread():
            worker.join(timeout)
        self._worker = None
        self._refresh()

    def _check_owner(self) -> None:
        worker = self._worker
        if worker is not None and worker.is_alive() and worker is not threading.current_thread():
            raise StatectlError(
                f"{self._name} is owned by its worker thread; post() events instead of "
                "processing them here"
            )
