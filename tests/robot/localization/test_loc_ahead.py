"""Issue 21: the front sonar's range to a known wall ahead as a position measurement
(``walls.ahead``).

On a long leg the side walls may be out of reach; only the step scale's uncertainty then bounds
the error along the drive. The front sonar meeting a known wall square on measures exactly that
coordinate. The geometry (which wall a cone meets first, and where) is checked against hand-worked
numbers; the filter against the test's own truth."""

from __future__ import annotations

import math
import random
from typing import Any

import pytest
import yaml

from modules.localization.config import default_config_path, load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.walls import KnownWall, beam_echoes

FRONT = 1
REAR = 5
FRONT_X_MM = 188.0  # the front sonar's face ahead of the reference point (robot.py)
HALF_CONE = math.radians(25.0)


def test_a_wall_square_ahead_echoes_from_the_foot_of_the_perpendicular() -> None:
    wall = KnownWall.segment(1000.0, -500.0, 1000.0, 500.0)
    (echo,) = beam_echoes((0.0, 0.0), 0.0, HALF_CONE, [wall])
    assert echo.range_mm == pytest.approx(1000.0)
    assert echo.foot_off == pytest.approx(0.0)


def test_a_wall_ten_degrees_off_the_axis_is_met_at_its_nearest_point() -> None:
    # the wall's normal 10° off the beam: the foot of the perpendicular from the sensor
    tilt = math.radians(10.0)
    foot = (1000.0 * math.cos(tilt), 1000.0 * math.sin(tilt))
    along = (-math.sin(tilt), math.cos(tilt))
    wall = KnownWall.segment(
        foot[0] - 800 * along[0], foot[1] - 800 * along[1], foot[0] + 800 * along[0], foot[1] + 800 * along[1]
    )
    (echo,) = beam_echoes((0.0, 0.0), 0.0, HALF_CONE, [wall])
    assert echo.range_mm == pytest.approx(1000.0)
    assert echo.foot_off is not None and math.degrees(echo.foot_off) == pytest.approx(10.0)


def test_a_wall_whose_perpendicular_is_outside_the_cone_echoes_from_the_cone_edge() -> None:
    # a wall along the beam's left edge region: y = 300 from x = 0 to 2000; its perpendicular
    # points 90° off the axis, so the nearest point in the cone is where the 25° edge crosses it
    wall = KnownWall.segment(0.0, 300.0, 2000.0, 300.0)
    (echo,) = beam_echoes((0.0, 0.0), 0.0, HALF_CONE, [wall])
    assert echo.foot_off is None
    assert echo.range_mm == pytest.approx(300.0 / math.sin(HALF_CONE))


def test_walls_are_listed_nearest_first_and_one_outside_the_cone_not_at_all() -> None:
    far = KnownWall.segment(1500.0, -500.0, 1500.0, 500.0, 0)
    near = KnownWall.segment(800.0, -100.0, 800.0, 100.0, 1)
    behind = KnownWall.segment(-700.0, -500.0, -700.0, 500.0, 2)
    echoes = beam_echoes((0.0, 0.0), 0.0, HALF_CONE, [far, near, behind])
    assert [e.wall.index for e in echoes] == [1, 0]
    assert [round(e.range_mm) for e in echoes] == [800, 1500]


# ---------------------------------------------------------------------------------------------
# the correction


def config(**ahead: Any) -> dict[str, Any]:
    data = yaml.safe_load(default_config_path().read_text())
    data["walls"]["ahead"] = {"enabled": True, **ahead}
    data["walls"]["bias_floor_mm"] = 0.0
    data["logs"] = {"enabled": False}
    # the floor at its nominal 1.0 ± 0.02, not the file's calibration: these drives draw their own
    data["filter"]["initial"].update(step_scale=1.0, step_scale_mean_sigma=0.02)
    return load_config(data)


def front_record(range_mm: float | None) -> dict[str, Any]:
    distances: list[int | None] = [None] * 8
    distances[FRONT] = None if range_mm is None else round(range_mm / 10) * 10
    return {"walls": [], "distances_mm": distances, "at": [0.0, 0.0, 0.0]}


def core_facing(walls: list[KnownWall], start: tuple[float, float, float], **ahead: Any) -> LocalizationCore:
    return LocalizationCore(config(**ahead), known_walls=walls, start_pose=start)


