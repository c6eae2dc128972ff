"""Reading world files: our YAML format and the seed's wall file (Darmstadt table B.3).

YAML world file (all lengths mm, all angles degrees counter-clockwise from +X)::

    name: office                      # default: the file name
    description: an L-shaped office with a pillar
    start: {x: 800, y: 800, angle_deg: 0}
    north_deg: 90                     # where magnetic north points (default 90: along +Y)
    earth_field_ut: 18                # horizontal Earth field, µT
    robot_radius_mm: 190              # the robot's collision circle
    floor: {glide_factor: 6.5, glide_spread: 0.10, step_scale: 1.01, step_noise: 0.005}
    batteries: {electronics: 1.0, motors: 1.0}       # initial state of charge 0..1
    walls:
      - [0, 0, 4000, 0]                              # one segment x1 y1 x2 y2
      - {from: [0, 0], to: [0, 3000], visible: [0, 4000, 0, 3000]}   # with a visibility box
      - {polygon: [[0, 0], [4000, 0], [4000, 3000], [0, 3000]]}      # closed outline
      - {polyline: [[1000, 0], [1000, 800]]}                         # open chain
    wall_file: lab.walls              # seed-format walls too (path relative to this file)
    circles: [{x: 2000, y: 1500, r: 300}]            # round obstacles
    anomalies: [{x: 1500, y: 900, radius: 400, field_ut: [6, -3]}]

Seed wall file: one wall per line, ten numbers separated by blanks — centre x, centre y,
direction (deg), length, visibility box x0 x1 y0 y1, Hessian d (mm) and alpha (deg); ``#`` lines
are comments. Loaded alone, the robot starts at the middle of the room facing +X.

Every problem is a :class:`WorldError` (exit code 2) naming the file and line.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import yaml

from modules.description.room import Anomaly, Batteries, Circle, Floor, Pose, Wall, World
from tokenring import NumberLoader, TokenRingError, UsageError, one_line, yaml_problem

ROOMS_DIR = Path(__file__).resolve().parent / "rooms"
DEFAULT_WORLD = "office"
#: coordinates beyond this (mm: 100 km) are no room
MAX_COORDINATE_MM = 1e8

_TOP_KEYS = {
    "name",
    "description",
    "start",
    "north_deg",
    "earth_field_ut",
    "robot_radius_mm",
    "floor",
    "batteries",
    "walls",
    "wall_file",
    "circles",
    "anomalies",
}


class WorldError(UsageError):
    """A world file (or world name) cannot be used; the message names file and line."""


def bundled_worlds() -> list[str]:
    """Names of the rooms shipped with tokenring (``tokenring up --world NAME``)."""
    return sorted(p.stem for p in ROOMS_DIR.glob("*.yaml"))


def resolve_world(name_or_path: str | Path) -> Path:
    """A bundled room's file by name, else the given path; WorldError if neither exists."""
    text = str(name_or_path)
    if "/" not in text and "." not in text and (ROOMS_DIR / f"{text}.yaml").exists():
        return ROOMS_DIR / f"{text}.yaml"
    path = Path(text)
    if path.is_file():
        return path
    raise WorldError(f"{text}: no such world file or bundled world (bundled: {', '.join(bundled_worlds())})")


def load_world(name_or_path: str | Path) -> World:
    """Load a bundled room by name (``office``) or a world file (YAML, or a seed wall file)."""
    from tokenring import message_error, read_text

    path = resolve_world(name_or_path)
    text = read_text(path, "world file", message_error(WorldError))
    if _looks_like_wall_file(text):
        walls = parse_wall_file(text, str(path))
        return _finish(World(name=path.stem, walls=tuple(walls), start=Pose(0, 0, 0), source=str(path)), None)
    return parse_world_yaml(text, str(path), path.stem, path.parent)


# ------------------------------------------------------------------------------------------------
# the seed's wall file


def _looks_like_wall_file(text: str) -> bool:
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        return False
    try:
        return all(len(r) == 10 and all(math.isfinite(float(v)) for v in r) for r in rows)
    except ValueError:
        return False


