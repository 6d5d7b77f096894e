"""Compact storage of a search's states: packed integers in flat arrays.

A global state is already packed (:mod:`statectl.cell.explore.compose` rule 1: each
device's local id, which holds its configuration, data and pending calls, in a few
bits). Kept as Python ints in a list and a dict from state to number, each cost some
135 bytes. Rules:

1. The states are one ``array('Q')`` (8 bytes each) when the packing fits 64 bits.
2. A walk that keeps no edges (no recovery goal to judge) never asks a state's
   number, so it needs only whether a state was seen. When the packing is at most
   :data:`MAP_BITS` bits wide that is one byte per possible state in an anonymous
   memory map (:class:`SeenMap`: the kernel gives zero pages as they are touched;
   ``in`` is a C-level index); wider, 64-bit masks of the low six bits keyed by the
   rest (:class:`SeenBits`): a step changes one device's field, so the states met
   share masks (on the 9-station bench about 7 bytes a state, where a set of ints
   took 64).
3. A walk that keeps edges keeps the dict from state to number. An open-addressing
   table of 4-byte slots in an array would make that small too, but its probing runs
   in Python, some four times slower than the dict: not worth it here.
"""

from __future__ import annotations

import mmap
from array import array
from collections.abc import MutableSequence

__all__ = ["MAP_BITS", "SeenBits", "SeenMap", "seen_store", "state_store"]

#: Widest packing whose seen-map (one byte per possible state: 64 MiB) rule 2 takes.
MAP_BITS = 26


def state_store(width: int) -> MutableSequence[int]:
    """Where a walk keeps its states: 8 bytes each when ``width`` bits fit (rule 1)."""
    return array("Q") if width <= 64 else []


class SeenMap(mmap.mmap):
    """Rule 2: one byte per possible state; ``h in seen`` reads byte ``h`` in C."""

    # ``in`` is the mapping's own byte read (0: not seen), with no Python frame
    __contains__ = mmap.mmap.__getitem__  # type: ignore[assignment]

    def __setitem__(self, h: int, n: int) -> None:  # type: ignore[override]
        mmap.mmap.__setitem__(self, h, 1)

    def __getitem__(self, h: int) -> int:  # type: ignore[override]
        raise KeyError("a walk without edges does not number its states")


class SeenBits:
    """Rule 2, wide packings: a dict from ``h >> 6`` to a 64-bit mask of the low bits.
    States a step apart differ in one device's field, so low fields fill their masks."""

    __slots__ = ("_count", "_masks")

    def __init__(self) -> None:
        self._masks: dict[int, int] = {}
        self._count = 0

    def __contains__(self, h: object) -> bool:
        assert isinstance(h, int)
        return (self._masks.get(h >> 6, 0) >> (h & 63)) & 1 == 1

    def __setitem__(self, h: int, n: int) -> None:
        key, bit = h >> 6, 1 << (h & 63)
        old = self._masks.get(key, 0)
        if not old & bit:
            self._count += 1
            self._masks[key] = old | bit

    def __getitem__(self, h: int) -> int:
        raise KeyError("a walk without edges does not number its states")

    def __len__(self) -> int:
        return self._count


def seen_store(width: int, numbered: bool) -> dict[int, int] | SeenMap | SeenBits:
    """What a walk asks ``h in seen`` and sets ``seen[h] = n`` on (rules 2 and 3)."""
    if numbered:
        return {}
    if width <= MAP_BITS:
        return SeenMap(-1, 1 << width)
    return SeenBits()