def test_a_range_to_the_wall_ahead_moves_the_pose_along_the_beam_only() -> None:
    wall = KnownWall.segment(1500.0, -1000.0, 1500.0, 1000.0)
    core = core_facing([wall], (0.0, 0.0, 0.0))
    # the filter puts the sonar 1312 mm from the wall; it reads 1270 (late echo 14 mm: 56 mm less),
    # twice: the first range waits for the second to bear it out
    core.process_synchronised(1, 100, {"sonar": front_record(1270.0)})
    assert core.ahead["used"] == 0 and core.ahead["unconfirmed"] == 1, core.ahead
    core.process_synchronised(2, 200, {"sonar": front_record(1270.0)})
    assert core.ahead["used"] == 1, core.ahead
    x, y, _ = core.ekf.pose  # type: ignore[union-attr]
    assert 20.0 < x <= 60.0  # towards the wall, by most of it (σ 20 mm before, 15 mm the range)
    assert abs(y) < 1.0


def test_nothing_is_used_at_a_corner_past_something_unknown_or_twice_in_one_place() -> None:
    wall = KnownWall.segment(2000.0, -1000.0, 2000.0, 1000.0, 0)
    side = KnownWall.segment(0.0, 350.0, 3000.0, 350.0, 1)  # the cone's edge meets it at ~750 mm
    corner = core_facing([wall, side], (1000.0, 0.0, 0.0))
    corner.process_synchronised(1, 100, {"sonar": front_record(700.0)})
    # the wall ahead is first (812 mm) but the side wall crosses the cone's edge at 828 mm
    assert corner.ahead["ambiguous"] == 1 and corner.ahead["used"] == 0, corner.ahead

    core = core_facing([wall], (1000.0, 0.0, 0.0))
    core.process_synchronised(1, 100, {"sonar": front_record(400.0)})  # a box the map does not have
    assert core.ahead["unexpected"] == 1 and core.ahead["used"] == 0
    for k in (2, 3, 4):  # at rest: the third range would be the second's error again
        core.process_synchronised(k, 100 * k, {"sonar": front_record(812.0)})
    assert core.ahead["used"] == 1 and core.ahead["repeated"] == 1, core.ahead


def test_a_round_pillar_in_the_cone_before_the_wall_leaves_the_range_unused() -> None:
    wall = KnownWall.segment(1500.0, -1000.0, 1500.0, 1000.0)
    core = core_facing([wall], (300.0, 0.0, 0.0))
    core.known_circles = [(1100.0, 250.0, 150.0)]  # its near face 0.51 m off, 22° off the axis
    for k in (1, 2):
        core.process_synchronised(k, 100 * k, {"sonar": front_record(1020.0)})
    assert core.ahead["used"] == 0 and core.ahead["ambiguous"] == 2, core.ahead
    core.known_circles = [(1100.0, 700.0, 150.0)]  # 49° off: clear of the cone (25° + 9° for its radius)
    for k in (3, 4):
        core.process_synchronised(k, 100 * k, {"sonar": front_record(1020.0)})
    assert core.ahead["used"] == 1, core.ahead


def test_a_lone_range_far_off_is_not_used() -> None:
    wall = KnownWall.segment(1500.0, -1000.0, 1500.0, 1000.0)
    core = core_facing([wall], (300.0, 0.0, 0.0))  # the sonar 1012 mm from the wall (late: 7.8 mm)
    core.process_synchronised(1, 100, {"sonar": front_record(1020.0)})
    core.process_synchronised(2, 200, {"sonar": front_record(1060.0)})  # 40 mm long, alone
    core.process_synchronised(3, 300, {"sonar": front_record(1020.0)})
    assert core.ahead["used"] == 0 and core.ahead["unconfirmed"] == 3, core.ahead
    x, _, _ = core.ekf.pose  # type: ignore[union-attr]
    assert x == 300.0


def test_nothing_is_used_while_turning() -> None:
    # turning, the beam sweeps across the wall and an echo 19° off its normal read 67 mm long
    wall = KnownWall.segment(1500.0, -1000.0, 1500.0, 1000.0)
    core = core_facing([wall], (0.0, 0.0, 0.0))
    turn = {"dl": -20, "dr": 20}  # 20 half-steps each way in 100 ms: about 30°/s
    core.process_synchronised(1, 100, {"odometry": {"dl": 0, "dr": 0}})
    core.process_synchronised(2, 200, {"odometry": turn, "sonar": front_record(1320.0)})
    assert core.ahead["used"] == 0
    for k in (3, 4):
        core.process_synchronised(k, 100 * k, {"odometry": {"dl": 0, "dr": 0}, "sonar": front_record(1320.0)})
    assert core.ahead["used"] == 1


