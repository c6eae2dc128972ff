"""The battery (ours): ``charger.data``'s voltages and remaining time, synchronised as the newest
sample (:class:`~modules.localization.sync.NewestSync`). Logged as ``B``, its records as they are
(``key=value``: appendix B has no battery); never fused, no position.
"""

from __future__ import annotations

from modules.localization.sensors.base import Sensor, SyncContext, register, sensor_settings
from modules.localization.sync import NewestSync


def _synchroniser(context: SyncContext) -> NewestSync:
    return NewestSync("battery")


BATTERY = register(
    Sensor(
        name="battery",
        letter="B",
        title="battery",
        rank=50,
        synchroniser=_synchroniser,
        channel="charger.data",
        value_fields=("electronics_mv", "motors_mv", "remaining_min", "state"),
        settings=sensor_settings(use=True),
    )
)
