"""Issue 21: a side wall's fit is not associated with a known wall the sonars are already past.

With the tangent range model a range is to the wall's nearest point in the beam: the foot of the
sensor's perpendicular when that lies on the wall, else the wall's end. Past a short wall's end
the sonars range on the end itself; such a series fits a line tilted some 14° off the wall and
up to 50 mm long, whose own points still lie on the wall (they are the end), so checking them
against the wall's extent does not catch it. Checked here: the sensors' own positions."""

from __future__ import annotations

import math
from typing import Any

import yaml

from modules.localization.config import default_config_path, load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.walls import KnownWall

LEFT_PAIR = [7, 6]  # left-front, left-rear (robot.py indices)
SHORT_WALL = KnownWall.segment(1000.0, 1400.0, 1600.0, 1400.0)  # 600 mm long, on the robot's left


def core_at(x: float) -> LocalizationCore:
    data = yaml.safe_load(default_config_path().read_text())
    data["logs"] = {"enabled": False}
    return LocalizationCore(load_config(data), known_walls=[SHORT_WALL], start_pose=(x, 0.0, 0.0))


def left_fit(robot_x: float, d_mm: float, along: tuple[float, float]) -> dict[str, Any]:
    """A pair's fitted line at the robot's left (robot frame), its points at world x ``along``."""
    sigma_a, sigma_d = math.radians(1.0), 8.0
    return {
        "kind": "pair",
        "alpha": math.pi / 2,
        "d": d_mm,
        "cov": [sigma_a**2, 0.0, sigma_d**2],
        "n": 12,
        "p1": (along[0] - robot_x, d_mm),
        "p2": (along[1] - robot_x, d_mm),
        "sensors": LEFT_PAIR,
    }


def sonar(fit: dict[str, Any]) -> dict[str, Any]:
    return {"walls": [fit], "distances_mm": [None] * 8, "at": [0.0, 0.0, 0.0]}


def test_a_fit_on_a_short_walls_end_from_past_it_is_left_out() -> None:
    # the robot 400 mm past the wall's end; what it fitted is 40 mm long, its points on the end
    core = core_at(2000.0)
    core.process_synchronised(1, 100, {"sonar": sonar(left_fit(2000.0, 1440.0, (1550.0, 1600.0)))})
    assert core.walls_associated == 0
    assert core.ekf is not None and core.ekf.pose[1] == 0.0  # not pulled towards -y
    assert core.walls_past_end == 1


def test_a_fit_from_just_past_the_end_is_left_out_too() -> None:
    # 100 mm past the end (the rear sonar 20 mm): the series' later ranges are to the end already
    core = core_at(1700.0)
    core.process_synchronised(1, 100, {"sonar": sonar(left_fit(1700.0, 1420.0, (1450.0, 1600.0)))})
    assert core.walls_associated == 0 and core.walls_past_end == 1


def test_the_same_fit_alongside_the_wall_is_used() -> None:
    core = core_at(1300.0)
    core.process_synchronised(1, 100, {"sonar": sonar(left_fit(1300.0, 1420.0, (1200.0, 1400.0)))})
    assert core.walls_associated == 1
    assert core.ekf is not None and core.ekf.pose[1] < -5.0  # the 20 mm longer range moved the pose
    assert core.walls_past_end == 0
