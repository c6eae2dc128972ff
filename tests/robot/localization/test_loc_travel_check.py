"""The travel gauge's wall is looked up where its ranges were read (``filter.travel.check_at``).

A rear sonar's range series ends long before its run does; extrapolated to the run's end its
range can reach a wall far beyond the one it saw. Here the rear beam saw a wall 20° off square
(its scale is then not the step scale), and from the run's end the extrapolated range meets a
short wall square on: ``end`` takes the fit, ``points`` leaves it as oblique."""

from __future__ import annotations

import copy
import math

from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.walls import KnownWall

REAR = 5
TILT = math.radians(20)


def walls() -> list[KnownWall]:
    """Wall 0 through (-88, 1000), 20° off the y axis (the rear beam from x = 912 meets it at
    1000 mm); wall 1 a short square one at x = 500, 2312 mm from the rear sonar at the run's end."""
    h = 500.0
    tilted = KnownWall.segment(
        -88 - h * math.sin(TILT),
        1000 - h * math.cos(TILT),
        -88 + h * math.sin(TILT),
        1000 + h * math.cos(TILT),
        0,
    )
    square = KnownWall.segment(500.0, 900.0, 500.0, 1100.0, 1)
    return [tilted, square]


def core_after_fit(check_at: str) -> LocalizationCore:
    config = copy.deepcopy(load_config("config/localization.yaml"))
    config["filter"]["travel"].update(enabled=True, check_at=check_at)
    config["logs"]["enabled"] = False
    config["filter"]["initial"].update(step_scale=1.0, step_scale_mean_sigma=0.02)  # not calibrated
    core = LocalizationCore(config, known_walls=walls(), start_pose=(3000.0, 1000.0, 0.0))
    fit = {
        "sensor": REAR,
        "scale": 0.97,
        "sigma": 0.004,
        "n": 60,
        "span_mm": 480.0,
        "range_mm": 1000.0,  # the points' mean range, read 1900 mm (nominal) before the run ended
        "range_end_mm": 2900.0,
        "back_mm": 1900.0,
        "residual_mm": 8.0,
        "end": [0.0, 0.0, 0.0],  # the run ended where the filter's pose is
    }
    core.process_synchronised(1, 100, {"sonar": {"walls": [], "travel": [fit]}})
    return core


def test_the_wall_seen_from_the_points_is_the_one_judged() -> None:
    at_points = core_after_fit("points")
    assert at_points.travel["oblique"] == 1 and at_points.travel["used"] == 0, at_points.travel
    assert at_points.ekf is not None and at_points.ekf.step_scale == 1.0


def test_from_the_runs_end_another_wall_is_met() -> None:
    at_end = core_after_fit("end")
    assert at_end.travel["used"] == 1, at_end.travel
    assert at_end.ekf is not None and at_end.ekf.step_scale < 0.99