def parse_wall_file(text: str, source: str) -> list[Wall]:
    """Walls of a seed wall file (table B.3); checks that (d, alpha) agree with centre and direction."""
    walls: list[Wall] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 10:
            raise WorldError(f"{source}:{number}: a wall line needs 10 numbers, found {len(parts)}")
        try:
            cx, cy, direction, length, x0, x1, y0, y1, d, alpha = (float(p) for p in parts)
        except ValueError:
            raise WorldError(f"{source}:{number}: not a number in {line!r}") from None
        if length <= 0:
            raise WorldError(f"{source}:{number}: wall of zero length")
        ux, uy = math.cos(math.radians(direction)), math.sin(math.radians(direction))
        wall = Wall(
            cx - ux * length / 2,
            cy - uy * length / 2,
            cx + ux * length / 2,
            cy + uy * length / 2,
            visible=(min(x0, x1), max(x0, x1), min(y0, y1), max(y0, y1)),
            line=number,
        )
        a = math.radians(alpha)
        off_axis = abs(math.cos(a) * ux + math.sin(a) * uy)
        if off_axis > math.sin(math.radians(1.0)) or abs(cx * math.cos(a) + cy * math.sin(a) - d) > 5.0:
            raise WorldError(
                f"{source}:{number}: d={d:g} alpha={alpha:g} do not describe the wall through "
                f"({cx:g}, {cy:g}) at {direction:g}° (expected d={wall.hessian[0]:.1f} "
                f"alpha={math.degrees(wall.hessian[1]):.1f})"
            )
        walls.append(wall)
    return walls


# ------------------------------------------------------------------------------------------------
# YAML with line numbers


class _Map(dict):
    line = 0


class _List(list):
    line = 0


def _compose(text: str, source: str) -> Any:
    try:
        node = yaml.compose(text, Loader=NumberLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}:{mark.line + 1}" if mark else source
        raise WorldError(f"{where}: {yaml_problem(exc)}") from None
    except yaml.YAMLError as exc:
        raise WorldError(f"{source}: not YAML text: {one_line(exc)}") from None
    return _convert(node, source) if node is not None else None


def _convert(node: yaml.Node, source: str) -> Any:
    line = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        out = _Map()
        out.line = line
        for key_node, value_node in node.value:
            key = _convert(key_node, source)
            if not isinstance(key, str):
                raise WorldError(f"{source}:{key_node.start_mark.line + 1}: keys must be words, not {key!r}")
            out[key] = _convert(value_node, source)
        return out
    if isinstance(node, yaml.SequenceNode):
        items = _List(_convert(v, source) for v in node.value)
        items.line = line
        return items
    loader = yaml.SafeLoader("")
    try:
        return loader.construct_object(node, deep=True)
    except yaml.YAMLError as exc:  # e.g. a bare '=' (YAML's value tag, which safe YAML refuses)
        raise WorldError(f"{source}:{line}: not a plain value: {one_line(exc)}") from None
    finally:
        loader.dispose()


