"""One node on Zenoh: link streams, acknowledgements, presence, published states.

Rules:
1. A node opens one Zenoh session in peer mode with multicast scouting off: it
   listens on its ``listen`` endpoints and connects to its ``connect`` ones, and
   nothing else (no router, no discovery outside the endpoints given). Its lease
   is the node's ``lease``: how soon the others notice it is cut off.
2. Presence is a liveliness token ``statectl/<cell>/node/<node>``. A node sees a
   peer come (its token appears) and go (disappears: the process ended, was
   killed, or its lease ran out); when a peer goes, each device of this node
   listed in ``peer_lost`` that a link joins to a device on that peer gets its
   declared event. Every change is printed: ``peers: a, b``. A lost peer's token is
   asked for once a lease: one that stalled (SIGSTOP) may keep its session and
   never put its token again.
3. Link events go once and in order per stream (statectl.channels.distributed.streams),
   as a JSON array ``[e, n, ev, d]`` (epoch, number, event, data); a node has one
   subscriber per stream it may receive (each other node, each device of its
   own), so a link event's callback reads only its payload. Link events are
   numbered, kept until acknowledged, resent after the peer comes back (a
   ``hello`` asks the receiver how far it got) or when nothing was acknowledged
   for :data:`RESEND_AFTER`. A ``queue`` link keeps its events while the peer is
   down; a ``drop`` link never sends them (statectl.channels.distributed.system rule 4).
4. The receiver acknowledges an event once it is applied: with a journal, once
   its inbox row (and the stream's position, in the same commit) is committed;
   without one, once the device ran it on the receiving thread (nobody owned the
   devices: statectl.channels.distributed.system rule 7) or it was queued for the owner.
   Acknowledgements are cumulative and sent by one thread, so a burst of events
   costs few of them.
5. Each device's state is put on ``statectl/<cell>/state/<device>`` after every
   step that changed it while a subscriber somewhere takes it in (Zenoh's matching
   status; the current state is put when one appears), and answered to queries on
   that key, so a node's rules (the mirror), a dashboard and an operator station see
   the whole cell.
6. A node resumed from its journal keeps its epoch and stream positions (the
   journal's ``meta`` rows ``link-epoch`` and ``link-in/<node>/<device>``) and
   sends again what its journal holds and the receiver has not acknowledged.
7. A node subscribes only to the streams some link carries and checks what
   arrives (statectl.channels.distributed.receive); every message it reads (acks,
   hellos, posts, states) is bounded before it is decoded, and a refused one is
   one escaped log line and a journal note (``zenoh-refused/NN``, the run's last
   100, and ``zenoh-refused``, the run's count), nothing else. A sender puts a stream's
   events only once the receiver acknowledged its hello since the peer came up (Zenoh
   may hand hello and event to their subscribers in either order); until then they
   are kept, the hello said again each :data:`_TICK` (one put before the peer's
   subscriber was known is lost), and its acknowledgement puts them: the first link
   event never waits for :data:`RESEND_AFTER` (``resends`` counts streams that did).
"""

from __future__ import annotations

import json
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TextIO

from statectl.cell.explore.enforce import Refused
from statectl.cell.model import Cell, Link
from statectl.channels.distributed.keys import Keys
from statectl.channels.distributed.messages import (
    Unreadable,
    encode_link,
    parse_snapshot,
    read_ack,
    read_hello,
    read_post,
    refuse_non_finite,
    snapshot_payload,
)
from statectl.channels.distributed.receive import refuse, stream_receiver
from statectl.channels.distributed.resume import EPOCH_KEY, read_links
from statectl.channels.distributed.streams import Inbound, Outbound
from statectl.channels.distributed.system import NodeSystem
from statectl.channels.distributed.trust import carried, printable, session_config, shown
from statectl.kernel.errors import StatectlError
from statectl.kernel.semantics import Snapshot
from statectl.run.commands import Origin

__all__ = ["RESEND_AFTER", "Wire"]

#: Seconds without an acknowledgement after which a stream asks again (rule 3).
RESEND_AFTER = 0.5
#: A post's origin at the System's door: who put it is Zenoh's to know (its access
#: control, with security:), not statectl's, so it is anonymous there.
ZENOH = Origin("zenoh")
_TICK = 0.05
_ACK_PAUSE = 0.002  # seconds between two rounds of acknowledgements, at least
_ENC = json.JSONEncoder(separators=(",", ":"), allow_nan=False)


