"""Who may command a device: one policy, asked at the System's one door (DESIGN.md).

Rules:
1. An :class:`Origin` says where a command comes from: its channel (:data:`CHANNELS`:
   ``stdin``, ``dashboard``, ``opcua``, ``zenoh``, ``link``, ``driver``, ``timer``,
   ``monitor``) and, where the channel authenticates, its principal (the OPC UA
   session's user, the dashboard token's holder, the Zenoh peer, a link's source device
   in one process or its sending node over Zenoh, the device whose driver reports,
   whose state timed out or whose monitor found a fault). ``None`` is an anonymous
   principal. ``link``, ``driver``, ``timer`` and ``monitor`` are the run's own
   (:data:`INTERNAL`): a full queue never refuses them.
2. A policy is a list of grants. A grant names one channel and who on it: ``CHANNEL``
   anyone (anonymous included), ``CHANNEL/*`` any authenticated principal,
   ``CHANNEL/NAME`` that principal; the devices it may command (all by default) and the
   events it may send them (all by default). A command is allowed when a grant of its
   channel covers its principal, device and event.
3. The defaults are what each channel allowed before the policy existed
   (:data:`DEFAULT_GRANTS`): anyone on ``stdin``, ``dashboard`` (it checks its token
   before it posts), ``zenoh``, ``link``, ``driver``, ``timer`` and ``monitor``; on
   ``opcua`` an authenticated user only. A run config's ``commands:`` section replaces
   the grants of the channels it names; a channel it does not name keeps its default.
4. :meth:`Commands.check` raises :class:`CommandRefused` (a ``StatectlError``) saying who
   was refused what, and what to do; the System journals the refusal and changes
   nothing, and each channel answers with its own refusal (OPC UA
   ``BadUserAccessDenied``, HTTP 403).
5. Pure: no I/O. :func:`parse_commands` reads the section from YAML nodes and reports
   every problem as a D540 error with its line.

The section, as a run config writes it::

    commands:
      - {from: opcua/operator, to: Motor, send: [Movement, Initialization]}
      - {from: dashboard, send: [Movement]}
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Final

import yaml

from statectl.kernel.errors import StatectlError
from statectl.kernel.text import shown

__all__ = [
    "ANYONE",
    "AUTHENTICATED",
    "CHANNELS",
    "DEFAULT_GRANTS",
    "GRANT_KEYS",
    "INTERNAL",
    "CommandRefused",
    "Commands",
    "Grant",
    "Origin",
    "parse_commands",
]

#: The channels a command can come through (rule 1).
CHANNELS: Final = ("stdin", "dashboard", "opcua", "zenoh", "link", "driver", "timer", "monitor")
#: The channels that are the run itself (rule 1): a cell's links, drivers' completions,
#: state timeouts and monitors' faults.
INTERNAL: Final = frozenset({"link", "driver", "timer", "monitor"})
#: A grant's principal: anyone on the channel, anonymous included (``from: CHANNEL``); no
#: principal is named so (an empty name is refused).
ANYONE: Final = ""
#: A grant's principal: anyone the channel authenticated (``from: CHANNEL/*``).
AUTHENTICATED: Final = "*"
#: The keys of a grant in the ``commands:`` section.
GRANT_KEYS: Final = ("from", "to", "send")
_EXAMPLE = "write '- {from: opcua/operator, to: Motor, send: [Movement]}'"


class CommandRefused(StatectlError):
    """A command its origin may not send (rule 4)."""


@dataclass(frozen=True, slots=True)
class Origin:
    """Where a command comes from: a channel and, if it authenticated one, a principal."""

    channel: str
    principal: str | None = None

    def __post_init__(self) -> None:
        if self.channel not in CHANNELS:
            raise StatectlError(
                f"unknown command channel {self.channel!r}; channels: {', '.join(CHANNELS)}"
            )

    def __str__(self) -> str:
        who = self.principal
        return f"{self.channel} (anonymous)" if who is None else f"{self.channel} {_shown(who)}"


@dataclass(frozen=True, slots=True)
class Grant:
    """Rule 2: ``principal`` (a name, :data:`ANYONE` or :data:`AUTHENTICATED`) on ``channel``
    may send ``events`` (None: all) to ``devices`` (None: all)."""

    channel: str
    principal: str = ANYONE
    devices: frozenset[str] | None = None
    events: frozenset[str] | None = None
    where: str = ""  # where it was granted: a file and line, "the defaults", or "" (code)

    def covers(self, principal: str | None, device: str, event: str) -> bool:
        who = self.principal
        if who != ANYONE and (principal is None or (who != AUTHENTICATED and who != principal)):
            return False
        return (self.devices is None or device in self.devices) and (
            self.events is None or event in self.events
        )

    def __str__(self) -> str:
        who = {ANYONE: "", AUTHENTICATED: "/*"}.get(self.principal, f"/{_shown(self.principal)}")
        to = "any device" if self.devices is None else ", ".join(sorted(self.devices))
        send = "any event" if self.events is None else ", ".join(sorted(self.events))
        said = f"{self.channel}{who} may send {send} to {to}"
        return f"{said} ({self.where})" if self.where else said


def _everything(g: Grant) -> bool:
    return g.principal == ANYONE and g.devices is None and g.events is None


def _shown(name: str) -> str:
    """A principal's name as a message shows it: as it is when printable, else escaped by
    the one display escape (kernel/text.py) and quoted, so the escape is seen as one."""
    return name if name.isprintable() else f"'{shown(name)}'"


#: Rule 3: what each channel allowed before there was a policy.
DEFAULT_GRANTS: Final = tuple(
    Grant(c, AUTHENTICATED if c == "opcua" else ANYONE, where="the defaults") for c in CHANNELS
)


class Commands:
    """The commands policy (rules 2-4): the grants by channel, the defaults where none."""

    __slots__ = ("_by_channel", "_open", "configured")

    def __init__(self, grants: Iterable[Grant] = ()) -> None:
        given = tuple(grants)
        #: whether a ``commands:`` section gave any grant (else every channel's default)
        self.configured = bool(given)
        named = {g.channel for g in given}
        by_channel: dict[str, list[Grant]] = {c: [] for c in CHANNELS}
        for g in (*given, *(d for d in DEFAULT_GRANTS if d.channel not in named)):
            by_channel[g.channel].append(g)
        self._by_channel = {c: tuple(gs) for c, gs in by_channel.items()}
        self._open = frozenset(c for c, gs in by_channel.items() if any(map(_everything, gs)))

    def open_to_all(self, channel: str) -> bool:
        """Whether anyone on ``channel`` may send anything anywhere: the door need not ask
        (a cell's links, drivers' completions, timeouts and faults by default, on the
        hot path)."""
        return channel in self._open

    def grants(self, channel: str) -> tuple[Grant, ...]:
        """The grants in force for ``channel``."""
        return self._by_channel.get(channel, ())

    def allows(self, origin: Origin, device: str, event: str) -> bool:
        """Whether a grant of ``origin``'s channel covers this command (rule 2)."""
        channel = origin.channel
        if channel in self._open:  # anyone may send anything there: nothing to walk
            return True
        principal = origin.principal
        return any(g.covers(principal, device, event) for g in self.grants(channel))

    def check(self, origin: Origin, device: str, event: str) -> None:
        """Raise :class:`CommandRefused` unless ``origin`` may send ``event`` to ``device``."""
        if not self.allows(origin, device, event):
            raise self.refusal(origin, device, event)

    def refusal(self, origin: Origin, device: str, event: str) -> CommandRefused:
        """Rule 4: the refusal, saying what is granted on the channel and what to do."""
        held = "; ".join(str(g) for g in self.grants(origin.channel)) or "nothing is granted"
        return CommandRefused(
            f"{device}: {event} refused: {origin} may not send it (commands policy: {held}); "
            "grant it in the run config's commands: section, or send it as someone who may"
        )

    def check_names(self, events: Mapping[str, Iterable[str]]) -> None:
        """Refuse grants naming a device the run lacks, or an event none of its devices
        has: a misspelt grant would refuse silently what it meant to allow."""
        problems = []
        for gs in self._by_channel.values():
            for g in gs:
                at = g.where or f"grant '{g}'"
                for d in sorted(g.devices or ()):
                    if d not in events:
                        problems.append(f"{at}: no device {d!r}; devices: {', '.join(events)}")
                scope = [events[d] for d in (g.devices or events) if d in events]
                known = {e for es in scope for e in es}
                for e in sorted(g.events or ()):
                    if e not in known:
                        problems.append(f"{at}: no device it names has an event {e!r}")
        if problems:
            raise StatectlError(f"commands: {'; '.join(problems)}")


