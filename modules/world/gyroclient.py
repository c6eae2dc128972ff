"""The gyro module's hardware client: its serial line to the world's gyroscope (``hw/gyro/read``,
:mod:`modules.world.gyroscope`)."""

from __future__ import annotations

from modules.world.clients import HardwareClient


class GyroHardware(HardwareClient):
    """The gyro's serial line: every raw value since the last read, with its time stamp."""

    module = "gyro"

    def read(self) -> tuple[list[int], list[float], int]:
        """The raw values (counts) taken since the last read, their stamps (ms), and how many
        older ones were lost (not read in time)."""
        result = self.request("gyro/read")
        return [int(r) for r in result["raw"]], [float(s) for s in result["stamps_ms"]], int(result["lost"])
