"""What a node trusts on Zenoh: the session's TLS and access control, and the bounds every
message is held to before it is read.

Rules:
1. A session is in peer mode with multicast scouting off (wire rule 1). With
   ``security: tls`` it runs Zenoh's TLS with client certificates (``enable_mtls``):
   a peer without a certificate of the cell's CA cannot connect. With ``users`` it
   logs in as its own name and accepts the names of the users file.
2. With either, the session's access control (Zenoh's ``access_control``, on
   receive) lets each node put only its own keys: node N puts
   ``link/N/*`` and ``hello/N/*``, ``ack/*/D`` and ``state/D`` for its devices D,
   its liveliness token ``node/N``, and ``post/D`` where the cell's ``posts``
   lets it (stations alike). Everything else sent to this node is dropped by Zenoh
   before statectl sees it. Subscriptions, queries and liveliness questions under
   the cell's root are open to every authenticated peer.
3. Whatever the session, statectl checks every message itself before it acts on
   it (statectl.channels.distributed.wire): a payload longer than
   :data:`MAX_PAYLOAD` bytes or nested deeper than :data:`MAX_DEPTH` is dropped
   before it is decoded; an event name longer than :data:`MAX_NAME` or holding a
   character that is not printable (control characters, bidi controls such as
   U+202E, line separators) is refused; names are printed with :func:`shown`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from statectl.cell.model import Cell
from statectl.channels.distributed.keys import Keys
from statectl.kernel.errors import StatectlError
from statectl.kernel.text import shown as display

__all__ = [
    "MAX_DEPTH",
    "MAX_NAME",
    "MAX_PAYLOAD",
    "access_control",
    "carried",
    "data_problem",
    "name_problem",
    "payload_problem",
    "printable",
    "security_line",
    "session_config",
    "shown",
]

#: Bytes of one message's payload, at most (a link event is ~40; a state a few hundred).
MAX_PAYLOAD = 64 * 1024
#: Nesting of arrays and objects in one payload, at most.
MAX_DEPTH = 32
#: Characters of an event name, at most.
MAX_NAME = 256
_SHOWN = 80  # characters of a name printed before it is cut


def payload_problem(payload: bytes) -> str | None:
    """Rule 3: why ``payload`` is not read at all (too long, nested too deep), or None."""
    if len(payload) > MAX_PAYLOAD:
        return f"payload of {len(payload)} bytes (at most {MAX_PAYLOAD})"
    if payload.count(b"[") + payload.count(b"{") <= MAX_DEPTH:  # the hot path: cannot be deeper
        return None
    depth = 0
    quoted = escaped = False
    for byte in payload:
        if quoted:
            if escaped:
                escaped = False
            elif byte == 0x5C:  # backslash
                escaped = True
            elif byte == 0x22:  # quote
                quoted = False
        elif byte == 0x22:
            quoted = True
        elif byte in (0x5B, 0x7B):  # [ {
            depth += 1
            if depth > MAX_DEPTH:
                return f"payload nested deeper than {MAX_DEPTH}"
        elif byte in (0x5D, 0x7D):
            depth -= 1
    return None


def name_problem(name: str) -> str | None:
    """Rule 3: why an event name from the wire is refused, or None."""
    if len(name) > MAX_NAME:
        return f"an event name of {len(name)} characters (at most {MAX_NAME})"
    if not name.isprintable():
        return f"an event name with a character that is not printable: {shown(name)}"
    return None


def shown(name: str) -> str:
    """A name from the wire as it may be printed or journalled: cut after 80 characters,
    escaped by the one display escape (kernel/text.py: ``\\n``, ``\\u202e``), quoted."""
    if len(name) <= _SHOWN:
        return f"'{display(name)}'"
    return f"'{display(name[:_SHOWN])}'... ({len(name)} characters)"


def printable(text: str, limit: int = 400) -> str:
    """A log line with every character that is not printable escaped and its length cut:
    a name from the wire cannot end the line, reorder it (U+202E) or flood the log."""
    if text.isprintable() and len(text) <= limit:
        return text
    out = display(text[:limit])  # the one display escape (kernel/text.py)
    return out if len(text) <= limit else f"{out}... ({len(text)} characters)"


def carried(cell: Cell) -> dict[tuple[str, str], dict[str, bool]]:
    """Per stream (sending node, device elsewhere): the events it may carry, each with
    whether it may carry data, and nothing else: the links' events from that node's
    devices to the device (with data when the link sends some or forwards the step's),
    and the ``on_violation`` events (no data) of the invariants that node watches (the
    node of the first device, in the cell's order, an invariant reads:
    distributed.system rule 6)."""
    assert cell.nodes is not None
    nodes = cell.nodes
    out: dict[tuple[str, str], dict[str, bool]] = {}

    def add(node: str, device: str, event: str, data: bool) -> None:
        if nodes.node_of(device) != node:
            events = out.setdefault((node, device), {})
            events[event] = events.get(event, False) or data

    for link in cell.links:
        data = link.forward_data or link.data is not None
        add(nodes.node_of(link.source), link.target, link.event, data)
    order = [d.name for d in cell.devices]
    for inv in cell.invariants:
        read = {d for d, _ in inv.expr.refs}
        first = next((d for d in order if d in read), None)
        if first is not None:
            for device, event in inv.on_violation:
                add(nodes.node_of(first), device, event, False)
    return out


def data_problem(data: Any) -> str | None:
    """Rule 3 for event data from the wire: every text in it (keys too) printable, since
    a trace or a log prints it; None when it is fine (and at once for no data)."""
    if data is None or isinstance(data, int | float | bool):
        return None
    values = [data]
    while values:
        value = values.pop()
        if isinstance(value, str):
            if not value.isprintable():
                return f"data holding a character that is not printable: {shown(value)}"
        elif isinstance(value, dict):
            values.extend(value.keys())
            values.extend(value.values())
        elif isinstance(value, list):
            values.extend(value)
    return None


def security_line(cell: Cell) -> str:
    """The banner's word on the session (rule 1): what a peer must prove to connect."""
    assert cell.nodes is not None
    sec = cell.nodes.security
    parts = []
    if sec.tls is not None:
        parts.append("mutual TLS (certificates of the cell's CA)")
    if sec.users is not None:
        parts.append("user/password")
    if parts:
        return "security " + " and ".join(parts) + "; access control: each node its own keys"
    if sec.insecure:
        return "security NONE (insecure: true): anyone who reaches these endpoints may command"
    return "security open on loopback: any local process may command these devices"


def session_config(
    cell: Cell,
    principal: str,
    *,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    lease: float | None = None,
) -> Any:
    """Rules 1-2: the Zenoh configuration of ``principal`` (a node or a station)."""
    import zenoh

    assert cell.nodes is not None
    c = zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "true")
    c.insert_json5("listen/endpoints", json.dumps(list(listen)))
    c.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if lease is not None:
        c.insert_json5("transport/link/tx/lease", str(max(50, int(lease * 1000))))
        c.insert_json5("transport/link/tx/keep_alive", "4")
    sec = cell.nodes.security
    if sec.tls is not None:
        from statectl.channels.distributed.certs import tls_files

        ca, cert, key = tls_files(cell, principal)
        tls = {
            "root_ca_certificate": str(ca),
            "listen_private_key": str(key),
            "listen_certificate": str(cert),
            "enable_mtls": True,
            "connect_private_key": str(key),
            "connect_certificate": str(cert),
        }
        c.insert_json5("transport/link/tls", json.dumps(tls))
    if sec.users is not None:
        c.insert_json5("transport/auth/usrpwd", json.dumps(_login(sec.users, principal)))
    if sec.authenticated:
        c.insert_json5("access_control", json.dumps(access_control(cell)))
    return c


