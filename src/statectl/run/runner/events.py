"""Event lines (``[DEVICE:] EVENT [DATA]``, ``+SECONDS``) and times, as runs read them.

Kept apart from the commands so the grammar of a line is in one small place
that tests and the dashboard can use without the run's machinery."""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

from statectl.front.tables import safeyaml
from statectl.kernel.errors import StatectlError


def parse_event_line(line: str) -> tuple[str | None, str, Any] | float | None:
    """``[DEVICE:] EVENT [DATA]`` -> (device, event, data); ``+S`` -> seconds; blank -> None."""
    text = line.split("#", 1)[0].strip()
    if not text:
        return None
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:  # bytes stdin could not decode, kept as surrogates
        bad = text[exc.start]
        byte = ord(bad) - 0xDC00 if 0xDC80 <= ord(bad) <= 0xDCFF else None
        what = f"byte 0x{byte:02x}" if byte is not None else repr(bad)
        raise StatectlError(
            f"the line is not UTF-8 text ({what} at column {exc.start + 1}); "
            "write event lines in UTF-8"
        ) from None
    if text.startswith("+"):
        try:
            seconds = float(text[1:])
        except ValueError:
            raise StatectlError(f"'+' needs seconds, e.g. '+1.5' (got {text!r})") from None
        if not 0 <= seconds < math.inf:
            raise StatectlError(
                f"'+' needs a finite number of seconds, 0 or more, e.g. '+1.5' (got {text!r})"
            )
        return seconds
    device = None
    head, colon, rest = text.partition(":")
    if colon and "{" not in head and "[" not in head and rest.startswith(" "):
        device, text = head.strip(), rest.strip()
    data: Any = None
    brace = min((i for i in (text.find("{"), text.find("[")) if i >= 0), default=-1)
    if brace >= 0:
        try:
            data = safeyaml.load_value(text[brace:])
        except safeyaml.YamlRefused as exc:
            raise StatectlError(f"event data is not YAML flow style ({exc.message})") from None
        text = text[:brace]
    event = " ".join(text.split())
    if not event:
        raise StatectlError("no event name")
    return device, event, data


def parse_time(text: str) -> float:
    """Seconds since the epoch, or an ISO 8601 date-time (local time if it has no zone)."""
    try:
        seconds = float(text)
    except ValueError:
        pass
    else:
        if math.isnan(seconds):  # every comparison with it is false: the window holds nothing
            raise StatectlError(f"not a time: {text!r}; give seconds since the epoch or ISO 8601")
        return seconds
    try:
        return dt.datetime.fromisoformat(text).timestamp()
    except ValueError:
        raise StatectlError(
            f"not a time: {text!r}; give seconds since the epoch or ISO 8601 (2024-05-01T12:00:00)"
        ) from None
