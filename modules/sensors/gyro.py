"""The gyro module's arithmetic (Darmstadt seed 000 §6.2.3): the zero point averaged at rest,
rates from raw values, the orientation by summing.

ω = (raw − NP) · SF (rad/s; the seed's increment per sample is ω·T), NP the mean of the raw
values taken while the robot stood still, SF constant (the nominal scale factor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

#: the nominal scale factor, rad/s per count (seed fig. 10.2: one bit = 1.7436e-5 rad in 20.48 ms)
SCALE_RAD_S = 8.51359e-4
SAMPLE_S = 0.02048
CALIBRATION_SAMPLES = 100  # 2.05 s at rest


@dataclass
class ZeroPointCalibration:
    """The mean of ``wanted`` raw values taken at rest (seed §3.2: the zero point)."""

    wanted: int = CALIBRATION_SAMPLES
    values: list[int] = field(default_factory=list)

    def add(self, raw: int) -> bool:
        """Take one raw value; True once ``wanted`` are in."""
        if not self.done:
            self.values.append(int(raw))
        return self.done

    @property
    def done(self) -> bool:
        return len(self.values) >= self.wanted

    def restart(self) -> None:
        """The robot moved: the values so far are not at rest."""
        self.values.clear()

    @property
    def zero_point(self) -> float:
        """The mean of the values (counts, not whole)."""
        return sum(self.values) / len(self.values)

    @property
    def spread(self) -> float:
        """Standard deviation of the values (counts): the noise the mean averaged."""
        n = len(self.values)
        if n < 2:
            return 0.0
        mean = self.zero_point
        return math.sqrt(sum((v - mean) ** 2 for v in self.values) / (n - 1))


def rate(raw: int, zero_point: float, scale: float = SCALE_RAD_S) -> float:
    """ω in rad/s, counter-clockwise positive."""
    return (raw - zero_point) * scale
