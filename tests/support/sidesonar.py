"""Synthetic side-sonar data for copro tests: a 30° beam over wall segments and the seed's classifier.

Deliberately independent of the world simulator: the nearest wall point inside the beam, rounded
to whole centimetres (optionally with Gaussian noise), and behaviours from first and second
differences as in the seed's ``observe_sensor``.
"""

from __future__ import annotations

import math

import numpy as np

from modules.mapping.vectorgen import DEGRESSIVE, LINEAR, NO_CONTACT_CM, PROGRESSIVE, SideSensors

BEHAVIOUR_NONE = 0
HALF_BEAM = math.radians(15.0)


def beam_distance_cm(
    origin: tuple[float, float],
    heading: float,
    walls: list[tuple[float, float, float, float]],
    max_mm: float = 1500.0,
    rng: np.random.Generator | None = None,
    sigma_cm: float = 0.0,
) -> int:
    """Distance (cm) to the nearest wall point inside the beam, 255 without contact."""
    best = math.inf
    ox, oy = origin
    for x1, y1, x2, y2 in walls:
        n = max(2, int(math.hypot(x2 - x1, y2 - y1) / 2.0))
        t = np.linspace(0.0, 1.0, n)
        px, py = x1 + t * (x2 - x1), y1 + t * (y2 - y1)
        dx, dy = px - ox, py - oy
        dist = np.hypot(dx, dy)
        bearing = np.abs((np.arctan2(dy, dx) - heading + math.pi) % (2 * math.pi) - math.pi)
        inside = bearing <= HALF_BEAM
        if inside.any():
            best = min(best, float(dist[inside].min()))
    if best > max_mm:
        return NO_CONTACT_CM
    cm = best / 10.0 + (rng.normal(0.0, sigma_cm) if rng is not None and sigma_cm else 0.0)
    return max(0, min(254, round(cm)))


def side_readings(
    pose: tuple[float, float, float],
    sensors: SideSensors,
    walls: list[tuple[float, float, float, float]],
    rng: np.random.Generator | None = None,
    sigma_cm: float = 0.0,
) -> tuple[int, int]:
    """(front, rear) readings of one side at ``pose``."""
    x, y, th = pose
    out = []
    for sx, sy in (sensors.front_xy, sensors.rear_xy):
        origin = (x + sx * math.cos(th) - sy * math.sin(th), y + sx * math.sin(th) + sy * math.cos(th))
        out.append(beam_distance_cm(origin, th + sensors.direction, walls, rng=rng, sigma_cm=sigma_cm))
    return out[0], out[1]


class SeedClassifier:
    """The seed's per-sensor behaviour: second difference 0 (± tolerance) → LINEAR, >0 DEGRESSIVE."""

    def __init__(self, tolerance_cm: int = 1) -> None:
        self.tolerance = tolerance_cm
        self.history: list[int] = []

    def feed(self, cm: int) -> int:
        if cm == NO_CONTACT_CM:
            self.history = []
            return BEHAVIOUR_NONE
        self.history = [*self.history[-2:], cm]
        if len(self.history) < 3:
            return BEHAVIOUR_NONE
        a, b, c = self.history
        second = (c - b) - (b - a)
        if abs(second) <= self.tolerance:
            return LINEAR
        return DEGRESSIVE if second > 0 else PROGRESSIVE
