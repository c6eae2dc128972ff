"""Transports carrying the ring: see :mod:`tokenring.transport.base` for the boundary."""

from tokenring.transport.base import Transport
from tokenring.transport.memory import MemoryHub, MemoryTransport

__all__ = ["MemoryHub", "MemoryTransport", "Transport"]
