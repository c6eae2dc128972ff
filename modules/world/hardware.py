"""The hardware interface: how a module's program reaches its (simulated) hardware.

Programs never see the world directly: the node process asks the ring's extensions for its
module's hardware (the robot's is :func:`open_hardware`, through :mod:`modules.plugin`) and hands
it to the program as ``self.hw``. Clients talk to the world simulator over
``tokenring/<ring>/hw/<module>/...`` (see :mod:`modules.world.service` for the key space and
:mod:`modules.world.clients` for the clients), never over the ring. A module without hardware
gets ``None``.
"""

from __future__ import annotations

from typing import Any

import zenoh

from modules.world.clients import CLIENTS, TruthFeed


def _open_lcd(session: zenoh.Session, ring: str) -> Any:
    from modules.world.lcdpanel import open_lcd

    return open_lcd(session, ring)


def _open_gyro(session: zenoh.Session, ring: str) -> Any:
    from modules.world.gyroclient import GyroHardware

    return GyroHardware(session, ring)


def _open_correlator(session: zenoh.Session, ring: str) -> Any:
    from modules.world.correlatorclient import CorrelatorHardware

    return CorrelatorHardware(session, ring)


#: module name -> factory(session, ring) returning that module's hardware client
FACTORIES: dict[str, Any] = {
    **CLIENTS,
    "lcd": _open_lcd,
    "copro": TruthFeed,
    "gyro": _open_gyro,
    "correlator": _open_correlator,
}


def open_hardware(module: str, session: zenoh.Session, ring: str) -> Any | None:
    """The hardware client of ``module`` on this ring, or None if it has no hardware."""
    factory = FACTORIES.get(module)
    return factory(session, ring) if factory is not None else None
