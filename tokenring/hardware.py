"""The hardware interface: how a module's program reaches its (simulated) hardware.

Programs never see the world directly: the node process opens a hardware client for its module
(``open_hardware``) and hands it to the program as ``self.hw``. Clients talk to the world
simulator over ``tokenring/<ring>/hw/<module>/...`` (see :mod:`tokenring.world.service` for the
key space and :mod:`tokenring.hw` for the clients), never over the ring. A module without
hardware gets ``None``.
"""

from __future__ import annotations

from typing import Any

import zenoh

from tokenring.hw import CLIENTS

#: module name -> factory(session, ring) returning that module's hardware client
FACTORIES: dict[str, Any] = dict(CLIENTS)
FACTORIES["lcd"] = lambda session, ring: __import__("tokenring.lcdhw").lcdhw.open_lcd(session, ring)


def open_hardware(module: str, session: zenoh.Session, ring: str) -> Any | None:
    """The hardware client of ``module`` on this ring, or None if it has no hardware."""
    factory = FACTORIES.get(module)
    return factory(session, ring) if factory is not None else None
