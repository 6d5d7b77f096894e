"""What a cell's ``nodes:`` section adds to verification: peers lost, link events dropped.

Rules:
1. Without ``nodes:`` (``cell.nodes`` absent or ``None``) nothing is added.
2. A device that a node's ``peer_lost`` names, and that is linked (a link in either
   direction) with a device on another node, may receive its peer-lost event at any
   point: one stimulus per device and event (kind ``peer lost``), offered in every
   global state, as each node notices a lost peer on its own.
3. A link between two nodes with ``on_peer_down: drop`` may lose its event (the peer
   was down when it was sent); its ``dropped`` event, if any, then goes to the link's
   source device in its place in the cascade. ``queue`` links deliver in order once the peer
   is back, which the cascade already assumes.
4. The section is read duck-typed (``nodes.nodes``: name, devices, peer_lost;
   ``nodes.delivery``: on_peer_down, dropped, one per link), so this module does not
   depend on how :mod:`statectl.cell.nodes` is written beyond those names.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from statectl.cell.model import Cell

__all__ = ["crossing", "peer_lost"]


def _nodes(cell: Cell) -> Any:
    return getattr(cell, "nodes", None)


def crossing(
    cell: Cell, position: Mapping[str, int]
) -> tuple[dict[str, str], dict[int, tuple[int, str] | None]]:
    """Each device's node, and rule 3's links: index -> (source position, dropped event)."""
    nodes = _nodes(cell)
    if nodes is None:
        return {}, {}
    node_of = {d: n.name for n in nodes.nodes for d in n.devices}
    dropped: dict[int, tuple[int, str] | None] = {}
    for i, (k, how) in enumerate(zip(cell.links, nodes.delivery, strict=False)):
        if node_of.get(k.source) == node_of.get(k.target):
            continue
        if getattr(how.on_peer_down, "value", how.on_peer_down) != "drop":
            continue
        event = how.dropped
        dropped[i] = (position[k.source], str(event)) if event else None
    return node_of, dropped


def peer_lost(
    cell: Cell, position: Mapping[str, int], node_of: Mapping[str, str]
) -> list[tuple[int, str]]:
    """Rule 2's stimuli as (device position, event), in the nodes' order."""
    nodes = _nodes(cell)
    if nodes is None:
        return []
    out: list[tuple[int, str]] = []
    for n in nodes.nodes:
        for device, event in n.peer_lost:
            here = node_of.get(device)
            linked = any(
                (k.source == device and node_of.get(k.target) != here)
                or (k.target == device and node_of.get(k.source) != here)
                for k in cell.links
            )
            if linked:
                out.append((position[device], event))
    return out
