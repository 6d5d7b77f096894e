"""Reading a large file builds many objects and no garbage: pause the cyclic collector.

A 10,000-state device file becomes ~300,000 nodes, rows, cells and locations, all
reachable until the chart is built. Each generation-0 collection the allocations
trigger walks the young ones and finds nothing to free, and the older generations
are walked again and again as they grow: half the time of a load went there
(``bench/check.py``). :func:`gc_paused` turns the collector off for such a load
and back on after it, only if it was on, so nested or concurrent loads leave it as
they found it. Reference counting still frees everything short-lived meanwhile.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["gc_paused"]


@contextmanager
def gc_paused() -> Iterator[None]:
    """Run the body with the cyclic garbage collector off, restoring it after."""
    was_on = gc.isenabled()
    if was_on:
        gc.disable()
    try:
        yield
    finally:
        if was_on:
            gc.enable()