def parse_commands(
    node: yaml.Node,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: Callable[[str, int | None, str, str], None],
    file: str = "",
) -> Commands:
    """The run config's ``commands:`` section (rule 5): a list of grants; problems are D540."""
    if not isinstance(node, yaml.SequenceNode):
        error("D540", line_of(node), "'commands' must be a list of grants", _EXAMPLE)
        return Commands()
    grants = []
    for entry in node.value:
        grant = _grant(entry, value, line_of, error, file)
        if grant is not None:
            grants.append(grant)
    return Commands(grants)


def _grant(
    node: yaml.Node,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: Callable[[str, int | None, str, str], None],
    file: str,
) -> Grant | None:
    line = line_of(node)
    if not isinstance(node, yaml.MappingNode):
        error("D540", line, "commands: a grant must be a mapping", _EXAMPLE)
        return None
    fields = {str(value(k)): (k, v) for k, v in node.value}
    bad = False
    for name, (k, _) in fields.items():
        if name not in GRANT_KEYS:
            error("D540", line_of(k), f"commands: unknown key {name!r}",
                  f"a grant has {', '.join(GRANT_KEYS)}")  # fmt: skip
            bad = True
    if "from" not in fields:
        error("D540", line, "commands: a grant needs 'from' (CHANNEL or CHANNEL/PRINCIPAL)",
              _EXAMPLE)  # fmt: skip
        return None
    who = value(fields["from"][1])
    channel, _, principal = who.partition("/") if isinstance(who, str) else ("", "", "")
    if channel not in CHANNELS or (isinstance(who, str) and "/" in who and not principal):
        error("D540", line_of(fields["from"][1]),
              f"commands: from must be CHANNEL, CHANNEL/* or CHANNEL/NAME (got {who!r})",
              f"channels: {', '.join(CHANNELS)}")  # fmt: skip
        return None
    devices = _names(fields, "to", value, line_of, error)
    events = _names(fields, "send", value, line_of, error)
    if bad or isinstance(devices, bool) or isinstance(events, bool):
        return None
    where = f"{file}:{line}" if file else f"line {line}"
    return Grant(channel, principal or ANYONE, devices, events, where)


def _names(
    fields: dict[str, tuple[yaml.Node, yaml.Node]],
    key: str,
    value: Callable[[yaml.Node], Any],
    line_of: Callable[[yaml.Node], int],
    error: Callable[[str, int | None, str, str], None],
) -> frozenset[str] | bool | None:
    """A grant's ``to`` or ``send``: a name or a list of names; None (all) when absent or
    ``'*'``; False after reporting a problem."""
    if key not in fields:
        return None
    node = fields[key][1]
    raw = value(node)
    listed = [raw] if isinstance(raw, str) else raw
    if not (isinstance(listed, list) and listed and all(isinstance(n, str) and n for n in listed)):
        what = "devices" if key == "to" else "events"
        error("D540", line_of(node), f"commands: {key} must name {what}, one or a list "
              f"(got {raw!r})", "'*' (or leaving it out) means all")  # fmt: skip
        return False
    return None if "*" in listed else frozenset(listed)
