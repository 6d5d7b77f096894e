"""The option checks of the CiA 402 drivers (D511): every problem at once, before a bus opens."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from statectl.run.devices.base import finite_number

__all__ = ["cia402_option_problems"]


def cia402_option_problems(options: Mapping[str, Any]) -> Sequence[str]:
    """Problems with a ``cia402``/``cia402-sim`` driver's option values."""
    problems: list[str] = []
    node = options.get("node_id", 1)
    if not (isinstance(node, int) and not isinstance(node, bool) and 1 <= node <= 127):
        problems.append(f"node_id must be a CANopen node id 1-127 (got {node!r})")
    for key in ("interface", "channel"):
        if key in options and not (isinstance(options[key], str) and options[key]):
            problems.append(f"{key} must be a name such as socketcan, can0 (got {options[key]!r})")
    eds = options.get("eds")
    if eds is not None and not (isinstance(eds, str) and Path(eds).is_file()):
        problems.append(f"eds must be the path of an EDS file that exists (got {eds!r})")
    bitrate = options.get("bitrate")
    if bitrate is not None and not (isinstance(bitrate, int) and bitrate > 0):
        problems.append(f"bitrate must be bits per second, e.g. 500000 (got {bitrate!r})")
    numbers = ("scale", "speed", "sdo_timeout", "heartbeat_timeout", "stale_after")
    for key in (*numbers, "mode_timeout", "acceleration"):
        v = options.get(key, 1.0)
        if not (finite_number(v) and v > 0):  # an infinite scale or timeout neither
            problems.append(f"{key} must be a number > 0 (got {v!r})")
    reaction = options.get("fault_reaction", 0.0)
    if not (finite_number(reaction) and reaction >= 0):
        problems.append(f"fault_reaction must be seconds >= 0 (got {reaction!r})")
    method = options.get("homing_method", 35)
    if not (type(method) is int and -128 <= method <= 127):
        problems.append(
            f"homing_method must be a 0x6098 method -128..127, e.g. 35 (got {method!r})"
        )
    speeds = options.get("homing_speeds", [1.0, 1.0])
    if not (
        isinstance(speeds, list | tuple)
        and len(speeds) == 2
        and all(finite_number(v) and v > 0 for v in speeds)
    ):
        problems.append(
            "homing_speeds must be two speeds > 0 in units/s, [switch search, zero search] "
            f"(got {speeds!r})"
        )
    window = options.get("window", 0)
    if not (isinstance(window, int) and not isinstance(window, bool) and window >= 0):
        problems.append(f"window must be a number of counts >= 0 (got {window!r})")
    return problems
