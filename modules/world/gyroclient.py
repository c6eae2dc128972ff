"""The gyro module's hardware client: its serial line to the world's gyroscope (``hw/gyro/read``,
:mod:`modules.world.gyroscope`)."""

from __future__ import annotations

from modules.world.clients import HardwareClient
from modules.world.gyroscope import GyroDevice


class GyroHardware(HardwareClient):
    """The gyro's serial line: every raw value since the last read, with its time stamp."""

    module = "gyro"

    @classmethod
    def attached(cls, device: GyroDevice) -> GyroHardware:
        """A client wired straight to an in-process :class:`GyroDevice` (fast tests)."""
        client = cls(None, "local")  # type: ignore[arg-type]
        client.simulator = device
        client._clock = device.clock
        return client

    def read(self) -> tuple[list[int], list[float], int]:
        """The raw values (counts) taken since the last read, their stamps (ms), and how many
        older ones were lost (not read in time)."""
        result = self.request("gyro/read")
        return [int(r) for r in result["raw"]], [float(s) for s in result["stamps_ms"]], int(result["lost"])
