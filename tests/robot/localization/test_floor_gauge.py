"""Explore 2 gauges the floor's step at the first wall, so that its lap is drawn on a measured step.

The closed loop (modules/sim/closedloop.py: main's navigator and pilot, copro's filter, the simulated
robot) explores a bundled room; the filter's step scale is read when the lap's first follow segment
is planned and judged against the floor the world simulates (ground truth, for judging only).
"""

from __future__ import annotations

import math
from typing import Any

import pytest

from modules.navigation.navigator import WallSettings
from modules.sim.closedloop import ClosedLoop


def step_scale_as_the_lap_begins(room: str, gauge_mm: int) -> dict[str, Any]:
    """The filter's step scale, its σ and the travel fits used when the first follow segment is planned."""
    loop = ClosedLoop(room, seed=1)
    loop.navigator.s = WallSettings(gauge_mm=gauge_mm)
    plan = loop.navigator.plan
    seen: dict[str, Any] = {}

    def watched(last, sensors, alert_lock):
        moves = plan(last, sensors, alert_lock)
        if moves and "scale" not in seen and any(m.label == "follow" for m in moves):
            ekf = loop.core.ekf
            i = ekf.index["step_scale"]
            seen.update(
                scale=float(ekf.x[i]),
                sigma=math.sqrt(float(ekf.P[i, i])),
                used=loop.core.travel["used"],
                labels=[line.split(": ", 1)[-1] for line in loop.log],
            )
        return moves

    loop.navigator.plan = watched
    loop.run(1.5)
    assert "scale" in seen, "the lap never began"
    seen["floor"] = loop.world.floor.step_scale
    return seen


@pytest.mark.slow
@pytest.mark.parametrize("room", ["empty", "square"])
def test_the_lap_begins_on_a_step_measured_square_on_to_the_first_wall(room: str) -> None:
    gauged = step_scale_as_the_lap_begins(room, gauge_mm=800)
    assert any(label.startswith("gauge back 800, gauge ahead 800") for label in gauged["labels"])
    assert gauged["used"] >= 1  # the front sonar's ranges of the two moves made a fit
    assert gauged["sigma"] < 0.7 * 0.01  # exploration's prior on the step: 1 %
    assert abs(gauged["scale"] - gauged["floor"]) < 2.0 * gauged["sigma"]
    assert gauged["scale"] != 1.0

    unmeasured = step_scale_as_the_lap_begins(room, gauge_mm=0)
    assert unmeasured["used"] == 0 and unmeasured["scale"] == 1.0  # the prior, 1 % off this floor
    assert unmeasured["sigma"] > 0.01
