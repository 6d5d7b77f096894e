"""The Zenoh key expressions of a cell, all under ``statectl/<cell>/`` (docs/distributed.md).

One function per kind of message, so the keys are written in one place:

| key | payload | who puts it |
|---|---|---|
| ``statectl/<cell>/node/<node>`` | liveliness token | each node while it runs |
| ``statectl/<cell>/link/<from-node>/<device>`` | ``[e, n, ev, d]`` link event | sending node |
| ``statectl/<cell>/ack/<from-node>/<device>`` | ``{e, n, r}`` how far it got | the receiving node |
| ``statectl/<cell>/hello/<from-node>/<device>`` | ``{e}`` asks for an ack | the sending node |
| ``statectl/<cell>/state/<device>`` | the device's snapshot | its node, after a change |
| ``statectl/<cell>/post/<device>`` | ``{ev, d}`` an operator's event | a node or a dashboard |
"""

from __future__ import annotations

import re

__all__ = ["Keys"]

_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]")


class Keys:
    """The key expressions of one cell (its name made safe for Zenoh: ``*$?#/`` become ``_``)."""

    def __init__(self, cell: str) -> None:
        self.root = f"statectl/{_UNSAFE.sub('_', cell) or '_'}"

    def node(self, name: str) -> str:
        return f"{self.root}/node/{name}"

    def link(self, source_node: str, device: str) -> str:
        return f"{self.root}/link/{source_node}/{device}"

    def ack(self, source_node: str, device: str) -> str:
        return f"{self.root}/ack/{source_node}/{device}"

    def hello(self, source_node: str, device: str) -> str:
        return f"{self.root}/hello/{source_node}/{device}"

    def state(self, device: str) -> str:
        return f"{self.root}/state/{device}"

    def post(self, device: str) -> str:
        return f"{self.root}/post/{device}"

    @staticmethod
    def last(key: str) -> tuple[str, str]:
        """The last two parts of a key: (node or kind, device or node)."""
        parts = str(key).rsplit("/", 2)
        return parts[-2], parts[-1]
