"""One node's System: its own devices, the links to devices on other nodes handed to a wire.

Rules:
1. A :class:`NodeSystem` is a :class:`~statectl.run.system.System` of the node's
   devices only. Links whose target runs here are sent as in one process; links
   to a device on another node go to the :class:`Wire` (statectl.channels.distributed.wire).
2. A link's guard is evaluated where its source runs, over the node's own devices
   and the last state each other node published of its devices (their *mirror*),
   so a guard over a remote device reads that device as of its last publication.
3. With a journal a link event to another node is accepted with the step that
   fired it, in one commit (the journal's rule 6), as an inbox row of the remote
   device in this node's journal: that row is the event's place in its stream, so
   a resumed node sends again exactly what its journal holds.
4. A ``drop`` link whose target's node is down sends nothing; the link's
   ``dropped`` event, if declared, goes to the source device instead (journalled
   with the step, like a link event).
5. An event posted for a device on another node (an operator's line, the
   dashboard) is forwarded to that node, once, without a journal on this side.
6. A node holds the cell to what verify assumes, as ``statectl run CELL`` does
   (statectl.run.system rule 6), over what it sees: its own devices and the last
   published state of the others (a device never published reads as its initial
   state). An environment command for a device of this node whose every ``when``
   is false is refused; a device guard ``In('other.State')`` reads the other
   device, here or mirrored; each invariant is watched by one node, the node of
   the first device (in the cell's ``devices:`` order) it reads, after every step
   of its devices and whenever a mirrored state changes, and its ``on_violation``
   events go to their devices, here or over the wire.
7. A link event from another node enters at the System's one door like any other
   (``System.submit``, origin ``link`` and the sending node: statectl.run.system
   rule 8), which runs it at once on the thread that received it while nobody owns
   the devices (no hand-over to the owner's thread, whose wake-up after a pause
   costs tens of microseconds), else queues it for the owner, in order. A link
   between two devices of this node passes the same policy check.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any, Protocol, cast

from statectl.cell.explore.conditions import bind_cross_guards
from statectl.cell.explore.enforce import CellRules
from statectl.cell.explore.replay import CellLinks
from statectl.cell.model import Cell, Link
from statectl.cell.nodes import LinkDelivery, PeerDown
from statectl.cell.options import cross_refs
from statectl.kernel.errors import StatectlError
from statectl.kernel.semantics import Outcome, Snapshot
from statectl.run.door import Submitted
from statectl.run.journal import JournalledDevice, Ticket
from statectl.run.runtime import Subject
from statectl.run.system import System

__all__ = ["NodeLinks", "NodeSystem", "RemoteDevice", "WireSide"]


class WireSide(Protocol):
    """What the System needs from the wire (statectl.channels.distributed.wire.Wire)."""

    def down(self, link: Link) -> bool: ...
    def send(self, device: str, event: str, data: Any) -> None: ...
    def forward(self, device: str, event: str, data: Any) -> None: ...


class NodeLinks(CellLinks):
    """A cell's links on one node: the global state reads remote devices from the mirror."""

    def __init__(self, cell: Cell, subjects: Mapping[str, Subject], mirror: dict[str, int]):
        super().__init__(cell, subjects)
        self.mirror = mirror  # device on another node -> local id of its last published state

    def seen(self, name: str) -> int:
        """The local id of a device on another node: its last published state, else initial."""
        lid = self.mirror.get(name)
        if lid is None:
            lid = self.model.local(self.model.initial[0], self.model.position[name])
        return lid

    def state(self) -> int:
        model = self.model
        g = 0
        for d, space in enumerate(model.spaces):
            name = model.names[d]
            subject = self.subjects.get(name)
            lid: int | None
            if subject is None:
                lid = self.seen(name)
            else:
                snap = subject.snapshot
                lid = space.lookup(snap, subject.data) if snap is not None else None
                if lid is None:
                    raise StatectlError(f"{name} is in a state the explorer never saw")
            g = model.replace(g, d, lid)
        return g


class _Mirrored:
    """A device on another node as a guard here reads it (rule 6): its last published state."""

    def __init__(self, links: NodeLinks, name: str) -> None:
        self._links = links
        self._name = name
        self._space = links.model.spaces[links.model.position[name]]

    @property
    def snapshot(self) -> Snapshot | None:
        return self._space.snapshots[self._links.seen(self._name)]


