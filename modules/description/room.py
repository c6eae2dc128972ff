"""The world's description: walls, round obstacles, the robot's start pose, the magnetic field, the floor.

Everything here is in the program convention: millimetres, radians, counter-clockwise, 0 along +X.
A :class:`World` is immutable; the simulator keeps the robot's moving state elsewhere. Mapping
(scoring against true walls) and the EKF (known walls, the seed's wall file) import it too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Pose:
    """A robot pose: x, y in mm, theta in radians counter-clockwise from +X."""

    x: float
    y: float
    theta: float = 0.0


@dataclass(frozen=True)
class Wall:
    """A wall segment from (x1, y1) to (x2, y2) in mm.

    ``visible`` is the seed wall file's visibility box (x0, x1, y0, y1): the area the robot must
    be in to see the wall (None: visible from everywhere). ``line`` is where it was defined."""

    x1: float
    y1: float
    x2: float
    y2: float
    visible: tuple[float, float, float, float] | None = None
    line: int = 0

    @property
    def length(self) -> float:
        return math.hypot(self.x2 - self.x1, self.y2 - self.y1)

    @property
    def direction(self) -> float:
        """Direction of the segment, radians CCW from +X, in [0, pi) (a wall has no sense)."""
        return math.atan2(self.y2 - self.y1, self.x2 - self.x1) % math.pi

    @property
    def centre(self) -> tuple[float, float]:
        return ((self.x1 + self.x2) / 2, (self.y1 + self.y2) / 2)

    @property
    def hessian(self) -> tuple[float, float]:
        """Hessian normal form (d, alpha): x cos(alpha) + y sin(alpha) = d with d >= 0, alpha in [0, 2 pi)."""
        alpha = self.direction + math.pi / 2
        cx, cy = self.centre
        d = cx * math.cos(alpha) + cy * math.sin(alpha)
        if d < 0:
            d, alpha = -d, alpha + math.pi
        return d, alpha % (2 * math.pi)

    def distance_to(self, x: float, y: float) -> float:
        """Shortest distance from a point to this segment, mm."""
        return float(point_segment_distance(np.array([[x, y]]), np.array([self.as_tuple()]))[0, 0])

    def as_tuple(self) -> tuple[float, float, float, float]:
        return (self.x1, self.y1, self.x2, self.y2)


@dataclass(frozen=True)
class Circle:
    """A round obstacle (pillar, bin): centre and radius in mm."""

    x: float
    y: float
    r: float
    line: int = 0


@dataclass(frozen=True)
class Anomaly:
    """A local magnetic disturbance: a horizontal field (bx, by) in µT at (x, y), fading as a
    Gaussian of the distance with the given radius (mm)."""

    x: float
    y: float
    radius: float
    bx: float
    by: float


@dataclass(frozen=True)
class Floor:
    """How the floor makes real motion differ from the steps issued (SPEC §5 defaults).

    ``glide_factor``: true half-steps per degree of turn (mean); ``glide_spread``: each turn draws
    uniformly within ±spread of it; ``step_scale``: systematic true/nominal straight step length;
    ``step_noise``: relative standard deviation of the straight step length, drawn per move."""

    glide_factor: float = 6.5
    glide_spread: float = 0.10
    step_scale: float = 1.01
    step_noise: float = 0.005


@dataclass(frozen=True)
class Batteries:
    """Initial state of charge (0..1) of the 12 V electronics battery and the 36 V motor pack."""

    electronics_soc: float = 1.0
    motors_soc: float = 1.0


@dataclass(frozen=True)
class World:
    """A room and what the simulator needs to run the robot in it."""

    name: str
    walls: tuple[Wall, ...]
    start: Pose
    circles: tuple[Circle, ...] = ()
    north: float = math.pi / 2  # direction of magnetic north, radians CCW from +X
    earth_field_ut: float = 18.0  # horizontal component of the Earth's field, µT
    anomalies: tuple[Anomaly, ...] = ()
    floor: Floor = field(default_factory=Floor)
    batteries: Batteries = field(default_factory=Batteries)
    robot_radius: float = 190.0  # the robot's collision circle, mm
    source: str = ""
    description: str = ""

    def segments(self) -> np.ndarray:
        """The walls as an (N, 4) array of x1, y1, x2, y2 (mm)."""
        if not self.walls:
            return np.zeros((0, 4))
        return np.array([w.as_tuple() for w in self.walls], dtype=float)

    def circle_array(self) -> np.ndarray:
        """The round obstacles as an (M, 3) array of x, y, r (mm)."""
        if not self.circles:
            return np.zeros((0, 3))
        return np.array([(c.x, c.y, c.r) for c in self.circles], dtype=float)

    def outline(self, circle_sides: int = 32) -> np.ndarray:
        """Walls plus every circle as a polygon of ``circle_sides`` segments: what a map should show."""
        parts = [self.segments()]
        for c in self.circles:
            a = np.linspace(0, 2 * math.pi, circle_sides + 1)
            xs, ys = c.x + c.r * np.cos(a), c.y + c.r * np.sin(a)
            parts.append(np.column_stack([xs[:-1], ys[:-1], xs[1:], ys[1:]]))
        return np.vstack(parts)

    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of everything in the room, mm."""
        outline = self.outline(8)
        if len(outline) == 0:
            return (0.0, 0.0, 0.0, 0.0)
        xs, ys = outline[:, [0, 2]], outline[:, [1, 3]]
        return (float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max()))

    def clearance(self, x: float, y: float) -> float:
        """Distance from a point to the nearest wall or obstacle surface, mm (inf in an empty world)."""
        best = math.inf
        if self.walls:
            best = float(point_segment_distance(np.array([[x, y]]), self.segments()).min())
        for c in self.circles:
            best = min(best, math.hypot(x - c.x, y - c.y) - c.r)
        return best

    def nearest_point(self, x: float, y: float) -> tuple[float, float] | None:
        """The point of a wall or obstacle surface nearest to (x, y), mm (None in an empty world)."""
        best: tuple[float, float, float] | None = None
        if self.walls:
            seg = self.segments()
            a, ab = seg[:, 0:2], seg[:, 2:4] - seg[:, 0:2]
            denom = np.einsum("ij,ij->i", ab, ab)
            t = np.clip(
                np.einsum("ij,ij->i", np.array([x, y]) - a, ab) / np.where(denom > 0, denom, 1.0), 0, 1
            )
            closest = a + t[:, None] * ab
            d = np.hypot(closest[:, 0] - x, closest[:, 1] - y)
            k = int(np.argmin(d))
            best = (float(d[k]), float(closest[k, 0]), float(closest[k, 1]))
        for c in self.circles:
            d = math.hypot(x - c.x, y - c.y)
            if d > 0 and (best is None or d - c.r < best[0]):
                best = (d - c.r, c.x + (x - c.x) * c.r / d, c.y + (y - c.y) * c.r / d)
        return None if best is None else (best[1], best[2])

    def heading(self, theta: float) -> float:
        """Compass heading of a robot pointing at ``theta``: radians from north, clockwise, [0, 2 pi)."""
        return (self.north - theta) % (2 * math.pi)

    def to_wall_file(self) -> str:
        """The walls in the seed's wall-file format (Darmstadt table B.3), one line per wall:
        centre x, centre y, direction (deg), length, visibility x0 x1 y0 y1, d, alpha (deg)."""
        xmin, ymin, xmax, ymax = self.bounds()
        lines = []
        for w in self.walls:
            cx, cy = w.centre
            d, alpha = w.hessian
            box = w.visible or (xmin, xmax, ymin, ymax)
            values = [cx, cy, math.degrees(w.direction), w.length, *box, d, math.degrees(alpha)]
            lines.append(" ".join(f"{v:.1f}" for v in values))
        return "\n".join(lines) + "\n"

    @classmethod
    def geometry_from_dict(cls, info: dict[str, Any]) -> World:
        """The room's geometry back from :meth:`to_dict`'s values (``world/info``): its name,
        walls, obstacles and start; the rest (floor, field, batteries) keeps its defaults."""
        start = info.get("start") or [0.0, 0.0, 0.0]
        return cls(
            name=str(info.get("name", "world")),
            walls=tuple(Wall(*map(float, w[:4])) for w in info.get("walls", [])),
            start=Pose(*map(float, start[:3])),
            circles=tuple(Circle(*map(float, c[:3])) for c in info.get("circles", [])),
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain values (msgpack/JSON): what ``world/info`` serves to tools."""
        return {
            "name": self.name,
            "description": self.description,
            "walls": [list(w.as_tuple()) for w in self.walls],
            "circles": [[c.x, c.y, c.r] for c in self.circles],
            "start": [self.start.x, self.start.y, self.start.theta],
            "north_rad": self.north,
            "earth_field_ut": self.earth_field_ut,
            "anomalies": [[a.x, a.y, a.radius, a.bx, a.by] for a in self.anomalies],
            "floor": vars(self.floor).copy(),
            "batteries": vars(self.batteries).copy(),
            "robot_radius": self.robot_radius,
            "source": self.source,
        }


def point_segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distances (P, S) from each of P points (x, y) to each of S segments (x1, y1, x2, y2)."""
    p = points[:, None, :]
    a = segments[None, :, 0:2]
    b = segments[None, :, 2:4]
    ab = b - a
    denom = np.einsum("...i,...i", ab, ab)
    t = np.einsum("...i,...i", p - a, ab) / np.where(denom > 0, denom, 1.0)
    t = np.clip(t, 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(p - closest, axis=-1)
