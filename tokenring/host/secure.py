"""A secured deployment: Zenoh TLS with mutual authentication, and access control by role.

Downloading a program runs code on a node; injecting a fault or stopping the ring is as
powerful. On an open Zenoh network any peer that reaches the ring may do all three. A secured
deployment has its own certificate authority and three roles, each a certificate it signs:

=========  ==========================================================================
role       may
=========  ==========================================================================
node       everything under ``tokenring/**``: the ring's own processes (nodes, the
           launcher, its services) on every host of the ring
operator   everything: download programs, inject faults, stop the ring (the PC link)
observer   read only: subscribe to frames, events and liveliness; query ``stats``,
           ``rounds``, ``visits``, ``program``, ``peers`` and the launcher's ``status``
=========  ==========================================================================

A peer without a certificate of this authority cannot open a link at all (mutual TLS, and
only TLS links are accepted); an observer's link carries its subscriptions and those queries
in, and data and replies out, nothing else. The rules live in the **node** configuration:
every ring process enforces them on each of its links (Zenoh ACL, default deny).

:func:`create_deployment` writes the authority and one self-contained Zenoh config per role
(certificate and key inline, base64), so that one file is all a host needs::

    tokenring secure init DIR --host 10.0.0.5
    tokenring up --listen tls/10.0.0.5:7447 --zenoh-config DIR/node.json5      # the ring's host
    tokenring load -e tls/10.0.0.5:7447 --zenoh-config DIR/operator.json5     # the operator
    tokenring sniff -e tls/10.0.0.5:7447 --zenoh-config DIR/observer.json5    # an observer
"""

from __future__ import annotations

import base64
import datetime
import ipaddress
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tokenring._util.files import check_output, write_atomically
from tokenring.errors import UsageError

ROLES = ("node", "operator", "observer")
#: the certificate common name of each role: what the access rules match links by
COMMON_NAMES = {role: f"tokenring-{role}" for role in ROLES}
CA_NAME = "tokenring deployment CA"
#: every message kind Zenoh's access control knows
ALL_MESSAGES = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
)
#: the control queries that only read (the others inject faults, leave, stop, signal)
OBSERVER_QUERIES = (
    "tokenring/*/ctl/*/stats",
    "tokenring/*/ctl/*/rounds",
    "tokenring/*/ctl/*/visits",
    "tokenring/*/ctl/*/program",
    "tokenring/*/ctl/*/peers",
    "tokenring/*/ctl/launcher/status",
)
DEFAULT_HOSTS = ("localhost", "127.0.0.1")
_HOSTNAME = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,62})(\.[A-Za-z0-9]([A-Za-z0-9-]{0,62}))*$")


def check_host(host: str) -> str:
    """An IP address or a DNS name a certificate can name (argparse type)."""
    try:
        ipaddress.ip_address(host)
        return host
    except ValueError:
        pass
    if not _HOSTNAME.match(host):
        raise UsageError(f"--host {host!r} is neither an IP address nor a host name")
    return host


