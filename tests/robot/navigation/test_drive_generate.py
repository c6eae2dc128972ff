"""``tokenring world drive``: random action files that stay clear of every wall of their room."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from shapely.geometry import LineString, Point, Polygon

from modules.description.generate import generate_room, room_yaml
from modules.navigation.actions import parse_actions
from tests.support.processes import run_tokenring


def room_shapes(data: dict) -> tuple[Polygon, list]:
    """The room's outline and everything standing in it, from the generator's own data."""
    outline = Polygon(data["walls"][0]["polygon"])
    inside = [
        Polygon(w["polygon"]) if "polygon" in w else LineString([w["from"], w["to"]])
        for w in data["walls"][1:]
    ]
    inside += [Point(c["x"], c["y"]).buffer(c["r"]) for c in data.get("circles", [])]
    return outline, inside


def driven_path(data: dict, text: str) -> list[tuple[float, float]]:
    """The drive's corners, each action taken exactly from the start pose."""
    x, y = data["start"]["x"], data["start"]["y"]
    heading = math.radians(data["start"]["angle_deg"])
    points = [(x, y)]
    for action in parse_actions(text):
        if action.kind == "r":
            heading += math.radians(action.args[0])
        elif action.kind == "s":
            x, y = x + action.args[0] * math.cos(heading), y + action.args[0] * math.sin(heading)
            points.append((x, y))
    return points


@pytest.mark.slow
def test_drives_keep_clear_of_every_wall_and_are_the_same_per_seed(tmp_path: Path) -> None:
    for room_seed in (3, 11, 250):
        data = generate_room(room_seed)
        world = tmp_path / f"room{room_seed}.yaml"
        world.write_text(room_yaml(data))
        outline, inside = room_shapes(data)
        for drive_seed in (1, 2):
            done = run_tokenring("world", "drive", "--world", str(world), "--seed", str(drive_seed))
            assert done.returncode == 0, done.stderr
            path = driven_path(data, done.stdout)
            assert len(path) == 9  # the start and 8 legs
            line = LineString(path)
            assert outline.contains(line)
            assert outline.exterior.distance(line) >= 449, (room_seed, drive_seed)
            assert all(shape.distance(line) >= 449 for shape in inside), (room_seed, drive_seed)
            again = run_tokenring("world", "drive", "--world", str(world), "--seed", str(drive_seed))
            assert again.stdout == done.stdout
        other = run_tokenring("world", "drive", "--world", str(world), "--seed", "3")
        assert other.stdout != done.stdout


@pytest.mark.slow
def test_drive_out_and_bad_arguments(tmp_path: Path) -> None:
    out = tmp_path / "drive.txt"
    done = run_tokenring(
        "world", "drive", "--world", "office", "--seed", "1", "--legs", "3", "--out", str(out)
    )
    assert done.returncode == 0, done.stderr
    assert len(parse_actions(out.read_text())) >= 4  # e, then s and r
    before = out.read_text()
    refused = run_tokenring("world", "drive", "--world", "office", "--seed", "2", "--out", str(out))
    assert refused.returncode == 2 and out.read_text() == before
    assert "exists" in refused.stderr and "Traceback" not in refused.stderr
    for args, words in (
        (["--world", "nosuch"], "nosuch"),
        (["--world", "office", "--legs", "0"], "--legs"),
        (["--world", "office", "--seed", "-1"], "--seed"),
    ):
        argv = ["world", "drive", *args] + ([] if "--seed" in args else ["--seed", "1"])
        bad = run_tokenring(*argv)
        assert bad.returncode == 2, (args, bad.stderr)
        lines = bad.stderr.strip().splitlines()
        assert words in lines[-1] and "Traceback" not in bad.stderr, bad.stderr
