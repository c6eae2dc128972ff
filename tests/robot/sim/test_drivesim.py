"""bench.drivesim: an action-file drive in one process, judged against the simulator's truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.drivesim import chance_beyond, summarise
from bench.rooms import generated_room
from modules.description import load_world
from modules.description.drives import drive_text, generate_drive
from modules.sim.drivesim import DriveSim, judge, repository_config


@pytest.mark.slow
def test_short_drive_is_judged_against_the_simulators_truth(tmp_path):
    path = generated_room(101, tmp_path)
    world = load_world(str(path))
    moves = generate_drive(world, 101)[:3]  # a turn, a leg, a turn
    moves.append(("s", 700))
    sim = DriveSim(str(path), 1, drive_text(moves, "short"), repository_config(str(path)))
    result = sim.drive(max_minutes=10)
    assert result["finished"] == "action file done"

    # the robot drove the file: the legs' length, as the robot's own truth says (the floor's
    # step is 1 % long, each move ±0.5 %; turns in place add little)
    start, end = world.start, sim.robot.pose
    straight = sum(amount for kind, amount in moves if kind == "s")
    path = np.diff(result["truth"][:, 1:3], axis=0)
    assert 0.95 * straight < float(np.hypot(path[:, 0], path[:, 1]).sum()) < 1.1 * straight
    # the file's turns add up to the truth's heading change, within the closed loop's tolerance
    meant = math.radians(sum(amount for kind, amount in moves if kind == "r"))
    assert abs(math.remainder(end.theta - start.theta - meant, 2 * math.pi)) < math.radians(3)

    # the judge's end error is the distance between the filter's last pose and the robot itself
    pose = sim.core.pose()
    own = math.hypot(pose.x_mm - end.x, pose.y_mm - end.y)
    figures = judge(result["positions"], result["truth"])
    assert abs(figures["K"]["end_error_mm"] - own) < 2.0
    assert figures["K"]["max_error_mm"] >= figures["K"]["end_error_mm"]
    assert 0.0 <= figures["K"]["within_3sigma"] <= 1.0
    assert figures["K"]["samples_3sigma"] == len(result["positions"]["K"])
    assert own < 60.0  # the walls are known: the filter holds the pose


def test_judge_on_hand_made_records():
    truth = np.array([[0.0, 0.0, 0.0, 0.0], [1000.0, 100.0, 0.0, 0.0]])
    k = [
        (0, {"x": 3.0, "y": 4.0, "psi": 0.0, "sigma": [2.0, 2.0, 0.01]}),  # 5 mm off, inside 3σ
        (500, {"x": 50.0, "y": 10.0, "psi": 0.0, "sigma": [1.0, 1.0, 0.01]}),  # truth (50, 0): outside
    ]
    o = [(0, {"x": 0.0, "y": 0.0, "psi": 0.0}), (1000, {"x": 130.0, "y": 40.0, "psi": 0.0})]
    figures = judge({"K": k, "O": o}, truth)
    assert figures["K"]["end_error_mm"] == 10.0
    assert figures["K"]["max_error_mm"] == 10.0
    assert abs(figures["K"]["rmse_mm"] - math.sqrt((25 + 100) / 2)) < 1e-9
    assert figures["K"]["within_3sigma"] == 0.5
    assert figures["O"]["end_error_mm"] == 50.0
    s = summarise(
        [
            {
                "room": 1,
                "seed": 1,
                "filter_mm": 10.0,
                "filter_rmse_mm": 8.0,
                "filter_max_mm": 12.0,
                "within_3sigma": 0.5,
                "samples_3sigma": 2,
                "dead_reckoning_mm": 50.0,
                "finished": "action file done",
            },
            {
                "room": 2,
                "seed": 1,
                "filter_mm": 30.0,
                "filter_rmse_mm": 9.0,
                "filter_max_mm": 40.0,
                "within_3sigma": 1.0,
                "samples_3sigma": 6,
                "dead_reckoning_mm": 70.0,
                "finished": "time is up",
            },
        ]
    )
    assert s["end_median_mm"] == 20.0 and s["end_worst_mm"] == 30.0
    assert s["within_3sigma"] == 0.875 and s["synchronisations"] == 8
    assert s["not_done"] == ["2/1"]


@pytest.mark.slow
def test_a_bundled_world_is_driven_by_an_action_file(tmp_path, capsys):
    from bench.drivesim import main

    actions = tmp_path / "short.act"
    actions.write_text("s 600\nr 90\ns 400\n")
    out = tmp_path / "square.json"
    assert main(["--world", "square", "--actions", str(actions), "--seeds", "2", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "room square seed 2: filter" in printed and "action file done" in printed
    import json

    (run,) = json.loads(out.read_text())["runs"]
    assert run["room"] == "square" and run["finished"] == "action file done"
    assert run["moves"]  # the file's moves were driven


def test_the_chance_beyond_the_aim_is_the_gaussians_mass_outside_the_disc():
    # a round Gaussian: Rayleigh's tail exp(-R²/2σ²), in closed form
    assert math.isclose(chance_beyond(50.0, 20.0, 20.0), math.exp(-(50.0**2) / (2 * 20.0**2)), rel_tol=1e-6)
    # an elongated one, against draws (1e6 draws: the share's sd is under 0.0005)
    rng = np.random.default_rng(7)
    x, y = rng.normal(0.0, 37.0, 1_000_000), rng.normal(0.0, 26.0, 1_000_000)
    assert abs(chance_beyond(50.0, 37.0, 26.0) - float(np.mean(np.hypot(x, y) > 50.0))) < 0.002
