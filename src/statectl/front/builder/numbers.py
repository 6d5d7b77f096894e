"""State numbers: the optional ``number`` column of the State Definition table.

Rules:
1. A standard profile numbers its states (PackML's Execute is 6, PLCopen's
   Standstill a number of the profile's own): the number is
   a whole number from 0 to 2**31 - 1, written as digits (B236 otherwise).
2. Two states of one device never share a number (B237): a client that reads
   ``CurrentState/Number`` must be able to tell them apart.
3. A state without a number has none (``None``); whoever shows numbers (OPC UA)
   numbers those after the highest given one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from statectl.front.builder.common import _d
from statectl.kernel.errors import Diagnostic, Location, Severity

#: The largest state number (fits OPC UA's Int32 and UInt32 alike).
MAX_NUMBER = 2**31 - 1


def state_numbers(
    texts: Mapping[str, tuple[str, Location]], kept: Sequence[str], diags: list[Diagnostic]
) -> dict[str, int]:
    """Each kept state's number, from its ``number`` cell text (rules 1-2)."""
    numbers: dict[str, int] = {}
    owner: dict[int, str] = {}
    for name in kept:
        text, where = texts.get(name, ("", Location()))
        if not text:
            continue
        digits = text.isascii() and text.isdigit() and len(text) <= len(str(MAX_NUMBER))
        if not digits or int(text) > MAX_NUMBER:
            diags.append(
                _d(
                    "B236",
                    Severity.ERROR,
                    where,
                    f"state {name!r}: number {text!r} is not a whole number from 0 to {MAX_NUMBER}",
                    "write the standard's state number as digits, e.g. 6, or leave it empty",
                )
            )
            continue
        number = int(text)
        if number in owner:
            diags.append(
                _d(
                    "B237",
                    Severity.ERROR,
                    where,
                    f"states {owner[number]!r} and {name!r} both have number {number}",
                    "give every state its own number",
                )
            )
            continue
        owner[number] = name
        numbers[name] = number
    return numbers
