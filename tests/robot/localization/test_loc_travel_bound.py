"""A travel fit on a wall the map does not have yet bounds the step scale from below
(``filter.travel.unknown_wall_bound``).

A sonar's range to a wall met φ off square changes by cos φ of the distance driven, so such a
fit reads the scale low and never high. Taken as square on, a rear series on a wall 18° off once
read 0.977 where the floor's scale was 1.010 and threw the pose 60 mm off (generated room 139,
world seed 1). As a bound, a fit more than ``unknown_wall_bound_sigma`` of its σ below the
filter's scale is no news and is left; one within that or above is used. A scattered series (σ
above ``unknown_wall_max_sigma``) is left whatever it reads: short series read low on average."""

from __future__ import annotations

import copy

from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore

FRONT = 1


def core_after_fit(scale: float, bound: bool, sigma: float = 0.004) -> LocalizationCore:
    """A filter at step scale 1.000 with no known wall, after one front-sonar fit of ``scale``."""
    config = copy.deepcopy(load_config("config/localization.yaml"))
    config["filter"]["travel"].update(
        enabled=True,
        unknown_wall=True,
        unknown_wall_bound=bound,
        unknown_wall_bound_sigma=2.0,
        unknown_wall_max_sigma=0.006,
    )
    config["logs"]["enabled"] = False
    config["filter"]["initial"].update(step_scale=1.0, step_scale_mean_sigma=0.02)  # not calibrated
    core = LocalizationCore(config, known_walls=[], start_pose=(1000.0, 1000.0, 0.0))
    fit = {
        "sensor": FRONT,
        "scale": scale,
        "sigma": sigma,
        "n": 60,
        "span_mm": 600.0,
        "range_mm": 600.0,
        "range_end_mm": 300.0,
        "back_mm": 300.0,
        "residual_mm": 5.0,
        "end": [0.0, 0.0, 0.0],
    }
    core.process_synchronised(1, 100, {"sonar": {"walls": [], "travel": [fit]}})
    return core


def test_a_fit_far_below_the_filters_scale_on_an_unknown_wall_is_left() -> None:
    core = core_after_fit(0.977, bound=True)  # 3.6 of its σ below
    assert core.travel["below_bound"] == 1 and core.travel["used"] == 0, core.travel
    assert core.ekf is not None and core.ekf.step_scale == 1.0


def test_a_fit_a_little_below_the_filters_scale_on_an_unknown_wall_is_used() -> None:
    core = core_after_fit(0.992, bound=True)  # 1.2 of its σ (0.0064 with the model's) below
    assert core.travel["used"] == 1 and core.travel["below_bound"] == 0, core.travel
    assert core.ekf is not None and core.ekf.step_scale < 0.998


def test_a_fit_reading_the_scale_high_on_an_unknown_wall_is_used() -> None:
    core = core_after_fit(1.012, bound=True)
    assert core.travel["used"] == 1 and core.travel["assumed_square"] == 1, core.travel
    assert core.ekf is not None and core.ekf.step_scale > 1.003


def test_without_the_bound_a_low_fit_is_taken_as_square_on() -> None:
    core = core_after_fit(0.977, bound=False)
    assert core.travel["used"] == 1, core.travel
    assert core.ekf is not None and core.ekf.step_scale < 0.995


def test_a_scattered_fit_on_an_unknown_wall_is_left_whatever_it_reads() -> None:
    core = core_after_fit(1.012, bound=True, sigma=0.012)
    assert core.travel["unknown"] == 1 and core.travel["used"] == 0, core.travel
    assert core.ekf is not None and core.ekf.step_scale == 1.0
