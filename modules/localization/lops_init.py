"""Position initialisation by LOPS (seed 000 §8, figure B.2): where the robot is and which way it
points, from LOPS's positions before and after a short straight drive.

The seed's program measured (``making first meassurement``), drove a short way forward (``driving
robot again...``), measured again and then set the robot's pose: the position is the second
measurement, the heading the direction from the first to the second. Here the Localizer watches
for that pattern in what it is given anyway — LOPS's positions while the robot stands, a straight
drive of at least ``drive_mm`` by the odometry, LOPS's positions at rest again — so any drive that
begins with a straight leg initialises it; the filter starts from that pose.

A fix counts at rest only ``settle_ms`` after the odometry stopped: LOPS stamps its packets on
arrival, so the first ones after a stop may have been measured while driving.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class LopsInitResult:
    """The pose found and how sure it is."""

    x_mm: float
    y_mm: float
    heading: float  # rad, counter-clockwise from +X
    sigma_mm: float
    sigma_deg: float
    drive_mm: float


@dataclass
class LopsInitialiser:
    """Collects LOPS's fixes at rest around a straight drive; :meth:`step` once per sync."""

    fixes: int = 5
    drive_mm: float = 300.0
    max_turn_deg: float = 2.0
    settle_ms: int = 500
    sigma_mm: float = 10.0  # one fix's
    #: fixes at the current rest, and the mean of the last rest's (the drive's start)
    at_rest: list[tuple[float, float]] = field(default_factory=list, init=False)
    start: tuple[float, float] | None = field(default=None, init=False)
    travelled_mm: float = field(default=0.0, init=False)
    turned: float = field(default=0.0, init=False)
    stopped_ms: int | None = field(default=None, init=False)
    moving: bool = field(default=True, init=False)

    def step(
        self, stamp_ms: int, moving: bool, s_mm: float, omega: float, fix: tuple[float, float] | None
    ) -> LopsInitResult | None:
        """One synchronisation: did the odometry move (``s_mm`` along, ``omega`` turned), and
        LOPS's newest position (None: none, or no position). Returns the pose once found."""
        if moving:
            if not self.moving:  # a drive starts: the rest before it is its start, if well measured
                self.start = _mean(self.at_rest) if len(self.at_rest) >= self.fixes else None
                self.travelled_mm = self.turned = 0.0
                self.at_rest = []
            self.travelled_mm += s_mm
            self.turned += omega
            self.moving = True
            return None
        if self.moving:
            self.moving = False
            self.stopped_ms = stamp_ms
        if fix is None or self.stopped_ms is None or stamp_ms - self.stopped_ms < self.settle_ms:
            return None
        self.at_rest.append(fix)
        if (
            self.start is None
            or abs(self.travelled_mm) < self.drive_mm
            or abs(math.degrees(self.turned)) > self.max_turn_deg
            or len(self.at_rest) < self.fixes
        ):
            return None
        end = _mean(self.at_rest)
        dx, dy = end[0] - self.start[0], end[1] - self.start[1]
        heading = math.atan2(dy, dx) + (math.pi if self.travelled_mm < 0 else 0.0)
        sigma = self.sigma_mm / math.sqrt(len(self.at_rest))
        # each end's mean errs by sigma; across the drive that turns the direction by their difference
        sigma_heading = math.degrees(math.atan2(sigma * math.sqrt(2.0), math.hypot(dx, dy)))
        return LopsInitResult(
            end[0], end[1], math.remainder(heading, 2 * math.pi), sigma, sigma_heading, self.travelled_mm
        )


def _mean(points: list[tuple[float, float]]) -> tuple[float, float]:
    return sum(p[0] for p in points) / len(points), sum(p[1] for p in points) / len(points)
