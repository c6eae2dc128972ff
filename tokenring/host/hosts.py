"""The inventory of ``tokenring up --hosts FILE``: which hosts the ring spans, how each is
reached and which of protocol.yaml's nodes it runs. Every mistake names the file and line
(exit code 2) before anything starts.

    port: 7447                 # each host's Zenoh router listens on ADDRESS:PORT (default 7447)
    scheme: tcp                # tcp, or tls for a secured ring (up --zenoh-config node.json5)
    lost_after: 30             # a share that hears nothing from the launcher this long stops
    hosts:
      pc:                      # the launcher's own host: the hub router, no SSH
        address: 10.0.0.1
        ssh: local
        nodes: [main, motor]
      board1:
        address: 10.0.0.2
        ssh: {user: robot, port: 22, identity: ~/.ssh/ring_ed25519, options: [-o, Compression=no]}
                               # (ssh: {host: ALIAS}: an ssh_config Host to reach it by, if not its address)
        nodes: 3               # the next three of protocol.yaml's nodes no other host names
        tokenring: /opt/ring/.venv/bin/tokenring
        store: /var/lib/tokenring
        zenoh_config: /etc/tokenring/node.json5
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tokenring._util.strict_yaml import read_yaml
from tokenring.errors import UsageError

DEFAULT_PORT = 7447
#: seconds a share runs on without a word from the launcher (docs/hosts.md says why 30)
DEFAULT_LOST_AFTER_S = 30.0
LOST_AFTER_RANGE_S = (5.0, 86_400.0)
SCHEMES = ("tcp", "tls")
TOP_KEYS = ("hosts", "port", "scheme", "lost_after")
HOST_KEYS = ("address", "ssh", "nodes", "tokenring", "store", "zenoh_config", "port", "lost_after")
SSH_KEYS = ("host", "user", "port", "identity", "options")


@dataclass
class Host:
    """One host of the ring and how the launcher reaches it."""

    name: str
    address: str
    line: int  # where the inventory names it
    local: bool = False  # the launcher's own host: no SSH, its router is the hub
    nodes: list[str] = field(default_factory=list)
    ssh_host: str | None = None  # what ssh is given (an ssh_config alias), else the address
    user: str | None = None
    ssh_port: int | None = None
    identity: str | None = None
    ssh_options: list[str] = field(default_factory=list)
    tokenring: list[str] = field(default_factory=lambda: ["tokenring"])
    store: str | None = None
    zenoh_config: str | None = None
    zenoh_port: int = DEFAULT_PORT
    lost_after: float = DEFAULT_LOST_AFTER_S  # its share stops after this long without the launcher

    def endpoint(self, scheme: str) -> str:
        """Where this host's router listens (and its nodes and the other routers reach it)."""
        address = f"[{self.address}]" if ":" in self.address else self.address
        return f"{scheme}/{address}:{self.zenoh_port}"


@dataclass
class Inventory:
    source: str
    hosts: list[Host]
    scheme: str = "tcp"

    @property
    def local(self) -> Host:
        return next(h for h in self.hosts if h.local)

    @property
    def remote(self) -> list[Host]:
        return [h for h in self.hosts if not h.local]

    def where(self, host: Host) -> str:
        """``FILE:LINE`` of a host, for messages."""
        return f"{self.source}:{host.line}"

    @property
    def node_count(self) -> int:
        return sum(len(h.nodes) for h in self.hosts)


