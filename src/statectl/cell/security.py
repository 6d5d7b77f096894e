"""A cell's ``security:`` section: who the nodes are to each other on Zenoh, and who may
publish what.

Rules:
1. ``tls`` turns on Zenoh's TLS with client certificates (mutual TLS) for every
   node: either a directory (``tls: certs``, relative to the cell file) where the
   cell's CA and one certificate per node and station are made on first run, or
   a mapping ``{ca: FILE, certificates: {NAME: {certificate: FILE, key: FILE}}}``
   naming certificates made elsewhere. A certificate's common name is its node's
   (or station's) name: that is who it is on the network.
2. With ``tls`` every endpoint of every node is a ``tls/`` (or ``quic/``) one: a
   ``tcp/`` listener beside it would let anyone in (V828).
3. ``users`` names a file of ``name:password`` lines (Zenoh's user/password
   authentication): each node logs in as its own name, and accepts the names in
   the file (so each node holds every password: TLS binds a name to a key, users
   only to a secret every node knows).
4. Who may publish what follows from the cell (a node puts its own links'
   events, acknowledgements and states); ``posts`` says who may post an
   operator's event to a device (``{arm: [line, operator]}``; a device not named
   takes posts from every node and station). ``stations`` names the operator
   stations (``statectl dashboard --as NAME``) besides the nodes. With ``tls`` or
   ``users`` each node's Zenoh refuses anything else on receive (its access
   control); statectl checks the rest (statectl.channels.distributed.trust).
   ``posts`` without ``tls`` or ``users`` is V828: nobody proves who they are.
5. Without ``tls`` a node's endpoints must all be on loopback (V827), unless the
   cell says ``insecure: true``: anyone who reaches a plain endpoint may publish.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from statectl.cell.expressions import _d
from statectl.kernel.errors import Location

__all__ = [
    "OPEN",
    "SECURITY_KEYS",
    "TLS_KEYS",
    "TLS_PROTOCOLS",
    "Security",
    "Tls",
    "is_loopback",
    "read_security",
]

SECURITY_KEYS = ("tls", "users", "posts", "stations", "insecure")
TLS_KEYS = ("ca", "certificates")
#: Protocols whose links Zenoh runs over TLS (the transport/link/tls settings).
TLS_PROTOCOLS = frozenset({"tls", "quic"})


@dataclass(frozen=True, slots=True)
class Tls:
    """Rule 1: where the certificates are (a directory to make them in, or given files)."""

    directory: Path | None = None
    ca: Path | None = None
    #: principal -> (certificate, key), when given as files
    files: tuple[tuple[str, Path, Path], ...] = ()


@dataclass(frozen=True, slots=True)
class Security:
    tls: Tls | None = None
    users: Path | None = None
    #: device -> the principals that may post to it (rule 4); a device not here: everyone
    posts: tuple[tuple[str, tuple[str, ...]], ...] = ()
    stations: tuple[str, ...] = ()
    insecure: bool = False

    @property
    def authenticated(self) -> bool:
        """Whether peers prove who they are (TLS certificates or user names)."""
        return self.tls is not None or self.users is not None

    def posters(self, device: str, everyone: Sequence[str]) -> tuple[str, ...]:
        """Rule 4: who may post an event to ``device``."""
        for name, who in self.posts:
            if name == device:
                return who
        return tuple(everyone)


#: A cell without a security: section.
OPEN = Security()


def is_loopback(endpoint: str) -> bool:
    """Whether a Zenoh endpoint's host is a loopback address (``127.0.0.0/8``, ``::1``,
    ``localhost``)."""
    address = endpoint.partition("/")[2].split("#", 1)[0].split("?", 1)[0]
    host = address.rpartition(":")[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def read_security(
    r: Any, node: yaml.Node | None, nodes: Any, base: Path, devices: Sequence[str]
) -> Security:
    """The ``security`` section, checked against the nodes (rules 1-5); V827/V828."""
    sec = Security()
    if node is not None and nodes is None:
        r.diags.append(
            _d(
                "V828",
                r.at(node),
                "security: applies to a cell whose devices run on nodes",
                "add a nodes: section, or remove security:",
            )
        )
    elif node is not None:
        f = r.mapping(node, "security", SECURITY_KEYS)
        if f is not None:
            sec = _fields(r, f, nodes, base, devices)
    if nodes is not None:
        _check_endpoints(r, nodes, sec)
    return sec


def _fields(
    r: Any, f: Mapping[str, yaml.Node], nodes: Any, base: Path, devices: Sequence[str]
) -> Security:
    names = [n.name for n in nodes.nodes] if nodes is not None else []
    stations = tuple(_texts(r, f.get("stations"), "security stations"))
    for s in stations:
        if not s.isidentifier() or s in names:
            r.diags.append(
                _d(
                    "V828",
                    r.at(f["stations"]),
                    f"security stations: {s!r} is not an identifier or is a node's name",
                    "a station is an operator's dashboard: give it a name of its own",
                )
            )
    principals = (*names, *stations)
    tls = _tls(r, f.get("tls"), base, principals)
    users = None
    if "users" in f:
        text = r.text(f["users"], "security users")
        if text is not None:
            users = (base / text).resolve()
            if not users.is_file():
                r.diags.append(
                    _d(
                        "V828",
                        r.at(f["users"]),
                        f"security users: {text!r} is not a file",
                        f"looked for {users}; write one 'name:password' line per node",
                    )
                )
    posts = _posts(r, f.get("posts"), devices, principals)
    if posts and tls is None and users is None and "posts" in f:
        r.diags.append(
            _d(
                "V828",
                r.at(f["posts"]),
                "security posts: without tls or users nobody proves who they are, so posts "
                "cannot be held to",
                "add tls: DIR (mutual TLS) or users: FILE",
            )
        )
    insecure = False
    if "insecure" in f:
        text = r.text(f["insecure"], "security insecure")
        if text not in ("true", "false"):
            r.diags.append(_d("V804", r.at(f["insecure"]), "insecure must be true or false"))
        insecure = text == "true"
    return Security(tls, users, posts, stations, insecure)


def _texts(r: Any, node: yaml.Node | None, what: str) -> list[str]:
    return [t for t in (r.text(i, what) for i in r.items(node, what)) if t is not None]


def _tls(r: Any, node: yaml.Node | None, base: Path, principals: Sequence[str]) -> Tls | None:
    """Rule 1: a directory, or the CA and each principal's certificate and key."""
    if node is None:
        return None
    if isinstance(node, yaml.ScalarNode):
        text = r.text(node, "security tls")
        return Tls(directory=(base / text).resolve()) if text else None
    f = r.mapping(node, "security tls", TLS_KEYS, TLS_KEYS)
    if f is None or "ca" not in f:
        return None
    ca = _file(r, f["ca"], "security tls ca", base)
    files: list[tuple[str, Path, Path]] = []
    given = f.get("certificates")
    if isinstance(given, yaml.MappingNode):
        for k, v in given.value:
            who = str(k.value)
            pair = ("certificate", "key")
            g = r.mapping(v, f"security tls certificates {who!r}", pair, pair)
            if g is None or "certificate" not in g or "key" not in g:
                continue
            cert = _file(r, g["certificate"], f"certificate of {who!r}", base)
            key = _file(r, g["key"], f"key of {who!r}", base)
            if cert is not None and key is not None:
                files.append((who, cert, key))
    elif given is not None:
        r.diags.append(_d("V804", r.at(given), "certificates must be a mapping of name: {...}"))
    missing = [p for p in principals if p not in {w for w, _, _ in files}]
    if missing and given is not None:
        r.diags.append(
            _d(
                "V828",
                r.at(node),
                f"security tls: no certificate for {', '.join(missing)}",
                "give each node and station {certificate: FILE, key: FILE}",
            )
        )
    return Tls(ca=ca, files=tuple(files)) if ca is not None else None


