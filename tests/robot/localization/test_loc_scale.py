"""Issue 21: the step scale's uncertainty on a long leg out of the walls' reach.

The floor draws each straight move's step length around its mean (SPEC §5: +1 % systematic,
0.5 % per move). The repository's filter keeps that mean as a state and starts each move there,
one draw away. Without it a move starts from the last move's scale, whose own draw is in it: the
new move's scale differs from it by √2 × 0.5 %, and a variance of one draw alone made the filter
too sure on the next leg (the Darmstadt square on the ring, seed 3: a 2.5 m leg with the scale
1.6 % off, 92 % of the synchronisations within 3σ). Here, over many trials, one move
towards a known wall ahead reads it at every synchronisation, then a leg reads no wall; the
scales are drawn as the floor draws them and the truth is the test's own sum of step lengths.
"""

from __future__ import annotations

import math
import random
from typing import Any

import pytest
import yaml

from modules.localization.config import default_config_path, load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.walls import KnownWall

WALL_X = 5000.0  # the known wall ahead, square across the drive along +x
START = (0.0, 1000.0, 0.0)
SEEN_STEPS, LEG_STEPS = 3200, 4000  # half-steps: about 1.7 m seeing the wall, then 2.2 m without
STEPS_PER_SYNC = 80
FLOOR_MEAN, FLOOR_PER_MOVE = 1.01, 0.005  # SPEC §5
TRIALS = 400


def config_with(per_move: float | None, mean_state: bool = True) -> dict:
    data = yaml.safe_load(default_config_path().read_text())
    if per_move is not None:
        data["filter"]["noise"]["step_scale_per_move"] = per_move
    if not mean_state:
        data["filter"]["estimate"] = [s for s in data["filter"]["estimate"] if s != "step_scale_mean"]
    data["walls"]["bias_floor_mm"] = 0.0  # fits without a shared error: the move's scale is learnt
    data["walls"]["repeat_after_mm"] = 0.0
    data["logs"] = {"enabled": False}
    return load_config(data)


def leg_end(config: dict, rng: random.Random) -> tuple[float, float]:
    """The filter's x error and σx at the end of the leg without walls."""
    core = LocalizationCore(
        config, known_walls=[KnownWall.segment(WALL_X, 0.0, WALL_X, 3000.0)], start_pose=START
    )
    mm_per_step = config["robot"]["mm_per_step"]
    x_true, k = START[0], 0

    def sync(steps: int, walls: list[dict[str, Any]]) -> None:
        nonlocal k
        k += 1
        data: dict[str, dict[str, Any]] = {
            "odometry": {"dl": steps, "dr": steps},
            "compass": {"heading": 0.0},
            "sonar": {"walls": walls},
        }
        core.process_synchronised(k, 100 * k, data)

    for steps, seen in ((SEEN_STEPS, True), (LEG_STEPS, False)):
        scale = FLOOR_MEAN * (1.0 + rng.gauss(0.0, FLOOR_PER_MOVE))  # this move's true step
        for _ in range(steps // STEPS_PER_SYNC):
            x_true += STEPS_PER_SYNC * mm_per_step * scale
            walls = []
            if seen:
                distance = WALL_X - x_true + rng.gauss(0.0, 1.0)
                walls.append(
                    {
                        "kind": "pair",
                        "sensors": [0, 1],
                        "alpha": 0.0,  # the wall's normal straight ahead
                        "d": distance,
                        "cov": [math.radians(0.5) ** 2, 0.0, 1.0**2],
                        "n": 10,
                        "p1": [distance, -200.0],
                        "p2": [distance, 200.0],
                    }
                )
            sync(STEPS_PER_SYNC, walls)
        for _ in range(3):
            sync(0, [])  # at rest between the moves
    position = core.positions["K"]
    return position["x"] - x_true, position["sigma"][0]


def share_within_3_sigma(config: dict) -> float:
    rng = random.Random(2126)
    ends = [leg_end(config, rng) for _ in range(TRIALS)]
    return sum(abs(error) <= 3 * sigma for error, sigma in ends) / len(ends)


@pytest.mark.slow
def test_a_leg_without_walls_after_a_learnt_move_keeps_the_truth_within_3_sigma() -> None:
    assert share_within_3_sigma(config_with(None)) >= 0.99  # the repository's: one draw from the mean


@pytest.mark.slow
def test_from_the_last_move_one_draw_alone_is_too_sure_of_the_next_leg() -> None:
    assert share_within_3_sigma(config_with(FLOOR_PER_MOVE, mean_state=False)) < 0.99  # short of the aim
    assert share_within_3_sigma(config_with(0.007, mean_state=False)) >= 0.99  # √2 draws: honest