class Wire:
    """One node's side of the cell on Zenoh (rules 1-6)."""

    def __init__(
        self,
        cell: Cell,
        node: str,
        system: NodeSystem,
        *,
        out: TextIO,
        journal: Path | None = None,
        resume: bool = False,
    ) -> None:
        if cell.nodes is None:
            raise StatectlError(f"{cell.path}: the cell has no nodes: section")
        self.cell = cell
        self.nodes = cell.nodes
        try:
            self.me = self.nodes.node(node)
        except KeyError:
            names = ", ".join(n.name for n in self.nodes.nodes)
            raise StatectlError(f"the cell has no node {node!r}; nodes: {names}") from None
        self.system = system
        self.out = out
        self.keys = Keys(cell.name)
        self.local = set(self.me.devices)
        self._devices = {d.name for d in cell.devices}
        self.up: set[str] = set()
        self.mirror: dict[str, int] = {}
        self.inbound = Inbound()
        #: (sending node, device) -> the events links and invariants send on that stream
        self.carried = carried(cell)
        self.refused = 0  # messages refused by rule 7, for the journal's note
        self.resends = 0  # streams asked again after RESEND_AFTER without an ack (rule 7)
        self.outbound: dict[str, Outbound] = {}
        self._acks: deque[tuple[int, str, str, str, int]] = deque()  # seq, node, device, e, n
        self._ack_due: dict[tuple[str, str], tuple[str, int, bool]] = {}
        self._hello_due: set[str] = set()
        self._resend_due: set[str] = set()
        self._due = threading.Lock()  # guards the three above: callbacks add, the thread takes
        self._states: dict[str, Snapshot] = {}  # "state/<device>" -> newest snapshot to put
        self._watched: dict[str, bool] = {}  # "state/<device>" -> does anyone subscribe?
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._print = threading.Lock()
        self._pubs: dict[str, Any] = {}
        self._decls: list[Any] = []
        self._session: Any = None
        self._thread: threading.Thread | None = None
        self._mirrored = False  # whether other nodes' states are taken in (open())
        self.lost_at: dict[str, float] = {}  # node -> monotonic time it was noticed gone
        self._asked = 0.0  # when lost peers' tokens were last asked for (rule 2)
        self.on_state: list[Callable[[str, Snapshot, float], None]] = []
        #: called with each forwarded environment command this node refused (its 'when')
        self.on_refused: list[Callable[[Exception], None]] = []
        epoch, backlog = self._from_journal(journal, resume)
        self.epoch = epoch
        for d in cell.devices:
            if d.name not in self.local:
                stream = Outbound(d.name, self.nodes.node_of(d.name), epoch)
                for event, data in backlog.get(d.name, ()):
                    stream.add(event, data)
                self.outbound[d.name] = stream
        system.attach(self, self.mirror)
        if system.journal is not None:
            system.journal.after_commit(self._committed)

    # -- the journal (rule 6) -----------------------------------------------------------------

    def _from_journal(
        self, path: Path | None, resume: bool
    ) -> tuple[str, dict[str, list[tuple[str, Any]]]]:
        """The epoch and, on resume, each stream's events the journal holds; the inbound state."""
        remote = [d.name for d in self.cell.devices if d.name not in self.local]
        found = read_links(path, resume, remote)
        self.inbound.last.update(found.last)
        if found.epoch is not None:
            return found.epoch, found.backlog
        epoch = uuid.uuid4().hex[:12]
        journal = self.system.journal
        if journal is not None:
            journal.note(EPOCH_KEY, f"{epoch} {found.top}")
        return epoch, {}

    def _committed(self) -> None:
        """On the journal's writer after a commit: acknowledge what is durable now (rule 4)."""
        journal = self.system.journal
        acks = self._acks
        if journal is None or not acks:
            return
        durable = journal.durable_seq
        woke = False
        with self.inbound.lock:
            while acks and acks[0][0] <= durable:
                _, node, device, e, n = acks.popleft()
                self._ack(node, device, e, n, False)
                woke = True
        if woke:
            self._wake.set()

    # -- opening and closing -----------------------------------------------------------------

    def open(self, *, states: bool = False) -> None:
        """Rule 1-2, 5: the session, the publishers, the mirror; before the System starts.

        Other nodes' states are taken in when a guard here reads them, or ``states``
        (a dashboard of the whole cell).
        """
        import zenoh

        me = self.me
        self._session = s = zenoh.open(
            session_config(self.cell, me.name, listen=me.listen, connect=me.connect, lease=me.lease)
        )
        root = self.keys.root
        block = zenoh.CongestionControl.BLOCK
        for name, stream in self.outbound.items():
            self._pubs[name] = s.declare_publisher(
                self.keys.link(self.me.name, name), congestion_control=block
            )
            del stream
        for name in self.local:
            pub = self._pubs["state/" + name] = s.declare_publisher(
                self.keys.state(name), congestion_control=block
            )
            self.system.subjects[name].on_step(self._stepped(name))
            self._watch_matching(pub, "state/" + name)
        self._decls += [
            s.declare_subscriber(f"{root}/ack/{self.me.name}/*", self._on_ack),
            s.declare_queryable(f"{root}/state/*", self._on_query),
        ]
        self._mirrored = states or self.system.reads_remote()
        if self._mirrored:
            self._decls.append(
                s.declare_subscriber(
                    f"{root}/state/*", self._on_state, allowed_origin=zenoh.Locality.REMOTE
                )
            )

    def _watch_matching(self, pub: Any, key: str) -> None:
        """Rule 5: put a device's states only while a subscriber somewhere takes them in
        (Zenoh's matching status); when one appears, put the current state at once."""
        try:
            self._watched[key] = bool(pub.matching_status.matching)
            listener = pub.declare_matching_listener(
                lambda status, key=key: self._matching(key, bool(status.matching))
            )
        except (AttributeError, TypeError):  # a Zenoh without matching status: always put
            self._watched.pop(key, None)
            return
        self._decls.append(listener)

    def _matching(self, key: str, matching: bool) -> None:
        self._watched[key] = matching
        if matching:
            snap = self.system.subjects[key.removeprefix("state/")].snapshot
            if snap is not None:
                self._states[key] = snap
                self._wake.set()

    def refresh(self) -> None:
        """Ask every node for its devices' states now (a dashboard that starts late)."""
        if self._session is not None:
            self._session.get(f"{self.keys.root}/state/*", self._on_reply)

    @property
    def session(self) -> Any:
        """The open Zenoh session (after :meth:`open`), for a host's own keys."""
        if self._session is None:
            raise StatectlError("the wire is not open")
        return self._session

    def listen(self) -> None:
        """After the System started (resumed): take link events, posts and presence."""
        s = self._session
        root = self.keys.root
        for (node, name), events in sorted(self.carried.items()):
            if name in self.local:  # rule 7: only the streams some link carries
                receiver = self._receiver(node, name, events)
                self._decls.append(s.declare_subscriber(self.keys.link(node, name), receiver))
        for name in sorted(self.local):
            self._decls += [
                s.declare_subscriber(f"{root}/hello/*/{name}", self._on_hello),
                s.declare_subscriber(self.keys.post(name), self._on_post),
            ]
        self._decls.append(
            s.liveliness().declare_subscriber(f"{root}/node/*", self._on_presence, history=True)
        )
        # present once listening: a peer's hello to a node that cannot hear it yet is lost
        self._decls.append(s.liveliness().declare_token(self.keys.node(self.me.name)))
        if self._mirrored:
            s.get(f"{root}/state/*", self._on_reply)
        for name in self.local:  # started or resumed: say where each device is now
            snap = self.system.subjects[name].snapshot
            if snap is not None:
                self._states["state/" + name] = snap
        self._thread = threading.Thread(target=self._run, name="statectl-wire", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()
        if self._session is not None:
            session, self._session = self._session, None
            session.close()

    # -- the System's side -------------------------------------------------------------------

    def down(self, link: Link) -> bool:
        stream = self.outbound.get(link.target)
        node = stream.node if stream is not None else self.nodes.node_of(link.target)
        return node not in self.up

    def send(self, device: str, event: str, data: Any) -> None:
        """Number, keep and (if the peer is up) put a link event (rule 3)."""
        stream = self.outbound[device]
        if data is not None:
            refuse_non_finite(data, device, event)
        with stream.lock:
            n = stream.add(event, data)
            if stream.greeted and stream.node in self.up and self._session is not None:
                self._pubs[device].put(encode_link(stream.epoch, n, event, data))

    def forward(self, device: str, event: str, data: Any) -> None:
        if self._session is not None:
            self._session.put(self.keys.post(device), _ENC.encode({"ev": event, "d": data}))

    def _stepped(self, name: str) -> Callable[[str, Any, str], None]:
        """Rule 5: put the device's state after a step that changed it."""
        subject = self.system.subjects[name]
        key = "state/" + name
        last: list[Snapshot | None] = [None]

        states = self._states
        wake = self._wake

        watched = self._watched

        def put(event: str, data: Any, outcome: str) -> None:
            if not watched.get(key, True):  # nobody takes this device's states in
                return
            snap = subject.snapshot
            if snap is None or snap == last[0]:
                return
            last[0] = snap
            states[key] = snap  # the wire's thread puts the newest one
            if not wake.is_set():
                wake.set()

        return put

    # -- Zenoh callbacks ---------------------------------------------------------------------

    def _receiver(
        self, node: str, device: str, events: dict[str, bool] | None = None
    ) -> Callable[[Any], None]:
        """The subscriber of one stream (``node`` -> ``device``, rules 3-4 and 7)."""
        if events is None:
            events = self.carried.get((node, device), {})
        return stream_receiver(self, node, device, events)

    def _refuse(
        self, key: str, reason: str, device: str | None = None, event: str | None = None
    ) -> None:
        refuse(self, key, reason, device, event)  # rule 7 (statectl.channels.distributed.receive)

    def _ack(self, node: str, device: str, e: str, n: int, again: bool) -> None:
        """Note an acknowledgement for the wire's thread to send (rule 4)."""
        with self._due:
            self._ack_due[node, device] = (e, n, again)

    def _on_ack(self, sample: Any) -> None:
        _, device = Keys.last(sample.key_expr)
        stream = self.outbound.get(device)
        try:
            e, n, again = read_ack(sample.payload.to_bytes())
        except Unreadable as exc:
            self._refuse(str(sample.key_expr), str(exc))
            return
        if stream is None or e != stream.epoch or not 0 <= n <= stream.sent:
            return  # an acknowledgement of what was never sent acknowledges nothing
        with stream.lock:
            stream.ack(n)
        if again:
            with self._due:
                self._resend_due.add(device)
            self._wake.set()

    def _on_hello(self, sample: Any) -> None:
        """Rule 3 and streams rule 4: how far this stream got; its epoch may start now."""
        node, device = Keys.last(sample.key_expr)
        try:
            if (node, device) not in self.carried:
                raise Unreadable(f"no link from {shown(node)} sends to {shown(device)}")
            e = read_hello(sample.payload.to_bytes())
        except Unreadable as exc:
            self._refuse(str(sample.key_expr), str(exc))
            return
        with self.inbound.lock:
            self.inbound.announce(node, device, e)
            applied = self.inbound.applied(node, device, e)
            if applied is not None and self.system.journal is not None:
                # an event still waiting for its commit is acknowledged by _committed
                pending = [a[4] for a in self._acks if a[1] == node and a[2] == device]
                if pending:
                    applied = pending[0] - 1
        self._ack(node, device, e, applied or 0, True)
        self._wake.set()

    def _on_post(self, sample: Any) -> None:
        _, device = Keys.last(sample.key_expr)
        try:
            event, data = read_post(sample.payload.to_bytes())
        except Unreadable as exc:
            self._refuse(str(sample.key_expr), str(exc))
            return
        try:  # at the System's door: the commands policy's zenoh grants (run/commands.py)
            self.system.post(device, event, data, origin=ZENOH)
        except (ValueError, KeyError, TypeError, StatectlError) as exc:
            self._say(f"event for {device} from another node refused: {exc}")
            if isinstance(exc, Refused):
                for callback in self.on_refused:
                    callback(exc)

    def _on_state(self, sample: Any, reply: bool = False) -> None:
        _, device = Keys.last(sample.key_expr)
        if device in self.local or device not in self._devices:
            if not reply:  # a put from elsewhere of this node's device, or of none
                self._refuse(str(sample.key_expr), "no other node runs this device")
            return
        try:
            snap, t = parse_snapshot(sample.payload.to_bytes())
        except Unreadable as exc:
            self._refuse(str(sample.key_expr), str(exc))
            return
        except (ValueError, KeyError, TypeError):
            return
        if device not in self.local:
            links = self.system.links
            if links is not None and device in links.model.position:
                d = links.model.position[device]
                lid = links.model.spaces[d].lookup(snap)
                if lid is not None and self.mirror.get(device) != lid:
                    self.mirror[device] = lid
                    self.system.recheck()  # invariants over what this node sees
        for callback in self.on_state:
            callback(device, snap, t)

    def _on_reply(self, reply: Any) -> None:
        if reply.ok is not None:
            self._on_state(reply.ok, reply=True)

    def _on_query(self, query: Any) -> None:
        for name in sorted(self.local):
            if query.key_expr.intersects(self.keys.state(name)):
                subject = self.system.subjects[name]
                snap = subject.snapshot
                if snap is not None:
                    query.reply(self.keys.state(name), snapshot_payload(snap))

    def _on_presence(self, sample: Any) -> None:
        import zenoh

        _, node = Keys.last(sample.key_expr)
        if node == self.me.name or node not in {n.name for n in self.nodes.nodes}:
            return
        if sample.kind == zenoh.SampleKind.PUT:
            if node in self.up:
                return
            self.up.add(node)
            self._say(f"peer {node} up; peers: {', '.join(sorted(self.up))}")
            if self._mirrored:
                self.refresh()  # where its devices are now
            for name, stream in self.outbound.items():
                if stream.node == node and (self.me.name, name) in self.carried:
                    with self._due:
                        self._hello_due.add(name)
            self._wake.set()
            return
        if node not in self.up:
            return
        self.up.discard(node)
        self.lost_at[node] = time.monotonic()
        for stream in self.outbound.values():
            if stream.node == node:
                stream.greeted = False  # its epoch is announced again when it is back
        self._say(f"peer {node} lost; peers: {', '.join(sorted(self.up)) or 'none'}")
        for device, event in self.peer_lost_events(node):
            try:
                self.system.post(device, event)
            except StatectlError as exc:
                self._say(f"peer_lost event {event!r} to {device}: {exc}")

    def peer_lost_events(self, node: str) -> list[tuple[str, str]]:
        """Rule 2: the (device, event) pairs of this node's peer_lost that ``node`` concerns."""
        there = set(self.nodes.node(node).devices)
        out = []
        for device, event in self.me.peer_lost:
            if any(
                (k.source == device and k.target in there)
                or (k.target == device and k.source in there)
                for k in self.cell.links
            ):
                out.append((device, event))
        return out

    def _say(self, text: str) -> None:
        """One line of the node's log; whatever came from the wire is escaped (rule 7)."""
        with self._print:
            self.out.write(f"node {self.me.name}: {printable(text)}\n")
            self.out.flush()

    # -- the wire's thread (rules 3-4) -------------------------------------------------------

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(_TICK)
            self._wake.clear()
            session = self._session
            if session is None:
                return
            try:
                self._put_states()
                self._ask_lost(session)
                acked = self._send_acks(session)
                self._resend(session)
                if acked:
                    time.sleep(_ACK_PAUSE)  # let a burst's acknowledgements gather (rule 4)
            except Exception as exc:  # the session closed under us: stop quietly
                if not self._stop.is_set():
                    self._say(f"wire: {exc}")

    def _ask_lost(self, session: Any) -> None:
        """Rule 2: while a peer is lost, ask for its token once a lease; a reply brings it up."""
        now = time.monotonic()
        if now >= self._asked + self.me.lease and any(n not in self.up for n in self.lost_at):
            self._asked = now
            session.liveliness().get(f"{self.keys.root}/node/*", self._on_alive)

    def _on_alive(self, reply: Any) -> None:
        if getattr(reply, "ok", None) is not None:
            self._on_presence(reply.ok)  # a PUT: only a node not up yet is said

    def _put_states(self) -> None:
        """Rule 5: put each device's newest snapshot (a burst of steps costs one put)."""
        states = self._states
        while states:  # popitem is atomic: the owner may add meanwhile, never iterated
            try:
                key, snap = states.popitem()
            except KeyError:
                return
            self._pubs[key].put(snapshot_payload(snap))

    def _send_acks(self, session: Any) -> bool:
        with self._due:
            due, self._ack_due = self._ack_due, {}
        for (node, device), (e, n, again) in due.items():
            session.put(self.keys.ack(node, device), _ENC.encode({"e": e, "n": n, "r": again}))
        return bool(due)

    def _resend(self, session: Any) -> None:
        now = time.monotonic()
        with self._due:
            hello, self._hello_due = self._hello_due, set()
            again, self._resend_due = self._resend_due, set()
        for name, stream in self.outbound.items():
            if stream.node not in self.up:
                continue
            with stream.lock:
                if name in again:  # the receiver knows the epoch: put what it lacks
                    self._put_all(stream)
                    stream.greeted = True  # what is sent from now on follows (rule 7)
                elif not stream.greeted:  # unheard: say it again next tick (rule 7)
                    if (self.me.name, name) in self.carried and now - stream.hello_at >= _TICK:
                        hello.add(name)
                elif stream.unacked and now - stream.last_send > RESEND_AFTER:
                    hello.add(name)
                    stream.last_send = now
                    self.resends += 1
            if name in hello:
                stream.hello_at = now
                session.put(self.keys.hello(self.me.name, name), _ENC.encode({"e": stream.epoch}))

    def _put_all(self, stream: Outbound) -> None:
        """Under the stream's lock: put every unacknowledged event again, in order."""
        pub = self._pubs[stream.device]
        for n, event, data in list(stream.unacked):
            pub.put(encode_link(stream.epoch, n, event, data))
        stream.last_send = time.monotonic()

    def peers(self) -> Sequence[str]:
        return sorted(self.up)
