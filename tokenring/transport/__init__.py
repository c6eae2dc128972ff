"""Transports carrying the ring (see :mod:`tokenring.transport.base` for the boundary), Zenoh's
configuration for every process, and a tool's sessions with a running ring."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring.transport.base import Transport
    from tokenring.transport.memory import MemoryHub, MemoryTransport
    from tokenring.transport.session import discover, free_port, query, query_one
    from tokenring.transport.zenoh_config import (
        HOST_RUNTIME,
        NODE_RUNTIME,
        RUNTIME_CHOSEN,
        make_config,
        open_session,
        use_host_runtime,
    )
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "discover": "tokenring.transport.session",
            "free_port": "tokenring.transport.session",
            "HOST_RUNTIME": "tokenring.transport.zenoh_config",
            "make_config": "tokenring.transport.zenoh_config",
            "MemoryHub": "tokenring.transport.memory",
            "MemoryTransport": "tokenring.transport.memory",
            "NODE_RUNTIME": "tokenring.transport.zenoh_config",
            "open_session": "tokenring.transport.zenoh_config",
            "query": "tokenring.transport.session",
            "query_one": "tokenring.transport.session",
            "RUNTIME_CHOSEN": "tokenring.transport.zenoh_config",
            "Transport": "tokenring.transport.base",
            "use_host_runtime": "tokenring.transport.zenoh_config",
        },
    )

__all__ = [
    "HOST_RUNTIME",
    "NODE_RUNTIME",
    "RUNTIME_CHOSEN",
    "MemoryHub",
    "MemoryTransport",
    "Transport",
    "discover",
    "free_port",
    "make_config",
    "open_session",
    "query",
    "query_one",
    "use_host_runtime",
]