class _Sink(deque[tuple[int, str, Any]]):
    """A remote device's expected events: nothing is processed here, so nothing is kept."""

    def append(self, item: tuple[int, str, Any]) -> None:
        pass


class _Post:
    """A remote device's stand-in Subject: posting sends the event over the wire."""

    def __init__(self, device: str, wire: WireSide) -> None:
        self.device = device
        self.wire = wire

    def post(
        self, event: str, data: Any = None, then: Callable[[str], object] | None = None
    ) -> None:
        self.wire.send(self.device, event, data)


class RemoteDevice(JournalledDevice):
    """A device on another node as a target of this node's journalled link sends (rule 3).

    The journal's hand-over (prompt) or delivery after the commit (durable-first)
    puts the event on the wire, in ``seq`` order, under this stand-in's lock.
    """

    def __init__(self, name: str, wire: WireSide) -> None:  # no Subject, no journal row
        import threading

        self.name = name
        self.wake = None
        self._lock = threading.Lock()
        self._expect = _Sink()
        self.subject = cast(Subject, _Post(name, wire))
        self._wire = wire

    def _deliver(
        self, seq: int, event: str, data: Any, then: Callable[[Outcome], object] | None = None
    ) -> None:
        with self._lock:
            self._wire.send(self.name, event, data)

    def post(
        self,
        event: str,
        data: Any = None,
        *,
        note: tuple[str, str] | None = None,
        then: Callable[[Outcome], object] | None = None,
    ) -> Ticket:
        raise StatectlError(f"{self.name} runs on another node")


_QUEUE = LinkDelivery()  # a link without a delivery policy of its own


