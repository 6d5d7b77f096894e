"""A cell's ``nodes:`` section: which devices run in which process, and how links cross.

Rules:
1. ``nodes`` maps a node name to ``devices`` (a list of the cell's instances),
   the node's Zenoh endpoints ``listen`` and ``connect`` (lists of locators such
   as ``tcp/127.0.0.1:7447``), ``lease`` (seconds, default 1.0: how soon the other
   nodes notice that this one is cut off) and ``peer_lost`` (a mapping of a
   device on this node to the event it receives when a node it is linked with is
   lost). Every device of the cell runs on exactly one node (V820).
2. A link may say what happens to its events while the target's node is down:
   ``on_peer_down: queue`` (default: kept until the node is back, then delivered
   once and in order) or ``drop`` (discarded; ``dropped: EVENT``, if given, is
   sent to the link's source device instead).
3. Without ``nodes`` nothing changes: one process. ``on_peer_down``/``dropped``
   there are checked but have no effect (V826, a warning).
4. This module only reads; :mod:`statectl.channels.distributed` runs nodes. The values are
   frozen and aligned with ``Cell.links`` (``Nodes.delivery[i]`` is link ``i``'s),
   so ``verify`` can read them as well.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import yaml

from statectl.cell.expressions import _d
from statectl.cell.security import OPEN, Security
from statectl.kernel.errors import Diagnostic, Location, Severity
from statectl.kernel.model import Chart

__all__ = [
    "DEFAULT_LEASE",
    "LINK_KEYS",
    "NODE_KEYS",
    "LinkDelivery",
    "Node",
    "Nodes",
    "PeerDown",
    "endpoint_problem",
]

#: The keys a link may carry for distribution (the link reader accepts them).
LINK_KEYS = ("on_peer_down", "dropped")
NODE_KEYS = ("devices", "listen", "connect", "lease", "peer_lost")
#: Seconds after which a node that stopped answering counts as lost (Zenoh's lease).
DEFAULT_LEASE = 1.0


class PeerDown(enum.Enum):
    QUEUE = "queue"  # keep the link's events until the target's node is back
    DROP = "drop"  # discard them (and send the declared event to the source)


@dataclass(frozen=True, slots=True)
class Node:
    name: str
    devices: tuple[str, ...]
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    lease: float = DEFAULT_LEASE
    #: (device on this node, event) sent when a node linked with the device is lost
    peer_lost: tuple[tuple[str, str], ...] = ()
    where: Location | None = None


@dataclass(frozen=True, slots=True)
class LinkDelivery:
    """What a link does while its target's node is down (rule 2)."""

    on_peer_down: PeerDown = PeerDown.QUEUE
    dropped: str | None = None


@dataclass(frozen=True, slots=True)
class Nodes:
    nodes: tuple[Node, ...]
    delivery: tuple[LinkDelivery, ...]  # one per link of the cell, in its order
    security: Security = OPEN  # the cell's security: section (cell/security.py)

    def node(self, name: str) -> Node:
        for n in self.nodes:
            if n.name == name:
                return n
        raise KeyError(name)

    def node_of(self, device: str) -> str:
        for n in self.nodes:
            if device in n.devices:
                return n.name
        raise KeyError(device)


def read_nodes(
    r: Any, node: yaml.Node | None, links: yaml.Node | None, charts: Mapping[str, Chart]
) -> Nodes | None:
    """The ``nodes`` section and the links' delivery keys; None without ``nodes`` (rule 3)."""
    delivery = _delivery(r, links, charts, distributed=node is not None)
    if node is None:
        return None
    if not isinstance(node, yaml.MappingNode) or not node.value:
        r.diags.append(
            _d("V804", r.at(node), "nodes must be a mapping of node name: {devices: [...]}")
        )
        return None
    out: list[Node] = []
    placed: dict[str, str] = {}
    for k, v in node.value:
        name = str(k.value) if isinstance(k, yaml.ScalarNode) else ""
        if not name.isidentifier() or any(n.name == name for n in out):
            r.diags.append(
                _d(
                    "V821",
                    r.at(k),
                    f"node name {name!r} is not an identifier or is used twice",
                    "node names appear in Zenoh key expressions: letters, digits and '_'",
                )
            )
            continue
        f = r.mapping(v, f"node {name!r}", NODE_KEYS, ("devices",))
        if f is None:
            continue
        devices = _names(r, f.get("devices"), f"node {name!r} devices")
        for d in devices:
            if d not in charts:
                r.diags.append(
                    _d(
                        "V807",
                        r.at(f["devices"]),
                        f"node {name!r}: no device named {d!r}",
                        "devices: " + ", ".join(sorted(charts)),
                    )
                )
            elif d in placed:
                r.diags.append(
                    _d(
                        "V820",
                        r.at(f["devices"]),
                        f"device {d!r} is on two nodes ({placed[d]!r} and {name!r})",
                        "a device runs in exactly one process",
                    )
                )
            else:
                placed[d] = name
        listen = _endpoints(r, f.get("listen"), f"node {name!r} listen")
        connect = _endpoints(r, f.get("connect"), f"node {name!r} connect")
        lease = _lease(r, f.get("lease"), name)
        lost = _peer_lost(r, f.get("peer_lost"), name, devices, charts)
        out.append(Node(name, tuple(devices), listen, connect, lease, lost, r.at(k)))
    unplaced = [d for d in charts if d not in placed]
    if unplaced and out:
        r.diags.append(
            _d(
                "V820",
                r.at(node),
                f"device(s) {', '.join(unplaced)} run on no node",
                "add each device to the devices of one node",
            )
        )
    return Nodes(tuple(out), tuple(delivery))


