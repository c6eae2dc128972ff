"""The compass module's arithmetic (seed §3.3.3): two KMZ51 bridges at 90°, flip and compensation.

A measurement takes each bridge's ADC samples with the flip coil set and again with it reset: half
the difference is the field the bridge sees (its own electrical offset cancels), half the sum is
that offset. Averaging 20 samples at 1 kHz spans one 50 Hz period, so mains fields cancel too.
The compensation coil cancels the motors' static field in the sensor (learned by calibration:
a circle fit through readings taken at rest at eight headings); it lowers the bridge's gain a
little, which is a known factor. Of the two bridges, the one within ±45° of its zero crossing
(the steep part of its sine) gives the angle by arccos; the other only says which side.
Heading: navigation convention, radians from north, clockwise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

ADC_MID = 2048
COUNTS_PER_UT = 20.0  # bridge + amplifier: the module's datasheet value
COMPENSATION_SENSITIVITY_LOSS = 0.002  # relative gain lost per µT of compensation field
SIN45 = math.sqrt(0.5)


def bridge_gain(compensation_ut: float) -> float:
    """ADC counts per µT of a bridge carrying ``compensation_ut`` in its compensation coil."""
    return COUNTS_PER_UT * (1.0 - COMPENSATION_SENSITIVITY_LOSS * abs(compensation_ut))


def flip_measurement(
    plus: np.ndarray, minus: np.ndarray, compensation_ut: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Samples (2 bridges x n) taken flipped and reset -> (field each bridge sees after
    compensation in µT, each bridge's electrical offset in counts)."""
    vp, vm = np.asarray(plus, float).mean(axis=1), np.asarray(minus, float).mean(axis=1)
    gains = np.array([bridge_gain(c) for c in compensation_ut])
    return (vp - vm) / (2 * gains), (vp + vm) / 2 - ADC_MID


def heading_from_bridges(h0: float, h1: float) -> tuple[float, int]:
    """Heading (radians from north, clockwise, [0, 2 pi)) from bridge 0 (forward axis, sees
    H cos psi) and bridge 1 (left axis, sees H sin psi), and which bridge gave the angle."""
    magnitude = math.hypot(h0, h1)
    if magnitude == 0:
        return 0.0, 0
    c0, c1 = h0 / magnitude, h1 / magnitude
    if abs(c0) <= SIN45:  # bridge 0 is on the steep part of its sine
        angle = math.acos(max(-1.0, min(1.0, c0)))
        heading = angle if c1 >= 0 else 2 * math.pi - angle
        return heading % (2 * math.pi), 0
    angle = math.acos(max(-1.0, min(1.0, c1)))  # angle between the field and bridge 1's axis
    heading = math.pi / 2 + angle if c0 <= 0 else math.pi / 2 - angle
    return heading % (2 * math.pi), 1


def fit_circle(points: np.ndarray) -> tuple[float, float, float]:
    """Least-squares circle (Kasa) through 2-D points: (centre x, centre y, radius)."""
    pts = np.asarray(points, dtype=float)
    if len(pts) < 3:
        raise ValueError("a circle needs at least three points")
    a = np.column_stack([pts[:, 0], pts[:, 1], np.ones(len(pts))])
    b = -(pts[:, 0] ** 2 + pts[:, 1] ** 2)
    (d, e, f), *_ = np.linalg.lstsq(a, b, rcond=None)
    cx, cy = -d / 2, -e / 2
    return float(cx), float(cy), float(math.sqrt(max(cx * cx + cy * cy - f, 0.0)))


def circular_mean(angles: Sequence[float]) -> float:
    """Mean direction of angles (radians), in [0, 2 pi)."""
    s = sum(math.sin(a) for a in angles)
    c = sum(math.cos(a) for a in angles)
    return math.atan2(s, c) % (2 * math.pi)


def angle_difference(a: float, b: float) -> float:
    """a - b folded into (-pi, pi]."""
    d = math.remainder(a - b, 2 * math.pi)
    return math.pi if d == -math.pi else d
