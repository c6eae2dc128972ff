"""The correlator module's hardware client: its serial line to the world's floor correlator
(``hw/correlator/read``, :mod:`modules.world.correlator`)."""

from __future__ import annotations

from typing import NamedTuple

from modules.world.clients import HardwareClient


class CorrelatorRead(NamedTuple):
    """One read of the serial line: the samples since the last read, oldest first."""

    increments_um: list[int]
    stamps_ms: list[float]
    lost: int  # older samples not read in time
    defective: bool  # the sensor is broken (the seed's body): it gives nothing


class CorrelatorHardware(HardwareClient):
    """The correlator's serial line: every translation increment since the last read, stamped."""

    module = "correlator"

    def read(self) -> CorrelatorRead:
        """The increments (µm) taken since the last read, their stamps (ms), how many older ones
        were lost, and whether the sensor is defective."""
        result = self.request("correlator/read")
        return CorrelatorRead(
            [int(i) for i in result["increments_um"]],
            [float(s) for s in result["stamps_ms"]],
            int(result["lost"]),
            bool(result.get("defective", False)),
        )