class _Reader:
    """Typed access to the parsed YAML with file:line in every message."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, line: int, problem: str) -> WorldError:
        return WorldError(f"{self.source}:{line}: {problem}")

    def number(
        self,
        value: Any,
        line: int,
        what: str,
        *,
        positive: bool = False,
        lo: float | None = None,
        hi: float | None = None,
    ) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise self.fail(line, f"{what} must be a number, not {value!r}")
        if lo is None and hi is None:  # no value of a room is beyond a room's size (1e300 is a typo)
            lo, hi = (0.0 if positive else -MAX_COORDINATE_MM), MAX_COORDINATE_MM
        if positive and value <= 0:
            raise self.fail(line, f"{what} must be positive, not {value!r}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.fail(line, f"{what} must be within {lo:g}..{hi:g}, not {value!r}")
        return float(value)

    def point(self, value: Any, line: int, what: str) -> tuple[float, float]:
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(getattr(value, "line", line), f"{what} must be a point [x, y], not {value!r}")
        return (
            self.number(value[0], line, f"{what} x", lo=-MAX_COORDINATE_MM, hi=MAX_COORDINATE_MM),
            self.number(value[1], line, f"{what} y", lo=-MAX_COORDINATE_MM, hi=MAX_COORDINATE_MM),
        )

    def mapping(self, value: Any, line: int, what: str, keys: set[str]) -> _Map:
        if not isinstance(value, dict):
            raise self.fail(line, f"{what} must be a mapping, not {value!r}")
        unknown = set(value) - keys
        if unknown:
            raise self.fail(
                getattr(value, "line", line),
                f"{what}: unknown key(s) {', '.join(sorted(unknown))} (known: {', '.join(sorted(keys))})",
            )
        return value  # type: ignore[return-value]


def _top_list(r: _Reader, doc: Any, key: str, empty_ok: bool = False) -> list[Any]:
    """The world file's list under ``key`` ([] if absent; with ``empty_ok`` also if left empty):
    anything else is one clear line naming the key, not a traceback from iterating it."""
    raw = doc.get(key, [])
    if empty_ok and not raw:
        return []
    if not isinstance(raw, list):
        raise r.fail(doc.line, f"{key} must be a list")
    return raw


def parse_world_yaml(text: str, source: str, default_name: str = "world", base: Path | None = None) -> World:
    """Parse our YAML world format (see the module docstring)."""
    doc = _compose(text, source)
    r = _Reader(source)
    if doc is None:
        raise WorldError(f"{source}: the file is empty (a world file has walls and a start pose)")
    if not isinstance(doc, dict):
        raise WorldError(
            f"{source}: a world file is a YAML mapping with walls and start, not {type(doc).__name__}"
        )
    doc = r.mapping(doc, 1, "world", _TOP_KEYS)
    top = doc.line

    walls: list[Wall] = []
    raw_walls = _top_list(r, doc, "walls")
    for index, item in enumerate(raw_walls, start=1):
        walls.extend(_parse_wall_item(r, item, index, getattr(item, "line", raw_walls.line)))
    if "wall_file" in doc:
        wall_path = Path(str(doc["wall_file"]))
        if not wall_path.is_absolute() and base is not None:
            wall_path = base / wall_path
        from tokenring import read_text

        def unreadable(where: str, problem: str) -> TokenRingError:
            return r.fail(top, f"wall_file {where}: {problem}")

        walls.extend(parse_wall_file(read_text(wall_path, "wall file", unreadable), str(wall_path)))

    circles = []
    raw_circles = _top_list(r, doc, "circles")
    for index, item in enumerate(raw_circles, start=1):
        line = getattr(item, "line", raw_circles.line)
        if isinstance(item, list) and len(item) == 3:
            x, y, rad = item
        else:
            m = r.mapping(item, line, f"circle {index}", {"x", "y", "r"})
            if set(m) != {"x", "y", "r"}:
                raise r.fail(line, f"circle {index} needs x, y and r")
            x, y, rad = m["x"], m["y"], m["r"]
        circles.append(
            Circle(
                r.number(x, line, f"circle {index} x"),
                r.number(y, line, f"circle {index} y"),
                r.number(rad, line, f"circle {index} r", positive=True),
                line,
            )
        )

    anomalies = []
    raw_anomalies = _top_list(r, doc, "anomalies", empty_ok=True)
    for index, item in enumerate(raw_anomalies, start=1):
        line = getattr(item, "line", top)
        m = r.mapping(item, line, f"anomaly {index}", {"x", "y", "radius", "field_ut"})
        missing = {"x", "y", "radius", "field_ut"} - set(m)
        if missing:
            raise r.fail(line, f"anomaly {index} needs {', '.join(sorted(missing))}")
        bx, by = r.point(m["field_ut"], line, f"anomaly {index} field_ut")
        anomalies.append(
            Anomaly(
                r.number(m["x"], line, f"anomaly {index} x"),
                r.number(m["y"], line, f"anomaly {index} y"),
                r.number(m["radius"], line, f"anomaly {index} radius", positive=True),
                bx,
                by,
            )
        )

    floor = Floor()
    if "floor" in doc:
        m = r.mapping(doc["floor"], top, "floor", set(vars(floor)))
        line = getattr(m, "line", top)
        floor = Floor(
            glide_factor=r.number(
                m.get("glide_factor", floor.glide_factor), line, "floor glide_factor", positive=True
            ),
            glide_spread=r.number(
                m.get("glide_spread", floor.glide_spread), line, "floor glide_spread", lo=0, hi=0.5
            ),
            step_scale=r.number(
                m.get("step_scale", floor.step_scale), line, "floor step_scale", lo=0.5, hi=1.5
            ),
            step_noise=r.number(
                m.get("step_noise", floor.step_noise), line, "floor step_noise", lo=0, hi=0.2
            ),
        )
    batteries = Batteries()
    if "batteries" in doc:
        m = r.mapping(doc["batteries"], top, "batteries", {"electronics", "motors"})
        line = getattr(m, "line", top)
        batteries = Batteries(
            electronics_soc=r.number(m.get("electronics", 1.0), line, "batteries electronics", lo=0, hi=1),
            motors_soc=r.number(m.get("motors", 1.0), line, "batteries motors", lo=0, hi=1),
        )

    start = None
    if "start" in doc:
        m = r.mapping(doc["start"], top, "start", {"x", "y", "angle_deg"})
        line = getattr(m, "line", top)
        if not {"x", "y"} <= set(m):
            raise r.fail(line, "start needs x and y (and angle_deg, default 0)")
        start = Pose(
            r.number(m["x"], line, "start x"),
            r.number(m["y"], line, "start y"),
            math.radians(r.number(m.get("angle_deg", 0.0), line, "start angle_deg", lo=-360, hi=360)),
        )
    world = World(
        name=str(doc.get("name", default_name)),
        description=str(doc.get("description", "")),
        walls=tuple(walls),
        circles=tuple(circles),
        start=start or Pose(0, 0, 0),
        north=math.radians(r.number(doc.get("north_deg", 90.0), top, "north_deg", lo=-360, hi=360)),
        earth_field_ut=r.number(doc.get("earth_field_ut", 18.0), top, "earth_field_ut", positive=True),
        anomalies=tuple(anomalies),
        floor=floor,
        batteries=batteries,
        robot_radius=r.number(doc.get("robot_radius_mm", 190.0), top, "robot_radius_mm", positive=True),
        source=source,
    )
    return _finish(world, getattr(doc.get("start"), "line", None) if start else None)


def _parse_wall_item(r: _Reader, item: Any, index: int, line: int) -> list[Wall]:
    what = f"wall {index}"
    if isinstance(item, list):
        if len(item) != 4:
            raise r.fail(line, f"{what} must be [x1, y1, x2, y2], not {list(item)!r}")
        coords = [r.number(v, line, what, lo=-MAX_COORDINATE_MM, hi=MAX_COORDINATE_MM) for v in item]
        return [_wall(r, *coords, None, line, what)]
    m = r.mapping(item, line, what, {"from", "to", "visible", "polygon", "polyline"})
    visible = None
    if "visible" in m:
        box = m["visible"]
        if not isinstance(box, list) or len(box) != 4:
            raise r.fail(line, f"{what} visible must be [x0, x1, y0, y1]")
        x0, x1, y0, y1 = (r.number(v, line, f"{what} visible") for v in box)
        visible = (min(x0, x1), max(x0, x1), min(y0, y1), max(y0, y1))
    if "from" in m or "to" in m:
        if not {"from", "to"} <= set(m) or {"polygon", "polyline"} & set(m):
            raise r.fail(line, f"{what} needs both from and to (and no polygon/polyline)")
        (x1, y1), (x2, y2) = r.point(m["from"], line, f"{what} from"), r.point(m["to"], line, f"{what} to")
        return [_wall(r, x1, y1, x2, y2, visible, line, what)]
    kind = "polygon" if "polygon" in m else "polyline" if "polyline" in m else None
    if kind is None:
        raise r.fail(line, f"{what} needs from/to, polygon or polyline")
    points = m[kind]
    if not isinstance(points, list) or len(points) < 2:
        raise r.fail(line, f"{what} {kind} needs at least two points")
    pts = [r.point(p, getattr(p, "line", line), f"{what} {kind} point") for p in points]
    if kind == "polygon":
        if len(pts) < 3:
            raise r.fail(line, f"{what} polygon needs at least three points")
        pts.append(pts[0])
    crossing = _self_crossing(pts, closed=kind == "polygon")
    if crossing is not None:
        i, j = crossing
        raise r.fail(line, f"{what} {kind} crosses itself: side {i} and side {j} intersect")
    return [
        _wall(r, *a, *b, visible, line, f"{what} ({kind} side {i})")
        for i, (a, b) in enumerate(itertools.pairwise(pts), start=1)
    ]


def _wall(r: _Reader, x1: float, y1: float, x2: float, y2: float, visible: Any, line: int, what: str) -> Wall:
    if math.hypot(x2 - x1, y2 - y1) < 1e-6:
        raise r.fail(line, f"{what} has zero length (from ({x1:g}, {y1:g}) to itself)")
    return Wall(x1, y1, x2, y2, visible=visible, line=line)


Point = tuple[float, float]


def _side(p: Point, q: Point, r: Point) -> float:
    """Which side of the line pq the point r lies on (the sign), twice the triangle's area."""
    return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])


