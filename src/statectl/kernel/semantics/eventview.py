"""``_event`` as a device table's guard and assignment read it, and a guard that fails.

Rules:
1. A guard reads the event's data as ``_event.data.pressure`` (the spelling
   SCXML documents use); ``_event['data']['pressure']`` reads the same field.
   ``_event.name`` (or ``_event['name']``) is the event's name. Data that is a
   mapping is a read-only :class:`Record`; a plain value (a number, a text) is
   itself, so ``_event.data == 'fast'`` works too.
2. A record has no methods a guard could reach: ``_event.data.keys`` is the
   field ``keys``, not the dict method; a missing field raises
   :class:`AttributeError` naming the fields the event did carry.
3. A guard that raises while it is evaluated is no silent "false": the step is
   not taken, the kernel returns it as :attr:`Unhandled.GUARD_ERROR` with a
   :class:`GuardFailure` naming the row (file:line), and the host reports it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from statectl.kernel.errors import Location, UnhandledEventError

__all__ = ["EventView", "GuardError", "GuardFailure", "Record", "event_view"]


class Record:
    """A read-only view of a mapping whose keys read as attributes or items (rule 2)."""

    __slots__ = ("_values",)

    def __init__(self, values: Mapping[str, Any]) -> None:
        object.__setattr__(self, "_values", values)

    def __getattr__(self, name: str) -> Any:
        values: Mapping[str, Any] = object.__getattribute__(self, "_values")
        try:
            return _view(values[name])
        except KeyError:
            carried = ", ".join(sorted(map(str, values))) or "none"
            raise AttributeError(
                f"the event data has no field {name!r} (it has: {carried})"
            ) from None

    def __getitem__(self, key: Any) -> Any:
        values: Mapping[str, Any] = object.__getattribute__(self, "_values")
        if key not in values:
            carried = ", ".join(sorted(map(str, values))) or "none"
            raise KeyError(f"the event data has no field {key!r} (it has: {carried})")
        return _view(values[key])

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("event data is read-only")

    def __contains__(self, key: object) -> bool:
        return key in object.__getattribute__(self, "_values")

    def __iter__(self) -> Iterator[Any]:
        return iter(object.__getattribute__(self, "_values"))

    def __len__(self) -> int:
        return len(object.__getattribute__(self, "_values"))

    def __eq__(self, other: object) -> bool:
        mine = object.__getattribute__(self, "_values")
        if isinstance(other, Record):
            return bool(mine == object.__getattribute__(other, "_values"))
        return bool(mine == other)

    def __hash__(self) -> int:
        return id(self)

    def __repr__(self) -> str:
        return repr(object.__getattribute__(self, "_values"))


def _view(value: Any) -> Any:
    return Record(value) if isinstance(value, Mapping) else value


class EventView:
    """``_event``: ``name`` and ``data`` as attributes, or as items (rule 1)."""

    __slots__ = ("data", "name")

    def __init__(self, name: str | None, data: Any) -> None:
        self.name = name
        self.data = _view(data)

    def __getitem__(self, key: str) -> Any:
        if key == "name":
            return self.name
        if key == "data":
            return self.data
        raise KeyError(f"_event has only 'name' and 'data' (got {key!r}); read _event.data.{key}")

    def __repr__(self) -> str:
        return f"_event(name={self.name!r}, data={self.data!r})"


def event_view(name: str | None, data: Any) -> EventView:
    return EventView(name, data)


@dataclass(frozen=True, slots=True)
class GuardFailure:
    """A guard that raised instead of answering: which, where, for which event, why."""

    guard: str
    event: str | None
    origin: Location
    reason: str

    def message(self, device: str) -> str:
        where = f"{self.origin}: " if self.origin.file or self.origin.line else ""
        reason = self.reason
        if "'NoneType' object" in reason:
            reason += " (the event was sent without data)"
        return (
            f"{where}{device}: the guard {self.guard!r} of event {self.event!r} failed: "
            f"{reason}; the event was not taken (read event data as _event.data.NAME, "
            "and send the fields the event declares)"
        )


class GuardError(UnhandledEventError):
    """A guard failed at run time: the event was refused, with the row's file:line."""
