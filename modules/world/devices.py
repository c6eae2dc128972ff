"""The world's devices beyond the Hamburg robot's: the Darmstadt sensors (seed 000 §3).

Each is made once per world from its :class:`~modules.world.sim.Simulator` and answers the
requests below ``hw/<name>/`` (``handle(what, request)``); the simulator's own hardware (motor,
sonar, compass, charger) stays in :mod:`modules.world.sim`. A sensor joins by adding its
factory here (the gyro and the floor correlator; LOPS runs beside the ring, not in the world).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from modules.world.correlator import CorrelatorDevice
from modules.world.gyroscope import GyroDevice
from modules.world.sim import Simulator

#: device name (the first part of its ``hw/`` keys) -> factory(simulator)
DEVICES: dict[str, Callable[[Simulator], Any]] = {"gyro": GyroDevice, "correlator": CorrelatorDevice}


def attach_devices(sim: Simulator) -> dict[str, Any]:
    """One device of each kind for ``sim`` (same seed, same clock)."""
    return {name: make(sim) for name, make in DEVICES.items()}