def _login(users: Path, principal: str) -> dict[str, str]:
    """Rule 1: this principal's line of the users file, and the file as the dictionary."""
    try:
        lines = users.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise StatectlError(f"security users: cannot read {users}: {exc}") from None
    for line in lines:
        name, sep, password = line.partition(":")
        if sep and name == principal:
            return {"user": name, "password": password, "dictionary_file": str(users)}
    raise StatectlError(
        f"security users: {users} has no line '{principal}:PASSWORD' for {principal!r}"
    )


_OPEN = [
    "declare_subscriber",
    "declare_queryable",
    "declare_liveliness_subscriber",
    "liveliness_query",
    "query",
]


def access_control(cell: Cell) -> dict[str, Any]:
    """Rule 2: the access control of every session of the cell (the same on each)."""
    assert cell.nodes is not None
    root = Keys(cell.name).root
    sec = cell.nodes.security
    everyone = (*(n.name for n in cell.nodes.nodes), *sec.stations)
    rules: list[dict[str, Any]] = [
        _rule("open", _OPEN, ["ingress", "egress"], [f"{root}/**"]),
        _rule("out", [*_OPEN, "put", "reply", "liveliness_token"], ["egress"], [f"{root}/**"]),
    ]
    subjects: list[dict[str, Any]] = [{"id": "anyone"}]
    policies = [{"rules": ["open", "out"], "subjects": ["anyone"]}]
    for who in everyone:
        subjects.append(_subject(who, sec.tls is not None, sec.users is not None))
        granted = _granted(cell, root, who, everyone)
        for rule in granted:
            rules.append(rule)
        if granted:
            policies.append({"rules": [r["id"] for r in granted], "subjects": [f"is-{who}"]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def _rule(id_: str, messages: list[str], flows: list[str], keys: list[str]) -> dict[str, Any]:
    return {
        "id": id_,
        "messages": messages,
        "flows": flows,
        "permission": "allow",
        "key_exprs": keys,
    }


def _granted(cell: Cell, root: str, who: str, everyone: tuple[str, ...]) -> list[dict[str, Any]]:
    """Rule 2: what ``who`` may send to a node (its puts, token and replies)."""
    assert cell.nodes is not None
    sec = cell.nodes.security
    keys = [f"{root}/post/{d.name}" for d in cell.devices if who in sec.posters(d.name, everyone)]
    if who not in {n.name for n in cell.nodes.nodes}:  # a station: its posts only
        return [_rule(f"put-{who}", ["put"], ["ingress"], keys)] if keys else []
    mine = cell.nodes.node(who).devices
    keys += [f"{root}/link/{who}/*", f"{root}/hello/{who}/*"]
    keys += [k for d in mine for k in (f"{root}/ack/*/{d}", f"{root}/state/{d}")]
    token = f"{root}/node/{who}"
    replies = [token, *(f"{root}/state/{d}" for d in mine)]
    return [
        _rule(f"put-{who}", ["put"], ["ingress"], keys),
        _rule(f"token-{who}", ["liveliness_token"], ["ingress"], [token]),
        _rule(f"reply-{who}", ["reply"], ["ingress"], replies),
    ]


def _subject(who: str, tls: bool, users: bool) -> dict[str, Any]:
    """Who ``who`` is on a transport: its certificate's common name, its user name."""
    subject: dict[str, Any] = {"id": f"is-{who}"}
    if tls:
        subject["cert_common_names"] = [who]
    if users:
        subject["usernames"] = [who]
    return subject
