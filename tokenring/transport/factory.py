"""Pick a transport backend by name (``tokenring node --transport``): what the node process uses."""

from __future__ import annotations

from typing import Any

from tokenring.errors import UsageError
from tokenring.transport.base import Transport

TRANSPORTS = ("zenoh", "udp", "zmq")


#: socket backends and the optional package each needs (pyproject.toml's extras)
EXTRAS = {"zmq": ("zmq", "pyzmq", "zmq")}


def require_backend(kind: str) -> None:
    """Refuse a backend whose optional package is missing, naming the extra that installs it."""
    import importlib.util

    if kind in EXTRAS:
        module, package, extra = EXTRAS[kind]
        if importlib.util.find_spec(module) is None:
            raise UsageError(
                f"--transport {kind} needs {package}, which is not installed: pip install 'tokenring[{extra}]'"
            )


def make_transport(
    kind: str,
    session: Any,
    ring: str,
    node_id: int,
    frame_size: int,
    registry: str | None = None,
    link_session: Any = None,
) -> Transport:
    """The token path's transport: ``zenoh`` on the node's session (with ``link_session``, a
    peer linked to the successor, the hop over that link), or a socket backend that finds its
    peers through the membership registry at ``registry`` (HOST:PORT)."""
    if kind == "zenoh" and link_session is not None:
        from tokenring.transport.links import LinkedZenohTransport

        return LinkedZenohTransport(session, link_session, ring, node_id, frame_size)
    if kind == "zenoh":
        from tokenring.transport.zenoh import ZenohTransport

        return ZenohTransport(session, ring, node_id, frame_size)
    if kind not in TRANSPORTS:
        raise UsageError(f"--transport {kind!r}: unknown (known: {', '.join(TRANSPORTS)})")
    if not registry:
        raise UsageError(
            f"--transport {kind} needs --registry HOST:PORT (the launcher's membership registry)"
        )
    require_backend(kind)
    from tokenring.transport.registry import parse_address
    from tokenring.transport.sockets import BACKENDS

    parse_address(registry)
    return BACKENDS[kind](ring, node_id, registry, frame_size=frame_size)
