"""Pick a transport backend by name (``tokenring node --transport``): what the node process uses."""

from __future__ import annotations

from typing import Any

from tokenring.errors import UsageError
from tokenring.transport.base import Transport

TRANSPORTS = ("zenoh", "udp", "zmq")


def make_transport(
    kind: str, session: Any, ring: str, node_id: int, frame_size: int, registry: str | None = None
) -> Transport:
    """The token path's transport: ``zenoh`` on the node's session, or a socket backend that
    finds its peers through the membership registry at ``registry`` (HOST:PORT)."""
    if kind == "zenoh":
        from tokenring.transport.zenoh import ZenohTransport

        return ZenohTransport(session, ring, node_id, frame_size)
    if kind not in TRANSPORTS:
        raise UsageError(f"--transport {kind!r}: unknown (known: {', '.join(TRANSPORTS)})")
    if not registry:
        raise UsageError(
            f"--transport {kind} needs --registry HOST:PORT (the launcher's membership registry)"
        )
    from tokenring.transport.registry import parse_address
    from tokenring.transport.sockets import BACKENDS

    parse_address(registry)
    return BACKENDS[kind](ring, node_id, registry, frame_size=frame_size)