def _port(value: Any, fail: Any, entry: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= 65535:
        raise fail(entry, f"{value!r} is not a port number 1..65535")
    return value


def _seconds(value: Any, fail: Any, entry: str) -> float:
    low, high = LOST_AFTER_RANGE_S
    if not isinstance(value, int | float) or isinstance(value, bool) or not low <= value <= high:
        raise fail(entry, f"{value!r} is not a number of seconds {low:g}..{high:g}")
    return float(value)


def _text(value: Any, fail: Any, entry: str, what: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise fail(entry, f"expected {what}, not {value!r}")
    return value.strip()


def load_inventory(path: str | Path, protocol: Any) -> Inventory:
    """Read and check an inventory against ``protocol`` (every node named exists, none twice)."""
    data, lines = read_yaml(path)
    source = str(path)

    def fail(entry: str, problem: str) -> UsageError:
        line = lines.get(entry)
        return UsageError(f"{source}:{line}: {entry}: {problem}" if line else f"{source}: {entry}: {problem}")

    if not isinstance(data, dict) or not isinstance(data.get("hosts"), dict) or not data["hosts"]:
        raise UsageError(
            f"{source}:1: an inventory is a mapping with 'hosts': {{NAME: {{address, ssh, nodes}}, ...}}"
        )
    for key in data:
        if key not in TOP_KEYS:
            raise fail(str(key), f"unknown key (allowed: {', '.join(TOP_KEYS)})")
    scheme = data.get("scheme", "tcp")
    if scheme not in SCHEMES:
        raise fail("scheme", f"{scheme!r} is not one of {', '.join(SCHEMES)}")
    port = _port(data.get("port", DEFAULT_PORT), fail, "port")
    lost_after = _seconds(data.get("lost_after", DEFAULT_LOST_AFTER_S), fail, "lost_after")
    hosts: list[Host] = []
    for name, raw in data["hosts"].items():
        entry = f"hosts.{name}"
        if not isinstance(name, str) or not name or "/" in name or " " in name:
            raise fail(entry, "a host's name is a word (it prefixes the host's log lines)")
        if not isinstance(raw, dict):
            raise fail(entry, "expected a mapping with address, ssh and nodes")
        for key in raw:
            if key not in HOST_KEYS:
                raise fail(f"{entry}.{key}", f"unknown key (allowed: {', '.join(HOST_KEYS)})")
        if "address" not in raw:
            raise fail(entry, "no address (the host's name or IP address on the network)")
        host = Host(name, _text(raw["address"], fail, f"{entry}.address", "an address"), lines.get(entry, 1))
        host.zenoh_port = _port(raw.get("port", port), fail, f"{entry}.port")
        host.lost_after = _seconds(raw.get("lost_after", lost_after), fail, f"{entry}.lost_after")
        ssh = raw.get("ssh", {})
        if ssh == "local":
            host.local = True
        elif isinstance(ssh, dict):
            for key in ssh:
                if key not in SSH_KEYS:
                    raise fail(f"{entry}.ssh.{key}", f"unknown key (allowed: {', '.join(SSH_KEYS)})")
            if ssh.get("host") is not None:
                host.ssh_host = _text(
                    ssh["host"], fail, f"{entry}.ssh.host", "a host name or ssh_config alias"
                )
            if ssh.get("user") is not None:
                host.user = _text(ssh["user"], fail, f"{entry}.ssh.user", "a user name")
            if ssh.get("port") is not None:
                host.ssh_port = _port(ssh["port"], fail, f"{entry}.ssh.port")
            if ssh.get("identity") is not None:
                identity = _text(ssh["identity"], fail, f"{entry}.ssh.identity", "a key file")
                if not Path(identity).expanduser().is_file():
                    raise fail(f"{entry}.ssh.identity", f"no such key file: {identity}")
                host.identity = str(Path(identity).expanduser())
            options = ssh.get("options", [])
            if not isinstance(options, list) or not all(isinstance(o, str) for o in options):
                raise fail(
                    f"{entry}.ssh.options", "expected a list of ssh arguments, e.g. [-o, Compression=no]"
                )
            host.ssh_options = list(options)
        else:
            raise fail(f"{entry}.ssh", "expected 'local' or a mapping of host, user, port, identity, options")
        if "tokenring" in raw:
            command = _text(raw["tokenring"], fail, f"{entry}.tokenring", "the tokenring command there")
            try:
                host.tokenring = shlex.split(command)
            except ValueError as exc:
                raise fail(f"{entry}.tokenring", f"cannot split {command!r}: {exc}") from None
        for key in ("store", "zenoh_config"):
            if raw.get(key) is not None:
                setattr(host, key, _text(raw[key], fail, f"{entry}.{key}", "a path on that host"))
        hosts.append(host)
    local = [h for h in hosts if h.local]
    if len(local) != 1:
        raise UsageError(
            f"{source}:{lines.get('hosts', 1)}: hosts: exactly one host must be 'ssh: local' (the "
            f"launcher's own, the hub router), not {len(local)}"
        )
    seen_endpoints: dict[tuple[str, int], str] = {}
    for host in hosts:
        key = (host.address, host.zenoh_port)
        if key in seen_endpoints:
            raise fail(
                f"hosts.{host.name}",
                f"{host.address}:{host.zenoh_port} is host {seen_endpoints[key]}'s router already "
                "(give one of them another port)",
            )
        seen_endpoints[key] = host.name
    _place_nodes(data["hosts"], hosts, protocol, fail)
    return Inventory(source, hosts, scheme)


def _place_nodes(raw_hosts: dict[str, Any], hosts: list[Host], protocol: Any, fail: Any) -> None:
    """Each host's nodes: a list of names or IDs, or a count of the next nodes of protocol.yaml's
    (its default ring, in ID order) that no host names."""
    owner: dict[int, str] = {}
    counts: list[tuple[Host, int]] = []
    for host in hosts:
        entry = f"hosts.{host.name}.nodes"
        value = raw_hosts[host.name].get("nodes")
        if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
            counts.append((host, value))
            continue
        if not isinstance(value, list):
            raise fail(
                entry if value is not None else f"hosts.{host.name}",
                "expected nodes: a list of node names or IDs, or how many nodes the host runs",
            )
        for item in value:
            try:
                spec = protocol.node(int(item) if str(item).isdigit() else str(item))
            except Exception:
                known = ", ".join(protocol.nodes)
                raise fail(entry, f"unknown node {item!r} (known: {known})") from None
            if spec.id in owner:
                raise fail(entry, f"node {spec.name} is on host {owner[spec.id]} already")
            owner[spec.id] = host.name
            host.nodes.append(spec.name)
    free = [n for n in protocol.default_nodes if n.id not in owner]
    for host, count in counts:
        if count > len(free):
            raise fail(
                f"hosts.{host.name}.nodes",
                f"{count} nodes asked, {len(free)} of protocol.yaml's default nodes are left",
            )
        taken, free = free[:count], free[count:]
        host.nodes = [n.name for n in taken]
        for spec in taken:
            owner[spec.id] = host.name
    if not owner:
        raise fail("hosts", "no host runs a node")
