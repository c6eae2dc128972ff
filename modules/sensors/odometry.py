"""The motor module's arithmetic: steps for a move, the glide factor, dead reckoning from steps.

No encoders (seed §4.3.3): the half-steps issued *are* the odometry. Straight: 0.5419 mm per
half-step. Turning on the spot: the glide factor μ (half-steps per degree, ≈ 6.5 on tiles)
converts degrees into steps; it depends on the floor and is corrected by RECALC_GLIDE_FACTOR with
the seed's formula (4.2): μ_new = α_target / (α_target + Δα) · μ_old.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from modules.description.robot import DEFAULT_GLIDE_FACTOR, MAX_STEP_RATE_HZ, STEP_MM
from modules.units import wrap_angle

GLIDE_MIN, GLIDE_MAX = 1.0, 60.0  # a glide factor outside this is a measuring mistake


def recalc_glide_factor(glide: float, target_deg: float, error_deg: float) -> float:
    """The seed's formula (4.2). ``error_deg`` is the angle actually turned minus ``target_deg``
    (a robot that turned 80° of 90° has error -10 and needs more steps: μ grows by 90/80)."""
    turned = target_deg + error_deg
    if target_deg == 0 or turned == 0 or (turned > 0) != (target_deg > 0):
        raise ValueError(f"cannot correct the glide factor from {target_deg:g}° wanted, {turned:g}° turned")
    new = target_deg / turned * glide
    if not GLIDE_MIN <= new <= GLIDE_MAX:
        raise ValueError(f"the corrected glide factor {new:.2f} is implausible (keep {glide:.2f})")
    return new


def steps_for_distance(distance_mm: float) -> int:
    """Half-steps for a straight move."""
    return round(abs(distance_mm) / STEP_MM)


def steps_for_angle(angle_deg: float, glide: float = DEFAULT_GLIDE_FACTOR) -> int:
    """Half-steps of each track for a turn on the spot."""
    return round(abs(angle_deg) * glide)


def step_rate_hz(speed_pct: float) -> float:
    """Half-steps per second at ``speed_pct`` (100 % = 10 cm/s)."""
    return MAX_STEP_RATE_HZ * speed_pct / 100.0


@dataclass
class DeadReckoning:
    """Pose from the issued half-steps: x, y in mm, theta in radians CCW.

    Each batch splits into its common part (straight, ``STEP_MM`` per half-step) and its
    difference (a turn, ``1/glide`` degree per half-step of each track, right track forward =
    counter-clockwise), applied at the mid-heading (Darmstadt §6.2.2)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    glide: float = DEFAULT_GLIDE_FACTOR

    def apply(self, left: int, right: int) -> tuple[float, float]:
        """Advance by ``left``/``right`` half-steps (signed, + = forward); returns (mm, rad)."""
        distance = (left + right) / 2 * STEP_MM
        rotation = math.radians((right - left) / 2 / self.glide)
        mid = self.theta + rotation / 2
        self.x += distance * math.cos(mid)
        self.y += distance * math.sin(mid)
        self.theta = wrap_angle(self.theta + rotation)
        return distance, rotation

    def set(self, x: float, y: float, theta: float) -> None:
        self.x, self.y, self.theta = x, y, wrap_angle(theta)


@dataclass
class Move:
    """A move in progress: signed step rates and totals per track."""

    seq: int
    commander: int
    direction: int
    speed_pct: int
    total: tuple[int, int]  # |steps| per track
    sign: tuple[int, int]
    rate_hz: tuple[float, float]
    start_ms: float
    issued: tuple[int, int] = (0, 0)