def _names(r: Any, node: yaml.Node | None, what: str) -> list[str]:
    out = []
    for item in r.items(node, what):
        text = r.text(item, what)
        if text is not None:
            out.append(text)
    return out


def _endpoints(r: Any, node: yaml.Node | None, what: str) -> tuple[str, ...]:
    out = []
    for item in r.items(node, what):
        text = r.text(item, what)
        if text is None:
            continue
        problem = endpoint_problem(text, connect=what.endswith("connect"))
        if problem is not None:
            r.diags.append(
                _d(
                    "V822",
                    r.at(item),
                    f"{what}: {text!r} {problem}",
                    "write PROTOCOL/HOST:PORT, e.g. tcp/127.0.0.1:7447",
                )
            )
            continue
        out.append(text)
    return tuple(out)


#: Zenoh's protocols over IP, whose locators end in ``:PORT``.
_IP_PROTOCOLS = frozenset({"tcp", "udp", "tls", "quic", "ws"})


def endpoint_problem(text: str, *, connect: bool) -> str | None:
    """What is wrong with a Zenoh endpoint ``PROTOCOL/ADDRESS``, or ``None``.

    Over IP the port of ``HOST:PORT[?metadata][#config]`` is checked here, when the
    file or the command line is read, rather than by Zenoh when the node opens.
    """
    proto, _, address = text.partition("/")
    if not proto or not address or ":" not in address:
        return "is not a Zenoh endpoint"
    if proto not in _IP_PROTOCOLS:
        return None
    port = address.split("#", 1)[0].split("?", 1)[0].rpartition(":")[2]
    lowest = 1 if connect else 0  # listening on port 0 takes any free port
    if (
        not (port.isascii() and port.isdigit() and len(port) <= 5)
        or not lowest <= int(port) <= 65535
    ):
        return f"has port {port!r}: a port is a number from {lowest} to 65535"
    return None


def _lease(r: Any, node: yaml.Node | None, name: str) -> float:
    if node is None:
        return DEFAULT_LEASE
    text = r.text(node, f"node {name!r} lease")
    try:
        value = float(text) if text is not None else 0.0
    except ValueError:
        value = 0.0
    if not 0.05 <= value <= 3600:
        r.diags.append(
            _d(
                "V804",
                r.at(node),
                f"node {name!r}: lease must be seconds between 0.05 and 3600 (got {text!r})",
                "e.g. lease: 0.5",
            )
        )
        return DEFAULT_LEASE
    return value


def _peer_lost(
    r: Any, node: yaml.Node | None, name: str, devices: list[str], charts: Mapping[str, Chart]
) -> tuple[tuple[str, str], ...]:
    if node is None:
        return ()
    if not isinstance(node, yaml.MappingNode):
        r.diags.append(_d("V804", r.at(node), "peer_lost must be a mapping of device: event"))
        return ()
    out = []
    for k, v in node.value:
        device = str(k.value) if isinstance(k, yaml.ScalarNode) else ""
        event = r.text(v, f"node {name!r} peer_lost {device!r}")
        if device not in devices:
            r.diags.append(
                _d(
                    "V825",
                    r.at(k),
                    f"node {name!r}: peer_lost names {device!r}, which does not run on it",
                    "devices of this node: " + ", ".join(devices),
                )
            )
            continue
        if event is None or device not in charts:
            continue
        if event not in charts[device].event_names:
            r.diags.append(
                _d(
                    "V809",
                    r.at(v),
                    f"peer_lost: device {device!r} has no event {event!r}",
                    "events: " + ", ".join(charts[device].event_names),
                )
            )
            continue
        out.append((device, event))
    return tuple(out)


def _delivery(
    r: Any, links: yaml.Node | None, charts: Mapping[str, Chart], *, distributed: bool
) -> list[LinkDelivery]:
    """Each link's ``on_peer_down``/``dropped`` (rule 2), in the links' order."""
    out: list[LinkDelivery] = []
    if links is None or not isinstance(links, yaml.SequenceNode):
        return out
    for item in links.value:
        if not isinstance(item, yaml.MappingNode):
            out.append(LinkDelivery())
            continue
        f = {str(k.value): v for k, v in item.value if isinstance(k, yaml.ScalarNode)}
        policy = PeerDown.QUEUE
        if "on_peer_down" in f:
            text = r.text(f["on_peer_down"], "link on_peer_down")
            try:
                policy = PeerDown(text)
            except ValueError:
                r.diags.append(
                    _d(
                        "V823",
                        r.at(f["on_peer_down"]),
                        f"on_peer_down must be queue or drop (got {text!r})",
                    )
                )
        dropped = r.text(f["dropped"], "link dropped") if "dropped" in f else None
        if dropped is not None and policy is not PeerDown.DROP:
            r.diags.append(
                _d(
                    "V824",
                    r.at(f["dropped"]),
                    "'dropped' names the event sent when a link drops, so it needs "
                    "on_peer_down: drop",
                )
            )
        where = f.get("from")
        source = str(where.value) if isinstance(where, yaml.ScalarNode) else ""
        if dropped is not None and source in charts and dropped not in charts[source].event_names:
            r.diags.append(
                _d(
                    "V809",
                    r.at(f["dropped"]),
                    f"link dropped: device {source!r} has no event {dropped!r}",
                    "events: " + ", ".join(charts[source].event_names),
                )
            )
        if not distributed and ("on_peer_down" in f or "dropped" in f):
            r.diags.append(
                Diagnostic(
                    "V826",
                    Severity.WARNING,
                    r.at(item),
                    "on_peer_down and dropped take effect only when the cell has nodes:",
                    "add a nodes: section, or remove them",
                )
            )
        out.append(LinkDelivery(policy, dropped))
    return out