def _segments_meet(a: Point, b: Point, c: Point, d: Point, ends: bool) -> bool:
    """Whether segments ab and cd intersect; with ``ends``, touching at an end counts too (a
    ray through a corner meets the room), without it only a proper crossing does."""
    first, second = _side(c, d, a) * _side(c, d, b), _side(a, b, c) * _side(a, b, d)
    return first <= 0 and second <= 0 if ends else first < 0 and second < 0


def _self_crossing(pts: list[tuple[float, float]], closed: bool) -> tuple[int, int] | None:
    """The first two sides (1-based) of a polyline or closed polygon that cross, or None."""
    sides = list(itertools.pairwise(pts))
    n = len(sides)
    for i in range(n):
        for j in range(i + 2, n):
            if closed and i == 0 and j == n - 1:
                continue  # the first and last side meet at the first point
            if _segments_meet(*sides[i], *sides[j], ends=False):
                return i + 1, j + 1
    return None


def _escapes(world: World, x: float, y: float) -> float | None:
    """The first of 16 directions (degrees) in which a ray from (x, y) meets no wall, or None:
    a start pose that can see out of the room in some direction is not inside it."""
    reach = 4 * max(
        (max(abs(w.x1 - x), abs(w.y1 - y), abs(w.x2 - x), abs(w.y2 - y)) for w in world.walls), default=1.0
    )
    for k in range(16):
        angle = 2 * math.pi * (k + 0.1) / 16  # off the axes and diagonals, where corners sit
        end = (x + reach * math.cos(angle), y + reach * math.sin(angle))
        if not any(_segments_meet((x, y), end, (w.x1, w.y1), (w.x2, w.y2), ends=True) for w in world.walls):
            return math.degrees(angle)
    return None