WALL_X = 5000.0
STEPS_PER_SYNC = 80
TRIALS = 100


def drive_towards_the_wall(enabled: bool, rng: random.Random) -> tuple[float, float, float, float]:
    """One 3.8 m move towards a wall, the floor's step 1 % long plus its per-move draw; the
    front sonar reads the wall (late by 25 mm/m beyond 0.7 m, 12 mm noise, whole cm) from 1.4 m
    on. Returns the filter's x error and σx at the end, and its step scale and the true one."""
    core = core_facing([KnownWall.segment(WALL_X, -1000.0, WALL_X, 3000.0)], (0.0, 1000.0, 0.0))
    core.config["walls"]["ahead"]["enabled"] = enabled
    mm_per_step = core.config["robot"]["mm_per_step"]
    scale = 1.01 * (1.0 + rng.gauss(0.0, 0.005))
    x_true = 0.0
    for k in range(1, 7000 // STEPS_PER_SYNC):
        x_true += STEPS_PER_SYNC * mm_per_step * scale
        true_range = WALL_X - x_true - FRONT_X_MM
        reading = None
        if true_range <= 1400.0:
            reading = true_range + max(0.0, true_range - 700.0) * 0.025 + rng.gauss(0.0, 12.0)
        data = {
            "odometry": {"dl": STEPS_PER_SYNC, "dr": STEPS_PER_SYNC},
            "compass": {"heading": 0.0},
            "sonar": front_record(reading),
        }
        core.process_synchronised(k, 100 * k, data)
    ekf = core.ekf
    assert ekf is not None
    return ekf.pose[0] - x_true, math.sqrt(ekf.P[0, 0]), ekf.step_scale, scale


@pytest.mark.slow
def test_the_wall_ahead_bounds_the_error_along_a_long_move_honestly() -> None:
    rng = random.Random(21)
    with_ahead = [drive_towards_the_wall(True, rng) for _ in range(TRIALS)]
    rng = random.Random(21)
    without = [drive_towards_the_wall(False, rng) for _ in range(TRIALS)]
    rms_with = math.sqrt(sum(e * e for e, *_ in with_ahead) / TRIALS)
    rms_without = math.sqrt(sum(e * e for e, *_ in without) / TRIALS)
    assert rms_with < rms_without / 4, (rms_with, rms_without)  # 6.9 against 41 mm here
    inside = sum(abs(e) <= 3 * s for e, s, *_ in with_ahead) / TRIALS
    assert inside >= 0.95, inside
    # the move's step scale is learnt from the ranges: nearer the truth than the prior (1.0)
    scale_error = sum(abs(est - true) for *_, est, true in with_ahead) / TRIALS
    assert scale_error < sum(abs(1.0 - true) for *_, true in with_ahead) / TRIALS / 2


def test_the_rear_sonar_ranges_a_wall_behind_as_the_front_one_does_ahead() -> None:
    # facing away from the wall: the rear sonar (188 mm behind the reference point) reads it
    wall = KnownWall.segment(-1500.0, -1000.0, -1500.0, 1000.0)
    core = core_facing([wall], (0.0, 0.0, 0.0), sensors=[REAR])
    # predicted 1312 mm; it reads 1270 (late echo 14 mm: 56 mm less), twice
    for k in (1, 2):
        core.process_synchronised(k, 100 * k, {"sonar": rear_record(1270.0)})
    assert core.ahead["used"] == 1, core.ahead
    x, y, _ = core.ekf.pose  # type: ignore[union-attr]
    assert -60.0 <= x < -20.0  # towards the wall behind, by most of it
    assert abs(y) < 1.0
    front_only = core_facing([wall], (0.0, 0.0, 0.0), sensors=[FRONT])
    for k in (1, 2):
        front_only.process_synchronised(k, 100 * k, {"sonar": rear_record(1270.0)})
    assert front_only.ahead["used"] == 0 and front_only.ekf.pose[0] == 0.0  # type: ignore[union-attr]


def rear_record(range_mm: float) -> dict[str, Any]:
    distances: list[int | None] = [None] * 8
    distances[REAR] = round(range_mm / 10) * 10
    return {"walls": [], "distances_mm": distances, "at": [0.0, 0.0, 0.0]}


def oblique_shift(**ahead: Any) -> tuple[float, dict[str, int]]:
    """How far two equal ranges to a wall whose normal lies 22° off the front beam move the
    pose along that normal (the wall's foot 1000 mm from the sonar, the reading 40 mm short of
    what the filter expects after the late echo's share: 25 mm/m past 0.7 m, 0.055 mm/deg²)."""
    tilt = math.radians(22.0)
    sonar = (FRONT_X_MM, 0.0)
    foot = (sonar[0] + 1000.0 * math.cos(tilt), sonar[1] + 1000.0 * math.sin(tilt))
    along = (-math.sin(tilt), math.cos(tilt))
    wall = KnownWall.segment(
        foot[0] - 1500 * along[0],
        foot[1] - 1500 * along[1],
        foot[0] + 1500 * along[0],
        foot[1] + 1500 * along[1],
    )
    core = core_facing([wall], (0.0, 0.0, 0.0), **ahead)
    late = (1000.0 - 700.0) * 0.025 + 0.055 * 22.0**2  # 7.5 + 26.6 mm
    for k in (1, 2):
        core.process_synchronised(k, 100 * k, {"sonar": front_record(1000.0 + late - 40.0)})
    x, y, _ = core.ekf.pose  # type: ignore[union-attr]
    return x * math.cos(tilt) + y * math.sin(tilt), dict(core.ahead)


def test_a_wall_met_obliquely_is_used_only_when_allowed_and_then_weighs_less() -> None:
    shift, counts = oblique_shift(max_off_deg=20.0)  # the built-in 20°: not square enough
    assert shift == 0.0 and counts["used"] == 0 and counts["not_square"] == 2, counts
    square_weight, counts = oblique_shift(max_off_deg=25.0, oblique_from_deg=25.0)
    assert counts["used"] == 1, counts
    oblique_weight, counts = oblique_shift(max_off_deg=25.0, oblique_from_deg=20.0, oblique_sigma_mm=25.0)
    assert counts["used"] == 1, counts
    # towards the wall by the Kalman gain's share of 40 mm: prior σ 20 mm in x and y, the range's
    # σ 15 mm -> 0.64 (the heading's lever adds a little to the prior); σ 25 mm weighs
    # (p + 15²) / (p + 25²) of that: 0.61 at p = 20², 0.65 at 23²
    assert 40.0 * 0.55 < square_weight < 40.0 * 0.75, square_weight
    assert 0.55 < oblique_weight / square_weight < 0.70, (oblique_weight, square_weight)


def test_a_diagonal_sonar_ranges_the_wall_it_meets_square_on_along_its_beam() -> None:
    # the front-right pair sits 133 mm ahead and 133 mm right of the reference point and looks
    # 45° right: a wall whose normal is that beam, its foot 1200 mm out, is met square on
    front_right, diagonal_mm = 2, 133.0
    beam = (math.cos(-math.pi / 4), math.sin(-math.pi / 4))
    foot = (diagonal_mm + 1200.0 * beam[0], -diagonal_mm + 1200.0 * beam[1])
    along = (-beam[1], beam[0])
    wall = KnownWall.segment(
        foot[0] - 1500 * along[0],
        foot[1] - 1500 * along[1],
        foot[0] + 1500 * along[0],
        foot[1] + 1500 * along[1],
    )
    late = (1200.0 - 700.0) * 0.025  # 12.5 mm: square on, no off-axis share
    distances: list[int | None] = [None] * 8
    distances[front_right] = round(1200.0 + late - 40.0)  # 40 mm nearer than the filter expects
    record = {"walls": [], "distances_mm": distances, "at": [0.0, 0.0, 0.0]}
    core = core_facing([wall], (0.0, 0.0, 0.0), sensors=[front_right])
    for k in (1, 2):
        core.process_synchronised(k, 100 * k, {"sonar": record})
    assert core.ahead["used"] == 1, core.ahead
    x, y, _ = core.ekf.pose  # type: ignore[union-attr]
    toward = x * beam[0] + y * beam[1]
    across = x * along[0] + y * along[1]
    assert 15.0 < toward <= 40.0  # towards the wall by most of the 40 mm (σ 20 mm before, 15 the range)
    assert abs(across) < 1.0  # nothing along the wall
    front_only = core_facing([wall], (0.0, 0.0, 0.0), sensors=[FRONT])
    for k in (1, 2):
        front_only.process_synchronised(k, 100 * k, {"sonar": record})
    assert front_only.ahead["used"] == 0
