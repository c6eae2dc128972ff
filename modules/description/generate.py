"""Random but plausible rooms, one per seed: rooms nobody tuned the mapping for (issue 21).

A room is an outline of 5-14 walls built from a rectangle: one corner may be pulled along a
side (an acute and an obtuse corner), corners cut off at a slant, rectangular notches taken
out of the sides; then partition stubs standing out of a wall, 0-3 free-standing pillars
(square, turned, round), and a start pose with room to turn. The polygon work is
`shapely`'s; the result is checked by the world loader like any world file.

    tokenring world generate --seed 7 --out room7.yaml
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import yaml
from shapely import affinity
from shapely.geometry import LineString, Point, Polygon, box
from shapely.geometry.polygon import orient
from shapely.ops import unary_union

#: the robot needs this much room round a pillar or stub to pass it (its radius is 190 mm)
PASSAGE_MM = 700.0
#: the start pose keeps this far from everything
START_CLEARANCE_MM = 500.0
#: every stretch of the outline lies this near somewhere the robot's centre can get to (a gap
#: narrower than the robot, ``ROBOT_ROOM_MM`` each side, is a wall): two notches side by side
#: once left a pocket 0.6 m wide whose only way in was 11 cm wide, 2 m of walls nobody could map;
#: a stub's tip 38 cm from a notch's corner another, 2.4 m
OUTLINE_REACH_MM = 600.0
ROBOT_ROOM_MM = 220.0
MIN_WALLS, MAX_WALLS = 5, 14


def _round(value: float) -> int:
    return int(round(value / 10.0) * 10)


def _outline(rng: np.random.Generator, width: float, height: float) -> Polygon:
    """The room's outline: a rectangle, reshaped until it has 5-14 sides."""
    corners = [(0.0, 0.0), (width, 0.0), (width, height), (0.0, height)]
    if rng.random() < 0.4:  # a corner pulled along its side: an acute and an obtuse corner
        i = int(rng.integers(4))
        x, y = corners[i]
        shift = rng.uniform(0.15, 0.35) * (width if rng.random() < 0.5 else height)
        if rng.random() < 0.5:
            corners[i] = (x + shift if x == 0 else x - shift, y)
        else:
            corners[i] = (x, y + shift if y == 0 else y - shift)
    room = Polygon(corners)
    for _ in range(int(rng.integers(0, 3))):
        room = _cut(room, _slanted_corner(rng, room))
    for _ in range(int(rng.integers(0, 3))):
        room = _cut(room, _notch(rng, room))
    for _ in range(50):  # at least five walls: cut another corner off
        if len(room.exterior.coords) - 1 >= MIN_WALLS:
            break
        room = _cut(room, _slanted_corner(rng, room))
    return orient(room)


def _slanted_corner(rng: np.random.Generator, room: Polygon) -> Polygon:
    """A triangle at a corner of the room's bounding box: cut off, it leaves a slanted wall."""
    x0, y0, x1, y1 = room.bounds
    cx, cy = (x0, x1)[int(rng.integers(2))], (y0, y1)[int(rng.integers(2))]
    a, b = rng.uniform(500, 1400), rng.uniform(500, 1400)
    sx, sy = (1 if cx == x0 else -1), (1 if cy == y0 else -1)
    return Polygon([(cx, cy), (cx + sx * a, cy), (cx, cy + sy * b)])


def _notch(rng: np.random.Generator, room: Polygon) -> Polygon:
    """A rectangle reaching 1 mm past one side of the bounding box: cut out, a notch."""
    x0, y0, x1, y1 = room.bounds
    depth, span = rng.uniform(400, 1200), rng.uniform(800, 1800)
    side = int(rng.integers(4))  # bottom, right, top, left
    if side in (0, 2):
        u = rng.uniform(x0 + 600, max(x0 + 600, x1 - 600 - span))
        return box(u, y0 - 1, u + span, y0 + depth) if side == 0 else box(u, y1 - depth, u + span, y1 + 1)
    v = rng.uniform(y0 + 600, max(y0 + 600, y1 - 600 - span))
    return box(x1 - depth, v, x1 + 1, v + span) if side == 1 else box(x0 - 1, v, x0 + depth, v + span)


def _cut(room: Polygon, piece: Polygon) -> Polygon:
    """``room`` without ``piece``, if that leaves one simple polygon with no side too short to
    follow and at most :data:`MAX_WALLS` sides; else ``room`` as it was."""
    rest = room.difference(piece).simplify(1.0)
    if not isinstance(rest, Polygon) or not rest.is_valid or rest.interiors:
        return room
    coords = list(rest.exterior.coords)[:-1]
    if len(coords) > MAX_WALLS or rest.area < 0.6 * room.area:
        return room
    sides = [math.dist(a, b) for a, b in zip(coords, coords[1:] + coords[:1], strict=True)]
    return rest if min(sides) >= 300 and _within_reach(rest) else room


def _within_reach(room: Polygon, stubs: Sequence[LineString] = ()) -> bool:
    """Every point of the outline and the stubs lies within :data:`OUTLINE_REACH_MM` of the
    largest piece of the room the robot's centre can go in (no pocket behind a gap it does not
    fit through)."""
    free = room.difference(unary_union([stub.buffer(1.0) for stub in stubs])) if stubs else room
    inner = free.buffer(-ROBOT_ROOM_MM)
    if inner.is_empty:
        return False
    largest = max(getattr(inner, "geoms", [inner]), key=lambda piece: piece.area)
    reach = largest.buffer(OUTLINE_REACH_MM)
    return bool(reach.covers(room.exterior) and all(reach.covers(stub) for stub in stubs))


