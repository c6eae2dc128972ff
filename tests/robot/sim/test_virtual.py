"""The robot in virtual time (``tokenring sim --world``): the programs ``up`` downloads, on the
simulated nodes, with the world in the same process on the same clock (modules/virtual.py).

Each run is a ``tokenring sim`` command as a user types it, in a process of its own: the same
command and seed give the same frames and the same map; a seed of its own gives other frames;
an action file ends where the world's ground truth puts the robot.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

import pytest

from tests.support.processes import REPO, run_tokenring

EXPLORE = ("--world", "empty", "--explore", "2", "--duration", "120")


def simulate(tmp_path: Path, name: str, *options: str) -> dict[str, Any]:
    """Run ``tokenring sim OPTIONS --json`` and return its summary."""
    summary = tmp_path / f"{name}.json"
    result = run_tokenring("sim", *options, "--json", str(summary), timeout=600)
    assert result.returncode == 0, (result.stdout[-3000:], result.stderr[-3000:])
    assert "Traceback" not in result.stdout + result.stderr, result.stderr[-3000:]
    return json.loads(summary.read_text())


@pytest.mark.slow
@pytest.mark.timeout(900)  # three runs of 120 virtual s, each up to 600 s on a loaded machine
def test_the_same_exploration_gives_the_same_frames_and_map(tmp_path: Path) -> None:
    mapped = tmp_path / "empty.json"
    first = simulate(tmp_path, "first", *EXPLORE, "--map-out", str(mapped))
    second = simulate(tmp_path, "second", *EXPLORE)
    assert first["frames_sha256"] == second["frames_sha256"]
    assert first["map_sha256"] == second["map_sha256"]
    # the hash is the map file's own, byte for byte
    assert hashlib.sha256(mapped.read_bytes()).hexdigest() == first["map_sha256"]
    robot = first["extra"]["robot"]
    assert robot["programs"] == ["main", "motor", "sonar", "compass", "copro", "map", "lcd", "charger"]
    assert not robot["program_errors"] and robot["failure"] is None
    (x0, y0, _), (x1, y1, _) = robot["start"], robot["truth"]
    assert math.hypot(x1 - x0, y1 - y0) > 300, robot  # the world's truth: the robot drove
    walls = json.loads(mapped.read_text())["vectors"]
    assert len(walls) > 0 and robot["map_vectors"] == len(walls)
    other = simulate(tmp_path, "other", *EXPLORE, "--seed", "2")
    assert other["frames_sha256"] != first["frames_sha256"]


@pytest.mark.slow
@pytest.mark.timeout(600)  # 120 virtual s, 30 s on an idle core
def test_an_action_file_ends_where_the_world_puts_the_robot(tmp_path: Path) -> None:
    """800 mm east, a quarter turn left, 500 mm north: from the empty room's start (1000, 1500)
    the world's truth has the robot at (1800, 2000) facing north."""
    actions = tmp_path / "ell.act"
    actions.write_text("e\ns 800\nr 90\ns 500\n")
    summary = simulate(tmp_path, "ell", "--world", "empty", "--actions", str(actions), "--duration", "120")
    robot = summary["extra"]["robot"]
    assert robot["failure"] is None, robot
    assert robot["start"] == [1000.0, 1500.0, 0.0]
    x, y, theta = robot["truth"]
    assert math.hypot(x - 1800.0, y - 2000.0) < 60.0, robot["truth"]
    assert abs(math.degrees(math.remainder(theta - math.pi / 2, math.tau))) < 5.0, robot["truth"]
    assert "action file done" in "\n".join(robot["lines"])


@pytest.mark.parametrize(
    ("options", "said"),
    [
        (("--explore", "2", "--actions", str(REPO / "actions" / "square-3-laps.act")), "give one of them"),
        (("--world", "office", "--no-world"), "--no-world runs the ring alone"),
        (("--world", "no-such-room"), "no-such-room"),
        (("--explore", "2", "--speed", "0"), "--speed 0"),
    ],
)
def test_refused_before_anything_runs(options: tuple[str, ...], said: str) -> None:
    result = run_tokenring("sim", *options)
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert said in result.stderr and "Traceback" not in result.stderr, result.stderr


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_faults_run_beside_the_robot_to_the_end_of_the_run(tmp_path: Path) -> None:
    """``--fault`` beside a mission that ends early: the schedule still runs its --duration out
    and its faults and the injectors' counts are in the summary."""
    options = ("--world", "empty", "--explore", "2", "--duration", "20", "--fault", "drop:motor:0.1@5")
    summary = simulate(tmp_path, "faults", *options)
    assert summary["simulated_s"] == 20.0
    [fault] = summary["faults"]
    assert fault["fault"] == "drop:motor:0.1@5" and fault["recovered_s"] is not None
    assert summary["fault_counts"]["20"]["dropped"] > 0
    assert summary["extra"]["robot"]["failure"] is None
