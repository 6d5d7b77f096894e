"""Compact state storage (cell/explore/pack.py): states in a flat array where they fit,
and a set where no state's number is ever asked."""

from __future__ import annotations

from array import array

import pytest

from statectl.cell.explore.pack import MAP_BITS, SeenBits, SeenMap, seen_store, state_store


@pytest.mark.parametrize(("width", "kind"), [(1, array), (64, array), (65, list), (200, list)])
def test_states_go_to_an_array_when_their_packing_fits_64_bits(width: int, kind: type) -> None:
    """Up to 64 bits a state is 8 bytes in an array('Q'); wider ones stay Python ints."""
    store = state_store(width)
    assert isinstance(store, kind)
    big = (1 << width) - 1
    store.append(big)
    assert store[0] == big


@pytest.mark.parametrize(
    ("width", "kind"), [(4, SeenMap), (MAP_BITS, SeenMap), (27, SeenBits), (130, SeenBits)]
)
def test_a_walk_without_edges_keeps_a_byte_map_or_a_set(width: int, kind: type) -> None:
    """Up to MAP_BITS bits every possible state has a byte; wider, bit masks; both
    answer ``in`` for states recorded with ``seen[h] = n`` and never give a number."""
    seen = seen_store(width, numbered=False)
    assert isinstance(seen, kind)
    top = (1 << width) - 1
    seen[top] = 7
    seen[0] = 8
    assert top in seen and 0 in seen and 1 not in seen and (top - 1) not in seen
    with pytest.raises(KeyError):
        seen[top]


def test_bit_masks_count_each_state_once() -> None:
    """States that share a mask (the same bits above the low six) are told apart."""
    seen = SeenBits()
    for h in (0, 1, 63, 64, 1 << 100, 1):
        seen[h] = 0
    assert len(seen) == 5
    assert [h in seen for h in (0, 1, 2, 63, 64, 65, 1 << 100)] == [
        True,
        True,
        False,
        True,
        True,
        False,
        True,
    ]


def test_a_walk_with_edges_numbers_its_states() -> None:
    """Recovery needs each state's number for its edges: a dict."""
    seen = seen_store(10, numbered=True)
    seen[3] = 0
    assert seen[3] == 0 and 3 in seen
