"""The target of a Movement, refused unless it is a finite number of units.

``base.requested_target`` reads ``{target: x}`` or ``{amount: dx}``; a ``.nan`` or
``.inf`` amount (or ``true``, which Python counts as 1) passed it and then failed
deep in a driver: a NaN timer delay, a stepper's ``round(nan)``, an encoder count of
infinity. Every shipped motor driver asks this function instead, so such data is one
clear :class:`StatectlError` (a bad line, or a failure the run reports) before any
API call is made.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from statectl.devices.base import requested_target
from statectl.errors import StatectlError

__all__ = ["finite_target"]


def finite_target(position: float, data: Any) -> float:
    """``requested_target(position, data)``, refused unless finite and given as a number."""
    target = requested_target(position, data)
    given = [data.get(k) for k in ("target", "amount")] if isinstance(data, Mapping) else []
    if math.isfinite(target) and not any(isinstance(v, bool) for v in given):
        return target
    raise StatectlError(
        "a movement needs a finite number: event data {amount: <number>} or "
        f"{{target: <number>}} (got {data!r})"
    )