def access_control() -> dict[str, Any]:
    """The node role's Zenoh ACL: ring and operator may do anything, observers only read."""
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            {
                "id": "everything",
                "messages": list(ALL_MESSAGES),
                "flows": ["ingress", "egress"],
                "permission": "allow",
                "key_exprs": ["tokenring/**"],
            },
            {
                "id": "observe",
                "messages": ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": ["tokenring/**"],
            },
            {
                "id": "read-only-queries",
                "messages": ["query"],
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": list(OBSERVER_QUERIES),
            },
            {
                # data and answers out, and the declarations that tell an observer's session
                # where the ring's queryables are (without them its queries reach nobody)
                "id": "to-observers",
                "messages": [
                    "put",
                    "delete",
                    "reply",
                    "liveliness_token",
                    "declare_queryable",
                    "declare_subscriber",
                ],
                "flows": ["egress"],
                "permission": "allow",
                "key_exprs": ["tokenring/**"],
            },
        ],
        "subjects": [
            {
                "id": "ring-and-operator",
                "cert_common_names": [COMMON_NAMES["node"], COMMON_NAMES["operator"]],
            },
            {"id": "observers", "cert_common_names": [COMMON_NAMES["observer"]]},
        ],
        "policies": [
            {"id": "ring-and-operator", "rules": ["everything"], "subjects": ["ring-and-operator"]},
            {
                "id": "observers",
                "rules": ["observe", "read-only-queries", "to-observers"],
                "subjects": ["observers"],
            },
        ],
    }


def zenoh_config(role: str, ca_pem: bytes, cert_pem: bytes, key_pem: bytes) -> dict[str, Any]:
    """A self-contained Zenoh config for ``role``: TLS only, mutual authentication, its
    certificate and key inline; the node role also carries the access rules."""
    if role not in ROLES:
        raise UsageError(f"role must be one of {', '.join(ROLES)}, not {role!r}")

    def b64(data: bytes) -> str:
        return base64.b64encode(data).decode("ascii")

    config: dict[str, Any] = {
        "mode": "peer",
        # tools and services connect out; `up --listen`/`node --listen` add the ring's listeners
        "listen": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "link": {
                "protocols": ["tls"],
                "tls": {
                    "root_ca_certificate_base64": b64(ca_pem),
                    "listen_certificate_base64": b64(cert_pem),
                    "listen_private_key_base64": b64(key_pem),
                    "connect_certificate_base64": b64(cert_pem),
                    "connect_private_key_base64": b64(key_pem),
                    "enable_mtls": True,
                    "verify_name_on_connect": True,
                },
            }
        },
    }
    if role == "node":
        config["access_control"] = access_control()
    return config


@dataclass(frozen=True)
class Deployment:
    """What :func:`create_deployment` wrote."""

    directory: Path
    files: dict[str, Path]
    hosts: tuple[str, ...]
    not_after: datetime.datetime


def _names(hosts: tuple[str, ...]) -> list[Any]:
    from cryptography import x509

    names: list[Any] = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return names


def _key_usage(authority: bool) -> Any:
    """An authority signs certificates; a role's key signs handshakes and agrees on keys."""
    from cryptography import x509

    return x509.KeyUsage(
        digital_signature=True,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=not authority,
        key_cert_sign=authority,
        crl_sign=authority,
        encipher_only=False,
        decipher_only=False,
    )


def _pem_key(key: Any) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )


def _certificate(
    common_name: str,
    key: Any,
    issuer: tuple[Any, str],
    validity: tuple[datetime.datetime, datetime.datetime],
    extensions: list[tuple[Any, bool]],
) -> bytes:
    """A PEM certificate for ``key`` named ``common_name``, signed by ``issuer`` (its key and
    name: the key's own for the authority), with a subject key identifier besides
    ``extensions`` (each with whether it is critical)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.x509.oid import NameOID

    issuer_key, issuer_name = issuer
    builder = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)]))
        .issuer_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, issuer_name)]))
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(validity[0])
        .not_valid_after(validity[1])
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
    )
    for extension, critical in extensions:
        builder = builder.add_extension(extension, critical=critical)
    return builder.sign(issuer_key, hashes.SHA256()).public_bytes(serialization.Encoding.PEM)


def create_deployment(
    directory: Path, hosts: tuple[str, ...] = DEFAULT_HOSTS, days: int = 365, force: bool = False
) -> Deployment:
    """Write a new authority (``ca.pem``, ``ca-key.pem``) and ``<role>.json5`` for every role.

    The node certificate names ``hosts`` (the addresses the ring listens on: a peer connecting
    to one checks it). Refuses to replace existing files unless ``force``; keys and configs
    (which hold keys) are written readable by their owner only."""
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID

    hosts = tuple(check_host(h) for h in hosts) or DEFAULT_HOSTS
    if days < 1 or days > 3650:
        raise UsageError(f"--days {days} must be within 1..3650")
    targets = {"ca": directory / "ca.pem", "ca-key": directory / "ca-key.pem"}
    targets.update({role: directory / f"{role}.json5" for role in ROLES})
    if directory.exists() and not directory.is_dir():
        raise UsageError(f"{directory}: exists and is not a directory")
    directory.mkdir(parents=True, exist_ok=True)
    for target in targets.values():
        check_output(target, force=force)

    now = datetime.datetime.now(datetime.UTC)
    validity = (now - datetime.timedelta(minutes=5), now + datetime.timedelta(days=days))
    ca_key = ec.generate_private_key(ec.SECP256R1())
    authority = (ca_key, CA_NAME)
    ca_pem = _certificate(
        CA_NAME,
        ca_key,
        authority,
        validity,
        [(x509.BasicConstraints(ca=True, path_length=0), True), (_key_usage(authority=True), True)],
    )
    _write(targets["ca"], ca_pem, private=False)
    _write(targets["ca-key"], _pem_key(ca_key), private=True)
    for role in ROLES:
        key = ec.generate_private_key(ec.SECP256R1())
        names = [*(_names(hosts) if role == "node" else []), x509.DNSName(COMMON_NAMES[role])]
        usage = [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
        cert_pem = _certificate(
            COMMON_NAMES[role],
            key,
            authority,
            validity,
            [
                (x509.BasicConstraints(ca=False, path_length=None), True),
                (_key_usage(authority=False), True),
                (x509.ExtendedKeyUsage(usage), False),
                (x509.SubjectAlternativeName(names), False),
                (x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), False),
            ],
        )
        text = json.dumps(zenoh_config(role, ca_pem, cert_pem, _pem_key(key)), indent=2) + "\n"
        _write(targets[role], text.encode(), private=True)
    return Deployment(directory, targets, hosts, validity[1])


def _write(path: Path, data: bytes, private: bool) -> None:
    """Replace ``path`` atomically; the temporary file is private (0600) from the start."""
    write_atomically(path, data)
    if not private:
        path.chmod(0o644)