def _pillar(rng: np.random.Generator, free: Any) -> tuple[str, Any] | None:
    """A square, turned or round pillar somewhere in ``free`` (where its centre may go)."""
    if free.is_empty:
        return None
    x0, y0, x1, y1 = free.bounds
    for _ in range(200):
        centre = Point(rng.uniform(x0, x1), rng.uniform(y0, y1))
        if free.contains(centre):
            break
    else:
        return None
    kind = ("square", "turned", "round")[int(rng.integers(3))]
    size = rng.uniform(250, 500)
    if kind == "round":
        return kind, centre.buffer(size / 2)
    shape = box(centre.x - size / 2, centre.y - size / 2, centre.x + size / 2, centre.y + size / 2)
    if kind == "turned":
        shape = affinity.rotate(shape, rng.uniform(15, 75), origin=centre)
    return kind, shape


def _stub(rng: np.random.Generator, room: Polygon) -> LineString | None:
    """A partition stub: a wall standing out of a long axis-parallel side into the room."""
    coords = list(room.exterior.coords)
    sides = [
        (a, b)
        for a, b in itertools.pairwise(coords)
        if math.dist(a, b) >= 2500 and (abs(a[0] - b[0]) < 1 or abs(a[1] - b[1]) < 1)
    ]
    if not sides:
        return None
    a, b = sides[int(rng.integers(len(sides)))]
    t = rng.uniform(0.3, 0.7)
    foot = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
    length = rng.uniform(600, 1400)
    dx, dy = (b[0] - a[0]) / math.dist(a, b), (b[1] - a[1]) / math.dist(a, b)
    for nx, ny in ((-dy, dx), (dy, -dx)):  # the normal that points into the room
        tip = (foot[0] + nx * length, foot[1] + ny * length)
        stub = LineString([foot, tip])
        if room.buffer(-10).contains(Point(foot[0] + nx * 20, foot[1] + ny * 20)) and room.covers(stub):
            return stub
    return None


def generate_room(seed: int, size: tuple[float, float] | None = None) -> dict[str, Any]:
    """The world file (as data) of the room for ``seed``; ``size`` (mm) fixes its bounding box."""
    rng = np.random.default_rng(seed)
    width, height = size or (rng.uniform(4000, 8000), rng.uniform(3000, 6000))
    room = _outline(rng, float(width), float(height))
    obstacles: list[tuple[str, Any]] = []
    stubs: list[LineString] = []
    taken = room.exterior.buffer(PASSAGE_MM)
    for _ in range(int(rng.integers(0, 3))):
        stub = _stub(rng, room)
        if (
            stub is not None
            and all(stub.distance(other) >= PASSAGE_MM for other in stubs)
            and _within_reach(room, [*stubs, stub])
        ):
            stubs.append(stub)
            taken = taken.union(stub.buffer(PASSAGE_MM))
    for _ in range(int(rng.integers(0, 4))):
        free = room.buffer(-PASSAGE_MM - 300).difference(taken)
        pillar = _pillar(rng, free)
        if pillar is not None:
            obstacles.append(pillar)
            taken = taken.union(pillar[1].buffer(PASSAGE_MM))
    start = _start(rng, room, stubs, [shape for _, shape in obstacles])
    return _world_data(seed, room, stubs, obstacles, start)


def _start(
    rng: np.random.Generator, room: Polygon, stubs: list[LineString], shapes: list[Any]
) -> tuple[float, float, float]:
    """A start pose with :data:`START_CLEARANCE_MM` round it, facing along an axis."""
    things = [room.exterior, *stubs, *shapes]
    x0, y0, x1, y1 = room.bounds
    best: tuple[float, Point] | None = None
    for _ in range(400):
        p = Point(rng.uniform(x0, x1), rng.uniform(y0, y1))
        if not room.contains(p):
            continue
        clearance = min(p.distance(t) for t in things)
        if clearance >= START_CLEARANCE_MM:
            return p.x, p.y, float(rng.integers(4)) * 90.0
        if best is None or clearance > best[0]:
            best = (clearance, p)
    assert best is not None, "a room with no inside"
    return best[1].x, best[1].y, 0.0


def _world_data(
    seed: int,
    room: Polygon,
    stubs: list[LineString],
    obstacles: list[tuple[str, Any]],
    start: tuple[float, float, float],
) -> dict[str, Any]:
    x0, y0, *_ = room.bounds

    def point(x: float, y: float) -> list[int]:
        return [_round(x - x0), _round(y - y0)]

    walls: list[Any] = [{"polygon": [point(*c) for c in list(room.exterior.coords)[:-1]]}]
    walls += [{"from": point(*s.coords[0]), "to": point(*s.coords[1])} for s in stubs]
    circles = []
    kinds = []
    for kind, shape in obstacles:
        kinds.append(kind)
        if kind == "round":
            c = shape.centroid
            radius = math.sqrt(shape.area / math.pi)
            circles.append({"x": _round(c.x - x0), "y": _round(c.y - y0), "r": _round(radius)})
        else:
            walls.append({"polygon": [point(*c) for c in list(shape.exterior.coords)[:-1]]})
    sides = len(room.exterior.coords) - 1
    x1, y1 = room.bounds[2] - x0, room.bounds[3] - y0
    data: dict[str, Any] = {
        "name": f"generated-{seed}",
        "description": (
            f"a generated room (seed {seed}): {x1 / 1000:.1f} m x {y1 / 1000:.1f} m, {sides} walls, "
            f"{len(stubs)} partition stub(s), pillars: {', '.join(kinds) or 'none'}"
        ),
        "start": {"x": _round(start[0] - x0), "y": _round(start[1] - y0), "angle_deg": int(start[2])},
        "walls": walls,
    }
    if circles:
        data["circles"] = circles
    return data


def room_yaml(data: dict[str, Any]) -> str:
    """A world file's text (the loader reads it like any other)."""
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