class NodeSystem(System):
    """A System of one node's devices (rules 1-5); :meth:`attach` wires its links."""

    def __post_init__(self) -> None:
        cell = self.cell
        self.cell = None  # the links are wired by attach(), once the wire exists
        System.__post_init__(self)
        self.cell = cell
        self._remote: dict[str, RemoteDevice] = {}  # attach() fills it

    def attach(self, wire: WireSide, mirror: dict[str, int]) -> None:
        """Wire the cell's links: local ones as in one process, the others through ``wire``."""
        cell = self.cell
        assert cell is not None and cell.nodes is not None
        self._wire = wire
        # by the link's id: a Link's own hash walks all its fields (the hot path asks per event)
        self._policy: dict[int, LinkDelivery] = {
            id(k): p for k, p in zip(cell.links, cell.nodes.delivery, strict=False)
        }
        self._remote = {
            d.name: RemoteDevice(d.name, wire) for d in cell.devices if d.name not in self.subjects
        }
        #: by the link's id: (its target here or None, may drop?), worked out once (the
        #: hot path of a link event, _link_step)
        self._routes: dict[int, tuple[Subject | None, bool]] = {
            id(k): (
                self.subjects.get(k.target),
                self._policy.get(id(k), _QUEUE).on_peer_down is PeerDown.DROP,
            )
            for k in cell.links
        }
        links = self.links = NodeLinks(cell, self.subjects, mirror)
        seen: dict[str, Any] = {n: _Mirrored(links, n) for n in self._remote}
        seen.update(self.subjects)
        bind_cross_guards(self.subjects, seen)  # rule 6: guards reading another device
        if self.enforce:
            watched = tuple(i for i in cell.invariants if self._watches(i.expr.refs))
            self.rules = CellRules(replace(cell, invariants=watched), links)
        for name, s in self.subjects.items():
            if name in links.rules.sources:  # heard before the step hook that sends the links
                s.listen_steps(links.watch_step)
            if name in self.bound:
                self.bound[name].sends = self._link_sends
            else:
                s.on_step(self._link_step)

    def _watches(self, refs: tuple[tuple[str, str], ...]) -> bool:
        """Rule 6: whether this node watches an invariant reading ``refs``."""
        assert self.cell is not None
        read = {d for d, _ in refs}
        first = next((d.name for d in self.cell.devices if d.name in read), None)
        return first is not None and first in self.subjects

    def reads_remote(self) -> bool:
        """Whether rule 2 or 6 here reads a device on another node (a guard of a link that
        starts here, a when, an invariant, a device guard): the wire mirrors them then."""
        cell = self.cell
        assert cell is not None
        here = self.subjects
        refs: list[tuple[str, str]] = []
        for k in cell.links:
            if k.source in here and k.guard is not None:
                refs.extend(k.guard.refs)
        for e in cell.environment:
            if e.device in here and e.when is not None:
                refs.extend(e.when.refs)
        if self.rules is not None:
            for inv in self.rules.cell.invariants:
                refs.extend(inv.expr.refs)
        for s in here.values():
            refs.extend((d, st) for _, d, st, _ in cross_refs(s.chart))
        return any(d not in here for d, _ in refs)

    def _send(self, device: str, event: str, data: Any = None) -> None:
        """An event to a device here (its queue) or on another node (the wire)."""
        target = self.subjects.get(device)
        if target is not None:
            target.post(event, data)
        else:
            self._wire.send(device, event, data)

    def recheck(self) -> None:
        """Rule 6 when a mirrored state changed: the invariants this node watches, as owner."""
        if self.rules is None or not self._live or not self.rules.watching:
            return
        with self.owner:
            sends = self._violations()
            for device, event in sends:
                bound = self.bound.get(device)
                if bound is not None:
                    bound.post(event)
                else:
                    self._send(device, event)
        if sends:
            self.wake.set()

    def _dropping(self, link: Link) -> bool:
        """A ``drop`` link (its route says so) whose peer is down now."""
        return self._routes[id(link)][1] and self._wire.down(link)

    def _link_step(self, event: str, data: Any, outcome: str) -> None:
        """Rules 1 and 4 without a journal, on the owner after a device's step."""
        assert self.links is not None
        if not self._live:
            self.links.fired.clear()
            return
        routes, links = self._routes, self.links.cell.links
        for send in self.links.sends(data):  # what each sends: statectl.cell.links
            link = links[send.link]
            target = routes[id(link)][0]
            if target is not None:
                if self._link_admitted(link.source, send.target, send.event, send.data):
                    target.post(send.event, send.data)
            elif self._dropping(link):
                dropped = self._policy[id(link)].dropped
                if dropped is not None:
                    self.subjects[link.source].post(dropped)
            else:
                self._wire.send(send.target, send.event, send.data)
        if self.rules is not None and self.rules.watching:
            for device, event in self._violations():
                self._send(device, event)

    def _link_sends(self) -> list[tuple[JournalledDevice, str]]:
        """Rules 1, 3 and 4 with a journal: what the step sends, journalled with it."""
        assert self.links is not None
        if not self._live:
            self.links.fired.clear()
            return []
        out: list[tuple[JournalledDevice, str]] = []
        for link in self.links.due():
            bound = self.bound.get(link.target)
            if bound is not None:
                if self._link_admitted(link.source, link.target, link.event, None):
                    out.append((bound, link.event))
            elif self._dropping(link):
                dropped = self._policy[id(link)].dropped
                if dropped is not None:
                    out.append((self.bound[link.source], dropped))
            else:
                out.append((self._remote[link.target], link.event))
        if self.rules is not None and self.rules.watching:
            for device, event in self._violations():
                out.append((self.bound.get(device) or self._remote[device], event))
        return out

    def post(self, device: str | None, event: str, data: Any = None, **how: Any) -> Ticket | None:
        """Rule 5: an event for a device on another node is forwarded there."""
        if device in self._remote:
            self._wire.forward(device, event, data)
            return None
        return System.post(self, device, event, data, **how)  # how: the origin (run/commands.py)

    def submit(self, device: str | None, event: str, data: Any = None, **how: Any) -> Submitted:
        """Rule 5 at the one door: an event for a device on another node is forwarded there,
        once; its handle fails (that node's door judges and runs it, and tells nobody here)."""
        if device in self._remote:
            self._wire.forward(device, event, data)
            handle = Submitted(device, event)
            handle.fail(StatectlError(f"{device} runs on another node; {event} was forwarded"))
            return handle
        return System.submit(self, device, event, data, **how)  # how: origin, note
