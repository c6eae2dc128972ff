"""What the launcher hands each node process: its command line (ring, bitrate, endpoints, direct
links, program, profile), the endpoints a node and a tool reach the ring at, and whether an
application adds a resident program to the node. Mixed into :class:`~tokenring.host.launcher.Launcher`,
which sets up the state it reads."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

from tokenring.contract import keys
from tokenring.transport.session import free_port

if TYPE_CHECKING:
    from tokenring.host.launcher import NodePlan


class NodeCommandLines:
    """The node processes' command lines, from the launcher's settings."""

    plans: list[NodePlan]
    ring: str
    bitrate: str
    ack_mode: str
    connect: list[str]
    listen: list[str]
    zenoh_config: str | None
    protocol_path: str | None
    log_level: str
    extra_node_args: list[str]
    extra_env: dict[str, str]
    expected_nodes: int | None
    residents: bool
    router: bool
    links: bool
    link_ports: dict[int, int]
    transport: str
    profile: str | None
    registry: Any
    endpoint: str | None
    _protocol_cache: Any

    def tool_options(self) -> list[str]:
        """The options a tool (``tokenring load``, ...) needs to reach this ring: ``--ring`` and
        ``-e`` where they differ from the tools' defaults."""
        options = [] if self.ring == keys.DEFAULT_RING else ["--ring", self.ring]
        endpoint = self.node_connect()[0]
        return options if endpoint == keys.default_endpoint() else [*options, "-e", endpoint]

    def node_connect(self) -> list[str]:
        return [self.endpoint] if self.endpoint else list(self.connect or [keys.default_endpoint()])

    def node_listen(self) -> list[str]:
        if self.router:
            return []  # clients of this host's router listen nowhere
        scheme, host = "tcp", "127.0.0.1"
        if self.endpoint:
            # the tap's scheme too: a secured ring (tls/) must not open plain TCP listeners
            scheme, rest = self.endpoint.split("/", 1)
            host = rest.rsplit(":", 1)[0]
            if host in ("0.0.0.0", "[::]"):
                host = "0.0.0.0"
        return [f"{scheme}/{host}:0"]

    def command_for(self, plan: NodePlan) -> list[str]:
        cmd = [sys.executable, "-m", "tokenring", "--log-level", self.log_level, "node"]
        cmd += ["--id", str(plan.node_id), "--ring", self.ring, "--bitrate", self.bitrate]
        cmd += ["--ack", self.ack_mode, "--expect", str(self.expected_nodes or len(self.plans))]
        if plan.name and not plan.name.startswith("node"):
            cmd += ["--name", plan.name]
        if self.protocol_path:
            cmd += ["--protocol", self.protocol_path]
        if self.zenoh_config:
            cmd += ["--zenoh-config", self.zenoh_config]
        for endpoint in self.node_connect():
            cmd += ["--connect", endpoint]
        for endpoint in self.node_listen():
            cmd += ["--listen", endpoint]
        if self.router:
            cmd += ["--mode", "client"]
        if self.links:
            cmd += self.link_options(plan.node_id)
        if plan.program:
            cmd += ["--program", plan.program]
        if self.registry is not None:
            cmd += ["--transport", self.transport, "--registry", self.registry.address]
        if self.profile:
            cmd += ["--profile", self.profile]
        if not self.has_resident(plan):
            cmd += ["--no-resident"]  # the node then loads no application before a program starts
        return cmd + self.extra_node_args + plan.extra_args

    def link_options(self, node_id: int) -> list[str]:
        """A node's direct link: where it listens and its ring successor's endpoint. Ports stay
        with their node ID, so a respawned node listens where its predecessor reconnects; a
        node that joins later is reached through the router until it is someone's successor
        at launch."""
        ids = sorted({p.node_id for p in self.plans} | {node_id})
        successor = ids[(ids.index(node_id) + 1) % len(ids)]
        for wanted in (node_id, successor):
            if wanted not in self.link_ports:
                self.link_ports[wanted] = free_port(avoid=self.link_ports.values())
        options = ["--link-listen", f"tcp/127.0.0.1:{self.link_ports[node_id]}"]
        if successor != node_id:
            options += ["--link-connect", f"tcp/127.0.0.1:{self.link_ports[successor]}"]
        return options

    def has_resident(self, plan: NodePlan) -> bool:
        """Whether an application adds a resident program to this node's OS (asked here, once
        per ring, so that the other nodes need not load the applications at boot)."""
        if not self.residents:
            return False
        if "TOKENRING_EXTENSIONS" in self.extra_env:
            return True  # the nodes have their own choice of applications: let them look
        from tokenring import extensions

        name = plan.name
        if name.startswith("node"):  # a generated plan: the node takes protocol.yaml's name
            spec = self._protocol().by_id.get(plan.node_id)
            name = spec.name if spec is not None else name
        return extensions.resident_program(name) is not None

    def _protocol(self) -> Any:
        if self._protocol_cache is None:
            from tokenring.contract.protocol import default_protocol, load_protocol

            self._protocol_cache = (
                load_protocol(self.protocol_path) if self.protocol_path else default_protocol()
            )
        return self._protocol_cache