def _finish(world: World, start_line: int | None) -> World:
    """Place a missing start pose in the middle of the room; refuse a room without walls, and a
    start inside a wall or obstacle or outside the room."""
    if not world.walls:
        raise WorldError(f"{world.source}: the room has no walls (a world needs at least its outline)")
    if start_line is None and world.start == Pose(0, 0, 0) and (world.walls or world.circles):
        xmin, ymin, xmax, ymax = world.bounds()
        world = _replace_start(world, Pose((xmin + xmax) / 2, (ymin + ymax) / 2, 0.0))
    clearance = world.clearance(world.start.x, world.start.y)
    if clearance < world.robot_radius:
        where = f"{world.source}:{start_line}" if start_line else world.source
        nearest = _nearest_thing(world)
        hint = "" if start_line else " (give a start pose: a YAML file with `wall_file:` and `start:`)"
        raise WorldError(
            f"{where}: start pose ({world.start.x:g}, {world.start.y:g}) is inside {nearest}: "
            f"{clearance:.0f} mm from it, the robot needs {world.robot_radius:g} mm{hint}"
        )
    open_towards = _escapes(world, world.start.x, world.start.y)
    if open_towards is not None:
        where = f"{world.source}:{start_line}" if start_line else world.source
        raise WorldError(
            f"{where}: start pose ({world.start.x:g}, {world.start.y:g}) is outside the room "
            f"(no wall towards {open_towards:.0f}°)"
        )
    return world


def _nearest_thing(world: World) -> str:
    best, label = math.inf, "a wall"
    for i, w in enumerate(world.walls, start=1):
        d = w.distance_to(world.start.x, world.start.y)
        if d < best:
            best, label = d, f"wall {i}" + (f" (line {w.line})" if w.line else "")
    for i, c in enumerate(world.circles, start=1):
        d = math.hypot(world.start.x - c.x, world.start.y - c.y) - c.r
        if d < best:
            best, label = d, f"circle {i}" + (f" (line {c.line})" if c.line else "")
    return label


def _replace_start(world: World, start: Pose) -> World:
    from dataclasses import replace

    return replace(world, start=start)
