"""A cell's values: devices, links, environment inputs, invariants, recovery goals and
the Cell that holds them, plus the V8xx codes. Split from the loader so the explorer,
the SPIN writer and the runner import the values without the YAML reading.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from statectl.kernel.codes import family
from statectl.kernel.errors import Location
from statectl.kernel.model import Chart

if TYPE_CHECKING:
    from statectl.cell.nodes import Nodes

#: Code -> one-line summary of every V8xx code (a view of statectl.kernel.codes.REGISTRY).
CODES: Mapping[str, str] = family("V8")

TOP_KEYS = (
    *("cell", "devices", "links", "environment", "invariants", "recovery", "completions"),
    "nodes",  # cell/nodes.py: which device runs in which process
    "security",  # cell/security.py: TLS, users, who may publish what over Zenoh
)


class Trigger(enum.Enum):
    ENTERS = "enters"  # the source device entered a state
    RAISES = "raises"  # the source device took a transition on an event


class InputKind(enum.Enum):
    COMMAND = "environment"  # the operator or a sensor sends it
    FAULT = "fault"  # hardware raises it in a monitored state
    COMPLETION = "completion"  # the device reports it back itself
    PEER_LOST = "peer lost"  # a node the device is linked with was lost (nodes:)


@dataclass(frozen=True, slots=True)
class GlobalExpr:
    """A checked global expression and the ``(device, state)`` pairs it reads."""

    source: str
    refs: tuple[tuple[str, str], ...]
    where: Location


@dataclass(frozen=True, slots=True)
class DeviceRef:
    name: str
    path: str
    chart: Chart
    where: Location


@dataclass(frozen=True, slots=True)
class Link:
    """``when source <trigger> what [guard]: send event to target``."""

    source: str
    trigger: Trigger
    what: str
    target: str
    event: str
    guard: GlobalExpr | None
    where: Location
    #: constant event data the link sends (``send: Reset {status: true}``), if any
    data: Any = None
    #: send the triggering step's event data on (``forward_data: true``)
    forward_data: bool = False
    #: the event is harmless where it lands unhandled: verify does not report it
    ignore_if_unhandled: bool = False
    #: ``lossy: true``: verify explores the event lost on the way
    lossy: bool = False
    #: ``delayed: true``: verify explores the event overtaken by later link events
    delayed: bool = False

    @property
    def label(self) -> str:
        text = f"{self.source} {self.trigger.value} {self.what} -> {self.target}.{self.event}"
        if self.guard is not None:
            text += f" [{self.guard.source}]"
        return text


@dataclass(frozen=True, slots=True)
class EnvInput:
    kind: InputKind
    device: str
    event: str
    when: GlobalExpr | None
    where: Location


@dataclass(frozen=True, slots=True)
class Invariant:
    name: str
    expr: GlobalExpr
    #: ``on_violation``: (device, event) sent when a run sees the invariant turn false
    on_violation: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True, slots=True)
class RecoveryGoal:
    """A cell's recovery goal (its ``recovery:``), a property verify checks: from every
    reachable state where ``source`` holds, some path must reach ``target``. Not a device's
    Recovery table (``front/recovery.py``), which says what a restarted device does first."""

    name: str
    target: GlobalExpr
    source: GlobalExpr | None


@dataclass(frozen=True, slots=True)
class Cell:
    name: str
    path: str
    devices: tuple[DeviceRef, ...]
    links: tuple[Link, ...] = ()
    environment: tuple[EnvInput, ...] = ()
    invariants: tuple[Invariant, ...] = ()
    recovery: tuple[RecoveryGoal, ...] = ()
    completions: bool = True
    nodes: Nodes | None = None  # cell/nodes.py; None: one process

    def device(self, name: str) -> DeviceRef:
        for d in self.devices:
            if d.name == name:
                return d
        raise KeyError(name)
