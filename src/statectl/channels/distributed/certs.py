"""The certificates a cell's nodes prove who they are with (mutual TLS on Zenoh).

Rules:
1. ``security: {tls: DIR}``: the first node (or station) that opens makes the
   cell's CA (``ca.pem``, ``ca-key.pem``) and a certificate for **every** node and
   station (``NAME.pem``, ``NAME-key.pem``) in DIR, so the directory can be copied
   to the other machines as it is; later runs take them, and make again only a
   certificate that is missing or expires within a day (needs ``ca-key.pem``).
   Keys are written owner-only (0600) in a 0700 directory, under a lock, so two
   nodes starting together on one machine make one CA.
2. A certificate's common name is its principal's name (Zenoh's access control
   matches it); its subject alternative names are the hosts its node listens on
   and the hosts the other nodes connect to on its ports (Zenoh checks the name
   of the host it connects to). Both TLS roles, server and client.
3. ``security: {tls: {ca: ..., certificates: ...}}``: the files given are taken as
   they are (made by the plant's own CA).
"""

from __future__ import annotations

import datetime
import ipaddress
import os
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

from statectl.cell.model import Cell
from statectl.cell.security import Tls
from statectl.kernel.errors import StatectlError

__all__ = ["cell_principals", "ensure_certificates", "tls_files"]

_CA_DAYS = 3650
_LEAF_DAYS = 825
_RENEW = datetime.timedelta(days=1)


def cell_principals(cell: Cell) -> dict[str, tuple[str, ...]]:
    """Rule 2: every node and station of the cell, with the host names its certificate names."""
    assert cell.nodes is not None
    out: dict[str, tuple[str, ...]] = {}
    connects = [e for n in cell.nodes.nodes for e in n.connect]
    for n in cell.nodes.nodes:
        ports = {_split(e)[1] for e in n.listen}
        hosts = [_split(e)[0] for e in n.listen]
        hosts += [h for h, p in map(_split, connects) if p in ports]
        out[n.name] = tuple(dict.fromkeys(h for h in hosts if h not in ("0.0.0.0", "::", "")))
    for s in cell.nodes.security.stations:
        out[s] = ()
    return out


def _split(endpoint: str) -> tuple[str, str]:
    address = endpoint.partition("/")[2].split("#", 1)[0].split("?", 1)[0]
    host, _, port = address.rpartition(":")
    return host.strip("[]"), port


def tls_files(cell: Cell, principal: str) -> tuple[Path, Path, Path]:
    """The CA, certificate and key ``principal`` uses (rules 1 and 3); made when needed."""
    assert cell.nodes is not None
    tls: Tls | None = cell.nodes.security.tls
    if tls is None:
        raise StatectlError(f"{cell.path}: the cell has no security: tls")
    if tls.directory is None:
        assert tls.ca is not None
        for who, cert, key in tls.files:
            if who == principal:
                return tls.ca, cert, key
        raise StatectlError(f"{cell.path}: security: tls gives no certificate for {principal!r}")
    principals = cell_principals(cell)
    if principal not in principals:
        raise StatectlError(f"{cell.path}: {principal!r} is no node or station of the cell")
    try:
        ensure_certificates(tls.directory, principals)
    except ImportError:
        raise StatectlError(
            "security: tls makes certificates with 'cryptography': pip install 'statectl[zenoh]'"
        ) from None
    except (OSError, ValueError) as exc:
        where = tls.directory
        raise StatectlError(f"tls: cannot make the certificates in {where}: {exc}") from None
    d = tls.directory
    return d / "ca.pem", d / f"{principal}.pem", d / f"{principal}-key.pem"


def ensure_certificates(directory: Path, principals: Mapping[str, Sequence[str]]) -> None:
    """Rule 1: the CA and every principal's certificate in ``directory``, made when missing."""
    from cryptography import x509

    try:
        directory.mkdir(parents=True, exist_ok=True, mode=0o700)
    except OSError as exc:
        raise StatectlError(f"tls: cannot create the certificate directory: {exc}") from None
    with _locked(directory):
        ca_pem, ca_key = directory / "ca.pem", directory / "ca-key.pem"
        remake = not ca_pem.exists()
        if remake:
            _write_ca(ca_pem, ca_key)
        ca = x509.load_pem_x509_certificate(ca_pem.read_bytes())
        for name, hosts in principals.items():
            cert = directory / f"{name}.pem"
            if remake or not cert.exists() or _expiring(cert):
                if not ca_key.exists():
                    raise StatectlError(
                        f"tls: {cert} is missing or expiring and {ca_key} is not here to make it: "
                        "make the certificates where the CA key is and copy them"
                    )
                _write_leaf(cert, directory / f"{name}-key.pem", name, hosts, ca, ca_key)


@contextmanager
def _locked(directory: Path) -> Iterator[None]:
    import fcntl

    with open(directory / ".lock", "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _expiring(path: Path) -> bool:
    from cryptography import x509

    try:
        cert = x509.load_pem_x509_certificate(path.read_bytes())
    except ValueError:
        return True
    return cert.not_valid_after_utc - _RENEW < datetime.datetime.now(datetime.UTC)


def _write_private(path: Path, data: bytes) -> None:
    """Owner-only from the first byte (O_CREAT with 0600), then replaced in one rename."""
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def _key_pem(key: object) -> bytes:
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric import ec

    assert isinstance(key, ec.EllipticCurvePrivateKey)
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _write_ca(cert_path: Path, key_path: Path) -> None:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "statectl"),
            x509.NameAttribute(NameOID.COMMON_NAME, "statectl cell CA"),
        ]
    )
    now = datetime.datetime.now(datetime.UTC)
    usage = x509.KeyUsage(
        digital_signature=True,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=False,
        key_cert_sign=True,
        crl_sign=True,
        encipher_only=False,
        decipher_only=False,
    )
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=_CA_DAYS))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(usage, critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    _write_private(key_path, _key_pem(key))
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def _write_leaf(
    cert_path: Path,
    key_path: Path,
    name: str,
    hosts: Sequence[str],
    ca: object,
    ca_key_path: Path,
) -> None:
    """Rule 2: a certificate for ``name`` signed by the cell's CA."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    assert isinstance(ca, x509.Certificate)
    ca_key = serialization.load_pem_private_key(ca_key_path.read_bytes(), None)
    assert isinstance(ca_key, ec.EllipticCurvePrivateKey)
    key = ec.generate_private_key(ec.SECP256R1())
    sans: list[x509.GeneralName] = []
    for h in (*hosts, "127.0.0.1", "localhost"):
        try:
            entry: x509.GeneralName = x509.IPAddress(ipaddress.ip_address(h))
        except ValueError:
            entry = x509.DNSName(h)
        if entry not in sans:
            sans.append(entry)
    now = datetime.datetime.now(datetime.UTC)
    roles = [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
        .issuer_name(ca.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=_LEAF_DAYS))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.SubjectAlternativeName(sans), critical=False)
        .add_extension(x509.ExtendedKeyUsage(roles), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())
    )
    _write_private(key_path, _key_pem(key))
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