def _file(r: Any, node: yaml.Node, what: str, base: Path) -> Path | None:
    text = r.text(node, what)
    if text is None:
        return None
    path: Path = (base / text).resolve()
    if not path.is_file():
        r.diags.append(
            _d("V828", r.at(node), f"{what}: {text!r} is not a file", f"looked for {path}")
        )
        return None
    return path


def _posts(
    r: Any, node: yaml.Node | None, devices: Sequence[str], principals: Sequence[str]
) -> tuple[tuple[str, tuple[str, ...]], ...]:
    if node is None:
        return ()
    if not isinstance(node, yaml.MappingNode):
        r.diags.append(_d("V804", r.at(node), "posts must be a mapping of device: [names]"))
        return ()
    out = []
    for k, v in node.value:
        device = str(k.value)
        who = tuple(_texts(r, v, f"security posts {device!r}"))
        unknown = [w for w in who if w not in principals]
        if device not in devices or unknown:
            r.diags.append(
                _d(
                    "V828",
                    r.at(k),
                    f"security posts: {device!r} is no device of the cell"
                    if device not in devices
                    else f"security posts {device!r}: {', '.join(unknown)} is no node or station",
                    "nodes and stations: " + ", ".join(principals),
                )
            )
            continue
        out.append((device, who))
    return tuple(out)


def _check_endpoints(r: Any, nodes: Any, sec: Security) -> None:
    """Rules 2 and 5, per endpoint."""
    for n in nodes.nodes:
        where = n.where if n.where is not None else Location(r.file, 1)
        for endpoint in (*n.listen, *n.connect):
            proto = endpoint.partition("/")[0]
            if sec.tls is not None and proto not in TLS_PROTOCOLS:
                r.diags.append(
                    _d(
                        "V828",
                        where,
                        f"node {n.name!r}: endpoint {endpoint!r} is not TLS in a cell with "
                        "security: tls",
                        "write tls/HOST:PORT: a plain endpoint would let anyone in",
                    )
                )
            elif sec.tls is None and not sec.insecure and not is_loopback(endpoint):
                r.diags.append(
                    _d(
                        "V827",
                        where,
                        f"node {n.name!r}: endpoint {endpoint!r} is reachable from the "
                        "network without TLS: anyone who reaches it could command the devices",
                        "add security: {tls: certs} and tls/ endpoints, or say "
                        "security: {insecure: true}",
                    )
                )
