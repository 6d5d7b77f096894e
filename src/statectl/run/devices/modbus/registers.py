"""Register words <-> model numbers: type, byte and word order, scale and offset.

Rules:
1. A value of ``n`` registers is the big-endian bytes of its words after two
   swaps: ``byte_order: little`` swaps the two bytes of each word, ``word_order:
   little`` puts the low word first (the "CDAB" layout many PLCs use for float32).
2. The model sees ``raw * scale + offset``; an integer type with an integer
   scale and offset stays an int (an event field declared ``int`` accepts it).
3. Writing is the inverse; a number the type cannot hold is refused with what fits.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

from statectl.kernel.errors import StatectlError
from statectl.run.devices.modbus.options import REGISTER_TYPES, Register

__all__ = ["decode_register", "encode_register"]


def _swap(word: int) -> int:
    return ((word & 0xFF) << 8) | (word >> 8)


def _arrange(reg: Register, words: Sequence[int]) -> list[int]:
    """Rule 1, which is its own inverse: wire order <-> big-endian order."""
    ordered = [_swap(w) if reg.byte_order == "little" else w for w in words]
    return ordered[::-1] if reg.word_order == "little" else ordered


def decode_register(reg: Register, words: Sequence[int]) -> int | float:
    """The model value of ``reg`` from its ``reg.width`` words as read (rules 1-2)."""
    raw_bytes = b"".join(w.to_bytes(2, "big") for w in _arrange(reg, words))
    raw: int | float = struct.unpack(">" + REGISTER_TYPES[reg.type][1], raw_bytes)[0]
    return raw * reg.scale + reg.offset


def encode_register(reg: Register, value: float) -> list[int]:
    """The words to write so ``reg`` reads ``value`` (rule 3)."""
    code = REGISTER_TYPES[reg.type][1]
    raw: int | float = (value - reg.offset) / reg.scale
    if code != "f":
        raw = round(raw)
    try:
        if not math.isfinite(raw):
            raise OverflowError
        packed = struct.pack(">" + code, raw)
    except (struct.error, OverflowError):
        raise StatectlError(
            f"register {reg.name} ({reg.type}, scale {reg.scale}, offset {reg.offset}) "
            f"cannot hold {value!r}"
        ) from None
    words = [int.from_bytes(packed[i : i + 2], "big") for i in range(0, len(packed), 2)]
    return _arrange(reg, words)
