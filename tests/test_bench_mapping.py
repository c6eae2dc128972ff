"""bench.mapping's compass figures from a recorded drive (no ring)."""

from __future__ import annotations

import math

import pytest

from bench.mapping import compass_error
from modules.common.units import heading_to_cdeg


def test_the_compass_error_on_straight_moves_is_fitted_as_a_harmonic_of_the_heading() -> None:
    """A running field misjudged by the calibration bends the heading on the move by
    b cos(heading) + c sin(heading); at rest the heading is right."""
    north = math.pi / 2
    truth, motor_log, compass_log = [], [], []
    for k in range(400):
        stamp = 1000 + 100 * k
        theta = (k // 50) * math.pi / 4  # eight legs, one per heading
        moving = k % 50 >= 10
        error = math.radians(0.4 * math.cos(theta) - 0.3 * math.sin(theta)) if moving else 0.0
        truth.append((stamp, 0.0, 0.0, theta))
        motor_log.append({"stamp_ms": stamp - 1, "direction": 1 if moving else 0, "state": int(moving)})
        heading = (north - theta + error) % (2 * math.pi)
        compass_log.append({"stamp_ms": stamp, "state": 1, "heading_cdeg": heading_to_cdeg(heading)})
    out = compass_error({"truth": truth, "motor_log": motor_log, "compass_log": compass_log}, settle_ms=0)
    assert out["moving_harmonic_deg"] == pytest.approx(0.5, abs=0.02)
