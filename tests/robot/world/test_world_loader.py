"""World files: bundled rooms, our YAML format, the seed's wall file, and clear errors."""

from __future__ import annotations

import math

import pytest

from modules.description import WorldError, bundled_worlds, load_world
from modules.description.roomfile import parse_wall_file


def test_bundled_rooms_load_with_clear_start_poses():
    assert set(bundled_worlds()) >= {"empty", "office", "square", "slanted"}
    for name in bundled_worlds():
        world = load_world(name)
        assert world.walls and world.name == name
        assert world.clearance(world.start.x, world.start.y) >= world.robot_radius
    office = load_world("office")
    assert office.bounds() == (0.0, 0.0, 6000.0, 5000.0) and office.anomalies
    assert load_world("slanted").circles[0].r == 300
    # the Darmstadt hall: every wall axis-parallel, the 3 m square path fits with room to spare
    square = load_world("square")
    assert all(w.direction in (0.0, math.pi / 2) for w in square.walls)
    for x, y in [(1000, 1000), (4000, 1000), (4000, 4000), (1000, 4000)]:
        assert square.clearance(x, y) > square.robot_radius


def test_yaml_world_fields_and_conventions(tmp_path):
    path = tmp_path / "room.yaml"
    path.write_text(
        "name: box\n"
        "start: {x: 500, y: 600, angle_deg: 90}\n"
        "north_deg: 0\n"
        "floor: {glide_factor: 7.2}\n"
        "batteries: {motors: 0.25}\n"
        "walls:\n"
        "  - [0, 0, 2000, 0]\n"
        "  - {from: [2000, 0], to: [2000, 2000], visible: [1000, 2000, 0, 2000]}\n"
        "  - {polyline: [[2000, 2000], [0, 2000], [0, 0]]}\n"
        "circles: [[1000, 1400, 100]]\n"
    )
    world = load_world(path)
    assert world.name == "box" and len(world.walls) == 4
    assert world.start.theta == pytest.approx(math.pi / 2)
    assert world.floor.glide_factor == 7.2 and world.floor.step_scale == 1.01
    assert world.batteries.motors_soc == 0.25 and world.batteries.electronics_soc == 1.0
    assert world.walls[1].visible == (1000, 2000, 0, 2000)
    # north along +X: a robot facing +Y heads 270° (west... of a compass whose north is +X)
    assert math.degrees(world.heading(math.pi / 2)) == pytest.approx(270)
    d, alpha = world.walls[1].hessian
    assert d == pytest.approx(2000) and alpha == pytest.approx(0)


def test_seed_wall_file_loads_and_round_trips(tmp_path):
    square = load_world("square")
    text = square.to_wall_file()
    path = tmp_path / "lab.walls"
    path.write_text("# the Darmstadt hall\n" + text)
    walls = load_world(path)
    assert len(walls.walls) == len(square.walls)
    for a, b in zip(square.walls, walls.walls, strict=True):
        assert a.hessian == pytest.approx(b.hessian, abs=0.2)
        assert {(round(a.x1), round(a.y1)), (round(a.x2), round(a.y2))} == {
            (round(b.x1), round(b.y1)),
            (round(b.x2), round(b.y2)),
        }
    assert walls.start.x == 2500 and walls.start.y == 2500  # the middle of the room
    # a YAML file can take seed walls and add a start pose
    (tmp_path / "lab.yaml").write_text("wall_file: lab.walls\nstart: {x: 1000, y: 1000}\n")
    assert load_world(tmp_path / "lab.yaml").start.x == 1000


def test_seed_wall_file_with_wrong_hessian_is_refused():
    with pytest.raises(WorldError, match=r"lab:2: d=100 alpha=90 do not describe"):
        parse_wall_file("# c\n1000 0 0 2000 0 2000 0 2000 100 90\n", "lab")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("walls:\n  - [0, 0, 1000, 0\nstart: {x: 1, y: 2}\n", r"room.yaml:3: YAML syntax error"),
        (
            "start: {x: 500, y: 500}\nwalls:\n  - [0, 0, 3000, 0]\n  - [1000, 1000, 1000, 1000]\n",
            r"room.yaml:4: wall 2 has zero length",
        ),
        (
            "walls:\n  - polygon: [[0, 0], [3000, 0], [3000, 3000], [0, 3000]]\n  - [0, 1500, 3000, 1500]\n"
            "start: {x: 1000, y: 1550}\n",
            r"room.yaml:4: start pose \(1000, 1550\) is inside wall 5 \(line 3\)",
        ),
        ("walls: []\nstart: {x: 1, y: 2}\nfloors: {}\n", r"room.yaml:1: world: unknown key\(s\) floors"),
        ("walls:\n  - [0, 0, a, 0]\n", r"room.yaml:2: wall 1 must be a number"),
        (
            "start: {x: 1, y: 2}\nfloor: {glide_factor: -1}\n",
            r"room.yaml:2: floor glide_factor must be positive",
        ),
        ("- just a list\n", r"a world file is a YAML mapping"),
        ("", r"room.yaml: the file is empty"),
        ("start: {x: 1, y: 2}\n", r"room.yaml: the room has no walls"),
        (
            "walls:\n  - polygon: [[0, 0], [3000, 3000], [3000, 0], [0, 3000]]\nstart: {x: 100, y: 1500}\n",
            r"room.yaml:2: wall 1 polygon crosses itself: side 1 and side 3 intersect",
        ),
        (
            "walls:\n  - polygon: [[0, 0], [3000, 0], [3000, 3000], [0, 3000]]\nstart: {x: 5000, y: 1500}\n",
            r"room.yaml:3: start pose \(5000, 1500\) is outside the room",
        ),
        ("walls:\n  - [0, 0, 1.0e+300, 0]\n", r"room.yaml:2: wall 1 must be within -1e\+08..1e\+08"),
        ("walls:\n  - polygon: [[0, 0], [1e9, 0], [0, 5]]\n", r"room.yaml:2: .*must be within"),
    ],
)
def test_bad_world_files_name_file_and_line(tmp_path, text, message):
    path = tmp_path / "room.yaml"
    path.write_text(text)
    with pytest.raises(WorldError, match=message) as info:
        load_world(path)
    assert info.value.exit_code == 2


def test_unknown_world_name_lists_bundled_rooms():
    with pytest.raises(
        WorldError, match=r"no such world file or bundled world \(bundled: darmstadt-hall, empty, office"
    ):
        load_world("kitchen")


@pytest.mark.parametrize("name", ["square", "office"])
def test_a_rooms_geometry_comes_back_from_what_world_info_serves(name: str) -> None:
    """LOPS rebuilds the room it measures in from ``world/info``: walls, obstacles and start."""
    import msgpack

    from modules.description.room import World

    world = load_world(name)
    served = msgpack.unpackb(msgpack.packb(world.to_dict()))  # as it crosses Zenoh
    again = World.geometry_from_dict(served)

    def segments(w: World) -> list[tuple[float, float, float, float]]:
        return [(s.x1, s.y1, s.x2, s.y2) for s in w.walls]

    assert (again.name, segments(again), again.circles, again.start) == (
        world.name,
        segments(world),
        world.circles,
        world.start,
    )
