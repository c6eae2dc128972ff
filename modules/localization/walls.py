"""Walls for the localisation: known walls (wall file, world, map) and the seed's sonar wall detector.

Lines are in Hessian normal form ``x·cos α + y·sin α = d`` with ``d ≥ 0`` (seed 000, §6.2.4).
The detector fits lines in the *odometry frame* (continuous dead reckoning, never corrected) so
that a correction of the filter in the middle of a fit cannot bend it, and reports each line in
the robot's frame at the synchronisation time together with its covariance; the filter then
associates it with a known wall (Darmstadt mode: the wall file; exploration mode: the map).

Two kinds of lines, as in the seed:

- **side** — one side-looking sensor's points collected while driving past a wall, fitted by
  orthogonal regression (the seed's ``y = m·x + b`` fails on walls parallel to the Y axis);
  accepted while the std of the point distances stays below a bound, then grown with older
  points while it still does;
- **pair** — two sensors measuring at the same time give one line per sample pair (the seed's
  formula); the mean of the last n is accepted while the std of α and d stay below bounds.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tokenring import UsageError

TWO_PI = 2.0 * math.pi


def wrap(angle: float) -> float:
    """``angle`` in [-π, π)."""
    return (angle + math.pi) % TWO_PI - math.pi


def hessian(x1: float, y1: float, x2: float, y2: float) -> tuple[float, float]:
    """Hessian normal form (α, d ≥ 0) of the line through two points."""
    alpha = math.atan2(x2 - x1, -(y2 - y1))  # normal = direction rotated by -90°
    d = x1 * math.cos(alpha) + y1 * math.sin(alpha)
    if d < 0:
        alpha, d = alpha + math.pi, -d
    return wrap(alpha), d


def line_in_frame(alpha: float, d: float, pose: tuple[float, float, float]) -> tuple[float, float]:
    """A line given in the outer frame, expressed in the frame of ``pose`` (x, y, ψ); d ≥ 0."""
    x, y, psi = pose
    a = alpha - psi
    dd = d - x * math.cos(alpha) - y * math.sin(alpha)
    if dd < 0:
        a, dd = a + math.pi, -dd
    return wrap(a), dd


def to_frame(point: tuple[float, float], pose: tuple[float, float, float]) -> tuple[float, float]:
    """A point of the outer frame in the frame of ``pose``."""
    dx, dy = point[0] - pose[0], point[1] - pose[1]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return c * dx + s * dy, -s * dx + c * dy


def from_frame(point: tuple[float, float], pose: tuple[float, float, float]) -> tuple[float, float]:
    """A point given in the frame of ``pose``, in the outer frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pose[0] + c * point[0] - s * point[1], pose[1] + s * point[0] + c * point[1]


# =============================================================================================
# known walls


@dataclass(frozen=True)
class KnownWall:
    """A wall the robot knows: a segment (mm) and its Hessian form; ``box`` limits visibility."""

    x1: float
    y1: float
    x2: float
    y2: float
    alpha: float
    d: float
    index: int = 0
    box: tuple[float, float, float, float] | None = None  # x0, x1, y0, y1 (seed table B.3)

    @classmethod
    def segment(cls, x1: float, y1: float, x2: float, y2: float, index: int = 0) -> KnownWall:
        alpha, d = hessian(x1, y1, x2, y2)
        return cls(float(x1), float(y1), float(x2), float(y2), alpha, d, index)

    @property
    def length(self) -> float:
        return math.hypot(self.x2 - self.x1, self.y2 - self.y1)

    def visible_from(self, x: float, y: float) -> bool:
        if self.box is None:
            return True
        x0, x1, y0, y1 = self.box
        return x0 <= x <= x1 and y0 <= y <= y1

    def contains(self, p1: tuple[float, float], p2: tuple[float, float], margin: float) -> bool:
        """Whether segment p1–p2 projects onto this wall entirely (± ``margin`` mm at the ends).

        A fitted line that runs past a wall's end was fitted partly on something else (a corner,
        the wall behind a post): associating it would pull the pose the wrong way."""
        length = self.length
        if length <= 0:
            return False
        ux, uy = (self.x2 - self.x1) / length, (self.y2 - self.y1) / length
        t1 = (p1[0] - self.x1) * ux + (p1[1] - self.y1) * uy
        t2 = (p2[0] - self.x1) * ux + (p2[1] - self.y1) * uy
        return min(t1, t2) >= -margin and max(t1, t2) <= length + margin

    def overlap(self, p1: tuple[float, float], p2: tuple[float, float], margin: float) -> bool:
        """Whether the projection of segment p1–p2 onto this wall overlaps it (± ``margin`` mm)."""
        length = self.length
        if length <= 0:
            return False
        ux, uy = (self.x2 - self.x1) / length, (self.y2 - self.y1) / length
        t1 = (p1[0] - self.x1) * ux + (p1[1] - self.y1) * uy
        t2 = (p2[0] - self.x1) * ux + (p2[1] - self.y1) * uy
        lo, hi = min(t1, t2), max(t1, t2)
        return hi >= -margin and lo <= length + margin


def load_known_room(
    name_or_path: str | Path,
) -> tuple[list[KnownWall], list[tuple[float, float, float]]]:
    """A room's known walls (a bundled world name, a YAML world file or the seed's wall file), and
    its round obstacles (x, y, radius in mm): nothing a wall fit can use, but a beam meets them
    before the wall behind.

    Reads through :func:`modules.description.load_world`, so every format the simulator accepts works
    here too; the seed wall file's visibility boxes (table B.3) are kept. Errors name the file
    and line (exit code 2 on the command line).
    """
    from modules.description import load_world

    world = load_world(name_or_path)
    if not world.walls:
        raise UsageError(f"{name_or_path}: the room has no walls to localise against")
    walls = []
    for i, w in enumerate(world.walls):
        wall = KnownWall.segment(w.x1, w.y1, w.x2, w.y2, index=i)
        walls.append(KnownWall(wall.x1, wall.y1, wall.x2, wall.y2, wall.alpha, wall.d, i, w.visible))
    return walls, [(c.x, c.y, c.r) for c in world.circles]


# how much later than the wall's distance a sonar's echo reads (walls.sonar_late, measured on
# recorded drives): a part growing with the range, and one with the wall's angle off the beam
def range_lateness_mm(range_mm: float, from_mm: float, mm_per_m: float) -> float:
    """The late echo's range part: ``mm_per_m`` beyond ``from_mm``."""
    return max(0.0, range_mm - from_mm) * mm_per_m / 1000.0


def off_axis_lateness_mm(off_axis: float, mm_per_deg2: float) -> float:
    """The late echo's angle part: ``mm_per_deg2`` times the square of the wall's normal's angle off
    the beam's axis (``off_axis``, rad) in degrees (a weaker echo crosses the threshold later)."""
    return mm_per_deg2 * math.degrees(off_axis) ** 2


def circle_in_beam(
    origin: tuple[float, float], direction: float, half_width: float, circle: tuple[float, float, float]
) -> float | None:
    """How far a sonar cone first meets a round obstacle (its near face, within the cone or
    touching its edge); None if the cone misses it."""
    cx, cy, radius = circle
    distance = math.hypot(cx - origin[0], cy - origin[1])
    if distance <= radius:
        return 0.0
    off = abs(wrap(math.atan2(cy - origin[1], cx - origin[0]) - direction))
    if off > half_width + math.asin(radius / distance) or off > math.pi / 2:
        return None
    return distance - radius


def segments_to_walls(segments: Any) -> list[KnownWall]:
    """Known walls from ``(x1, y1, x2, y2)`` segments in mm (a world's walls, the map's vectors)."""
    return [KnownWall.segment(*map(float, seg[:4]), index=i) for i, seg in enumerate(segments)]


#: a known wall within this of an axis counts as parallel to it (the seed's lab had no other)
AXIS_TOLERANCE_RAD = math.radians(5.0)


def wall_position(
    reference: tuple[float, float, float], fits: list[tuple[float, float, KnownWall]]
) -> dict[str, Any] | None:
    """The seed's position from associated walls (seed 000 §6.2.4): each wall's heading error
    (its measured against its known direction) and, for a wall parallel to an axis, the error
    of the one coordinate across it (measured against computed distance); the errors averaged
    and taken off the ``reference`` pose. A coordinate no wall corrected keeps the reference
    value with its valid flag false. ``fits``: (α, d) measured in the robot frame and the known
    wall each was associated with. None without walls."""
    if not fits:
        return None
    x0, y0, psi0 = reference
    headings: list[float] = []
    dx: list[float] = []
    dy: list[float] = []
    limit = math.sin(AXIS_TOLERANCE_RAD)
    for alpha_r, d_r, wall in fits:
        alpha_known, d_known = line_in_frame(wall.alpha, wall.d, reference)
        headings.append(wrap(alpha_known - alpha_r))
        nx, ny = math.cos(wall.alpha), math.sin(wall.alpha)
        side = 1.0 if wall.d - x0 * nx - y0 * ny >= 0 else -1.0
        across = side * (d_known - d_r)  # how far the robot is along the wall's normal from reference
        if abs(ny) <= limit:
            dx.append(across / nx)
        elif abs(nx) <= limit:
            dy.append(across / ny)
    return {
        "x": x0 + sum(dx) / len(dx) if dx else x0,
        "y": y0 + sum(dy) / len(dy) if dy else y0,
        "psi": wrap(psi0 + sum(headings) / len(headings)),
        "valid": [bool(dx), bool(dy), True],
    }


def ray_crossing(
    origin: tuple[float, float], direction: float, wall: KnownWall
) -> tuple[float, float, float] | None:
    """Where a ray from ``origin`` along ``direction`` (rad) crosses ``wall``'s line: how far along
    the ray, where along the wall (0 at its first end, 1 at its second) and the sine of the angle
    between ray and wall; None if they are parallel."""
    dx, dy = math.cos(direction), math.sin(direction)
    ex, ey = wall.x2 - wall.x1, wall.y2 - wall.y1
    denominator = dx * ey - dy * ex
    if abs(denominator) < 1e-9:
        return None
    wx, wy = wall.x1 - origin[0], wall.y1 - origin[1]
    return (
        (wx * ey - wy * ex) / denominator,
        (wx * dy - wy * dx) / denominator,
        abs(denominator) / wall.length,
    )


@dataclass(frozen=True)
class BeamEcho:
    """Where a beam first meets one known wall: the nearest point of the wall inside the cone."""

    range_mm: float
    wall: KnownWall
    #: the perpendicular's angle off the beam's axis when the nearest point is the foot of the
    #: perpendicular (then the range is the distance to the wall's line); None at a cone's edge
    #: or a wall's end
    foot_off: float | None


def beam_echoes(
    origin: tuple[float, float], direction: float, half_width: float, walls: list[KnownWall]
) -> list[BeamEcho]:
    """Every known wall a sonar cone (apex ``origin``, axis ``direction``, ± ``half_width`` rad)
    meets, nearest first: the first echo comes from the nearest point of any wall in the cone,
    which is the foot of the perpendicular if that lies in the cone, else an end of the wall or
    a crossing of the cone's edge."""
    ox, oy = origin
    echoes = []
    for wall in walls:
        ex, ey = wall.x2 - wall.x1, wall.y2 - wall.y1
        length_sq = ex * ex + ey * ey
        if length_sq <= 0.0:
            continue
        candidates: list[tuple[float, float | None]] = []
        u = ((ox - wall.x1) * ex + (oy - wall.y1) * ey) / length_sq
        if 0.0 <= u <= 1.0:
            fx, fy = wall.x1 + u * ex - ox, wall.y1 + u * ey - oy
            off = wrap(math.atan2(fy, fx) - direction)
            if abs(off) <= half_width:
                candidates.append((math.hypot(fx, fy), off))
        for px, py in ((wall.x1, wall.y1), (wall.x2, wall.y2)):
            if abs(wrap(math.atan2(py - oy, px - ox) - direction)) <= half_width:
                candidates.append((math.hypot(px - ox, py - oy), None))
        for edge in (direction - half_width, direction + half_width):
            crossing = ray_crossing(origin, edge, wall)
            if crossing is not None and crossing[0] > 0.0 and 0.0 <= crossing[1] <= 1.0:
                candidates.append((crossing[0], None))
        if candidates:
            distance, off = min(candidates, key=lambda c: c[0])
            echoes.append(BeamEcho(distance, wall, off))
    echoes.sort(key=lambda e: e.range_mm)
    return echoes


# =============================================================================================
# the wall detector


@dataclass(frozen=True)
class SonarMount:
    """Where a sonar sits on the robot and where it looks (robot frame, mm and rad)."""

    x: float
    y: float
    angle: float


@dataclass(frozen=True)
class DetectorParams:
    """The seed's [WALLS] options (table B.1), in mm and degrees."""

    history: int = 60
    max_distance_mm: float = 1500.0
    side_sensors: tuple[int, ...] = ()
    pairs: tuple[tuple[int, int], ...] = ()
    min_points_side: int = 12
    min_span_side_mm: float = 150.0
    max_sigma_side_mm: float = 12.0
    min_points_pairs: int = 6
    max_sigma_d_pairs_mm: float = 15.0
    max_sigma_alpha_pairs_deg: float = 6.0
    noise_floor_mm: float = 5.0
    max_turn_deg: float = 0.5  # more rotation than this between two sonar samples: not driving past
    min_sigma_d_mm: float = 6.0  # the least uncertainty a fitted line may claim (beam, mounting)
    min_sigma_alpha_deg: float = 0.7
    #: tangent: a range is the perpendicular distance from the sensor to the wall (the nearest
    #: point in the beam echoes first); axis: the seed's point on the beam's axis
    range_model: str = "axis"
    max_beam_off_deg: float = 25.0  # tangent: a wall whose normal is farther off the beam axis is not used
    #: tangent: how late an echo reads (mm), taken off each range: beyond ``late_from_mm`` by
    #: ``late_mm_per_m``, and by ``late_mm_per_deg2`` times the square of the wall's angle off the
    #: beam axis (a weaker echo crosses the threshold later). Measured on recorded drives.
    late_from_mm: float = 700.0
    late_mm_per_m: float = 25.0
    late_mm_per_deg2: float = 0.055
    #: an error all points of one fit share (the late-echo model's residue, a wall not quite flat):
    #: it does not average out over the points, so it adds its variance to d and (2σ/span)² to α
    shared_sigma_mm: float = 0.0


class WallDetector:
    """Collects sonar readings in the odometry frame and fits wall lines (side regression, pairs).

    A reading is kept as the sensor's position, its beam direction and the range. With the
    tangent range model (``range_model: tangent``, as config/localization.yaml sets it) the range is the perpendicular distance from the sensor
    to the wall — a beam 30° wide meets a wall up to 25° off square at its nearest point first —
    so a line is fitted as the common tangent of the range circles: ``n·S + r = d``. The seed put
    each point on the beam's axis instead, which puts a wall met 20° off square 6 % too close
    (60 mm at 1 m) and turns it by the difference between sin and tan of its angle."""

    def __init__(self, mounts: list[SonarMount], params: DetectorParams) -> None:
        self.mounts = mounts
        self.params = params
        self.points: dict[int, deque[tuple[float, float, float, float]]] = {
            i: deque(maxlen=params.history) for i in params.side_sensors
        }
        self.pair_lines: dict[
            tuple[int, int], deque[tuple[float, float, tuple[float, float], tuple[float, float]]]
        ] = {pair: deque(maxlen=params.history) for pair in params.pairs}
        self.fitted = 0
        self.last_heading: float | None = None
        self.tangent = params.range_model == "tangent"
        self.max_off = math.radians(params.max_beam_off_deg)

    def point(self, index: int, distance: float, pose: tuple[float, float, float]) -> tuple[float, float]:
        """Where the reading lies on the beam's axis (odometry frame)."""
        mount = self.mounts[index]
        local = (mount.x + distance * math.cos(mount.angle), mount.y + distance * math.sin(mount.angle))
        return from_frame(local, pose)

    def reading(
        self, index: int, distance: float, pose: tuple[float, float, float]
    ) -> tuple[float, float, float, float]:
        """The sensor's position, its beam direction and the range (odometry frame)."""
        mount = self.mounts[index]
        sx, sy = from_frame((mount.x, mount.y), pose)
        if self.tangent:
            p = self.params
            distance -= range_lateness_mm(distance, p.late_from_mm, p.late_mm_per_m)
        return sx, sy, wrap(pose[2] + mount.angle), distance

    def late_off_axis(self, normal: float, beam: float) -> float:
        """How much later (mm) an echo from a wall whose normal is ``normal`` reads in ``beam``."""
        return off_axis_lateness_mm(wrap(normal - beam), self.params.late_mm_per_deg2)

    def add(self, stamp_ms: int, pose: tuple[float, float, float], distances: list[int | None]) -> None:
        """One sonar sample (distances in mm, None = no contact) taken at odometry-frame ``pose``."""
        limit = self.params.max_distance_mm
        turning = (
            self.last_heading is not None
            and abs(math.degrees(wrap(pose[2] - self.last_heading))) > self.params.max_turn_deg
        )
        self.last_heading = pose[2]
        if turning:  # a wall is fitted while driving past it, never while turning on the spot
            for readings in self.points.values():
                readings.clear()
            for lines in self.pair_lines.values():
                lines.clear()
            return
        usable: dict[int, float] = {
            i: float(d)
            for i, d in enumerate(distances)
            if d is not None and 0 < d <= limit and i < len(self.mounts)
        }
        for i, history in self.points.items():
            if i in usable:
                history.append(self.reading(i, usable[i], pose))
            else:
                history.clear()  # the wall ended (or never was): a fit must not bridge a gap
        for (i, j), lines in self.pair_lines.items():
            line = self._pair_line(i, j, usable, pose) if i in usable and j in usable else None
            if line is not None:
                lines.append(line)
            else:
                lines.clear()

    def _pair_line(
        self, i: int, j: int, usable: dict[int, float], pose: tuple[float, float, float]
    ) -> tuple[float, float, tuple[float, float], tuple[float, float]] | None:
        """One sample's line of a pair: (α, d, foot i, foot j); None if no wall fits the beams."""
        if not self.tangent:
            p, q = self.point(i, usable[i], pose), self.point(j, usable[j], pose)
            alpha, d = hessian(*p, *q)
            return alpha, d, p, q
        si, sj = self.reading(i, usable[i], pose), self.reading(j, usable[j], pose)
        n = _tangent_normal(si, sj)
        if n is None:
            return None
        if any(abs(wrap(n - s[2])) > self.max_off for s in (si, sj)):
            return None  # the wall's nearest point lies outside a beam: the range is not to it
        si, sj = ((s[0], s[1], s[2], s[3] - self.late_off_axis(n, s[2])) for s in (si, sj))
        n = _tangent_normal(si, sj)
        if n is None:
            return None
        alpha, d, feet = _tangent_line(n, [si, sj])
        return alpha, d, feet[0], feet[1]

    def detect(self, pose: tuple[float, float, float]) -> list[dict[str, Any]]:
        """Walls fitted from the points collected so far, in the frame of ``pose`` (odometry frame).

        A sensor's points are used once: after a wall is reported they are dropped, so the filter
        never sees the same points twice (repeated measurements would make it overconfident).
        """
        walls = []
        for i, history in self.points.items():
            wall = self._fit_side(list(history), pose)
            if wall is not None:
                wall["sensors"] = [i]
                walls.append(wall)
                history.clear()
        for pair, lines in self.pair_lines.items():
            wall = self._fit_pairs(list(lines), pose)
            if wall is not None:
                wall["sensors"] = list(pair)
                walls.append(wall)
                lines.clear()
        self.fitted += len(walls)
        return walls

    def _side_fit(self, readings: list[tuple[float, float, float, float]]) -> dict | None:
        if not self.tangent:
            return _orthogonal_fit([_on_axis(r) for r in readings])
        fit = _tangent_fit(readings)
        if fit is None or abs(wrap(fit["normal"] - readings[-1][2])) > self.max_off:
            return None
        late = [self.late_off_axis(fit["normal"], r[2]) for r in readings]
        return _tangent_fit([(*r[:3], r[3] - dl) for r, dl in zip(readings, late, strict=True)])

    def _fit_side(
        self, readings: list[tuple[float, float, float, float]], pose: tuple[float, float, float]
    ) -> dict | None:
        p = self.params
        n = p.min_points_side
        if len(readings) < n:
            return None
        best = None
        while n <= len(readings):
            fit = self._side_fit(readings[-n:])
            if fit is None or fit["sigma"] > p.max_sigma_side_mm:
                break
            if fit["span"] >= p.min_span_side_mm:
                best = fit
            n += 1
        if best is None:
            return None
        return _report("side", best, pose, max(best["sigma"], p.noise_floor_mm), p)

    def _fit_pairs(self, lines: list[tuple], pose: tuple[float, float, float]) -> dict | None:
        p = self.params
        n = p.min_points_pairs
        if len(lines) < n:
            return None
        best = None
        while n <= len(lines):
            recent = lines[-n:]
            ref = recent[-1][0]
            alphas = [ref + wrap(a - ref) for a, *_ in recent]
            ds = [d for _, d, *_ in recent]
            mean_a, mean_d = sum(alphas) / n, sum(ds) / n
            sd_a = math.sqrt(sum((a - mean_a) ** 2 for a in alphas) / (n - 1))
            sd_d = math.sqrt(sum((d - mean_d) ** 2 for d in ds) / (n - 1))
            if sd_d > p.max_sigma_d_pairs_mm or math.degrees(sd_a) > p.max_sigma_alpha_pairs_deg:
                break
            points = [pt for *_, a, b in recent for pt in (a, b)]
            best = {"alpha": wrap(mean_a), "d": mean_d, "sd_a": sd_a, "sd_d": sd_d, "n": n, "points": points}
            n += 1
        if best is None:
            return None
        alpha, d = line_in_frame(best["alpha"], best["d"], pose)
        var_a = max(best["sd_a"] ** 2 / best["n"], math.radians(p.min_sigma_alpha_deg) ** 2)
        var_d = max(max(best["sd_d"], p.noise_floor_mm) ** 2 / best["n"], p.min_sigma_d_mm**2)
        p1, p2 = _extent(best["points"], best["alpha"], best["d"], pose)
        var_a, var_d = _shared(var_a, var_d, math.dist(p1, p2), p)
        return {
            "kind": "pair",
            "alpha": alpha,
            "d": d,
            "cov": [var_a, 0.0, var_d],
            "n": best["n"],
            "p1": p1,
            "p2": p2,
        }


def _on_axis(reading: tuple[float, float, float, float]) -> tuple[float, float]:
    """The seed's point of a reading: on the beam's axis at the range."""
    sx, sy, beam, r = reading
    return sx + r * math.cos(beam), sy + r * math.sin(beam)


def _tangent_normal(
    a: tuple[float, float, float, float], b: tuple[float, float, float, float]
) -> float | None:
    """The direction of the wall normal (rad, from the sensors to the wall) tangent to the range
    circles of two readings, on the side their beams look; None if the ranges cannot both hold."""
    dx, dy = a[0] - b[0], a[1] - b[1]
    baseline = math.hypot(dx, dy)
    if baseline < 1e-6:
        return None
    c = (b[3] - a[3]) / baseline  # n·(Sa − Sb) = rb − ra
    if abs(c) >= 1.0:
        return None
    along = math.atan2(dy, dx)
    off = math.acos(c)
    candidates = (wrap(along + off), wrap(along - off))
    return min(candidates, key=lambda n: abs(wrap(n - a[2])))


def _tangent_line(
    normal: float, readings: list[tuple[float, float, float, float]]
) -> tuple[float, float, list[tuple[float, float]]]:
    """Hessian form (α, d ≥ 0) of the line with ``normal`` tangent to the readings' range circles
    (least squares in d) and the feet of the readings on it."""
    nx, ny = math.cos(normal), math.sin(normal)
    d = sum(nx * sx + ny * sy + r for sx, sy, _, r in readings) / len(readings)
    feet = []
    for sx, sy, _, _ in readings:
        gap = d - (nx * sx + ny * sy)
        feet.append((sx + gap * nx, sy + gap * ny))
    alpha = normal
    if d < 0:
        alpha, d = normal + math.pi, -d
    return wrap(alpha), d, feet


def _tangent_fit(readings: list[tuple[float, float, float, float]]) -> dict | None:
    """The line tangent to the range circles of one sensor's readings (``n·S_i + r_i = d`` in
    least squares, Gauss-Newton on the normal's angle from the beam's direction): Hessian form,
    residual std, span, centroid — what :func:`_report` needs, like :func:`_orthogonal_fit`."""
    n = len(readings)
    sx = np.array([r[0] for r in readings])
    sy = np.array([r[1] for r in readings])
    rr = np.array([r[3] for r in readings])
    normal = readings[-1][2]
    cx, cy, cr = float(sx.mean()), float(sy.mean()), float(rr.mean())
    for _ in range(8):
        c, s = math.cos(normal), math.sin(normal)
        e = c * (sx - cx) + s * (sy - cy) + (rr - cr)
        g = -s * (sx - cx) + c * (sy - cy)
        gg = float(g @ g)
        if gg <= 1e-9:
            return None
        step = -float(e @ g) / gg
        normal = wrap(normal + step)
        if abs(step) < 1e-9:
            break
    c, s = math.cos(normal), math.sin(normal)
    e = c * (sx - cx) + s * (sy - cy) + (rr - cr)
    t = -s * sx + c * sy  # along the line
    span = float(np.ptp(t))
    if span <= 0:
        return None
    alpha, d, feet = _tangent_line(normal, list(readings))
    fx = sum(p[0] for p in feet) / n
    fy = sum(p[1] for p in feet) / n
    return {
        "alpha": alpha,
        "d": d,
        "normal": normal,
        "sigma": math.sqrt(float(e @ e) / max(n - 2, 1)),
        "span": span,
        "n": n,
        "centroid": (fx, fy),
        "stt": float(((t - t.mean()) ** 2).sum()),
        "points": feet,
    }


def _orthogonal_fit(points: list[tuple[float, float]]) -> dict | None:
    """Total least squares line through points: Hessian form, residual std, span, centroid."""
    n = len(points)
    cx = sum(x for x, _ in points) / n
    cy = sum(y for _, y in points) / n
    sxx = sum((x - cx) ** 2 for x, _ in points)
    syy = sum((y - cy) ** 2 for _, y in points)
    sxy = sum((x - cx) * (y - cy) for x, y in points)
    direction = 0.5 * math.atan2(2 * sxy, sxx - syy)  # of the largest spread
    ux, uy = math.cos(direction), math.sin(direction)
    ts = [(x - cx) * ux + (y - cy) * uy for x, y in points]
    residuals = [-(x - cx) * uy + (y - cy) * ux for x, y in points]
    span = max(ts) - min(ts)
    if span <= 0:
        return None
    sigma = math.sqrt(sum(r * r for r in residuals) / max(n - 2, 1))
    alpha = direction + math.pi / 2
    d = cx * math.cos(alpha) + cy * math.sin(alpha)
    if d < 0:
        alpha, d = alpha + math.pi, -d
    return {
        "alpha": wrap(alpha),
        "d": d,
        "sigma": sigma,
        "span": span,
        "n": n,
        "centroid": (cx, cy),
        "stt": sum(t * t for t in ts),
        "points": points,
    }


def _shared(var_a: float, var_d: float, span: float, p: DetectorParams) -> tuple[float, float]:
    """A fit's variances of α and d with the error its points share (``shared_sigma_mm``) added:
    it tilts a line by up to twice itself over the span, and shifts it by itself."""
    shared = p.shared_sigma_mm
    return var_a + (2.0 * shared / max(span, 1.0)) ** 2, var_d + shared**2


def _report(
    kind: str, fit: dict, pose: tuple[float, float, float], sigma: float, p: DetectorParams
) -> dict[str, Any]:
    """A fitted line in the frame of ``pose`` with its covariance (var α, cov αd, var d)."""
    alpha, d = line_in_frame(fit["alpha"], fit["d"], pose)
    cx, cy = to_frame(fit["centroid"], pose)
    var_a = max(sigma**2 / fit["stt"], math.radians(p.min_sigma_alpha_deg) ** 2)
    var_d = max(sigma**2 / fit["n"], p.min_sigma_d_mm**2)
    var_a, var_d = _shared(var_a, var_d, fit["span"], p)
    tangential = -math.sin(alpha) * cx + math.cos(alpha) * cy  # the centroid's position along the line
    cov = [var_a, var_a * tangential, var_a * tangential**2 + var_d]
    p1, p2 = _extent(fit["points"], fit["alpha"], fit["d"], pose)
    return {"kind": kind, "alpha": alpha, "d": d, "cov": cov, "n": fit["n"], "p1": p1, "p2": p2}


def _extent(points: list, alpha: float, d: float, pose: tuple[float, float, float]) -> tuple[list, list]:
    """The two extreme points projected onto the line, in the frame of ``pose``."""
    ux, uy = -math.sin(alpha), math.cos(alpha)
    ts = [x * ux + y * uy for x, y in points]
    foot = (d * math.cos(alpha), d * math.sin(alpha))
    ends = []
    for t in (min(ts), max(ts)):
        ends.append(list(to_frame((foot[0] + t * ux, foot[1] + t * uy), pose)))
    return ends[0], ends[1]


# =============================================================================================
# the travel gauge: the true length of straight moves from the front and rear sonar


@dataclass(frozen=True)
class GaugeParams:
    """Which sonars look along the track and what a usable range series is (mm)."""

    sensors: tuple[int, ...] = (1, 5)  # front and rear (modules/description/robot.py)
    min_range_mm: float = 150.0
    max_range_mm: float = 800.0  # farther, the first echo comes late (+6 mm at 1 m): a slope bias
    min_points: int = 12
    min_span_mm: float = 250.0  # nominal travel the points must span
    max_sigma_mm: float = 15.0  # residual scatter of a plane ahead or behind (a post: larger)
    outlier_mm: float = 30.0
    min_sigma_scale: float = 0.002  # the least uncertainty a measured scale may claim
    #: how late an echo reads beyond ``late_from_mm`` (mm per m, :class:`DetectorParams`): taken
    #: off each range, else the range falls 2.5 % faster than the robot drives out there
    late_from_mm: float = 700.0
    late_mm_per_m: float = 0.0


class TravelGauge:
    """The step scale of straight drives, measured by the sonars looking ahead and behind.

    While the robot drives straight (its odometry-frame heading unchanged), the front sonar's
    range to a wall ahead falls, and the rear's to a wall behind grows, by the *true* distance
    travelled times cos φ (φ: the beam's angle to the wall's normal; the sonar returns the
    nearest point in its beam). Against the nominal distance of the step counters the slope of
    a line through (nominal travel, range) is the step scale — what own-map wall corrections
    cannot see, as the map was drawn with the same scale. A run ends when the heading changes;
    its fits come back from :meth:`add` as ``{"sensor", "scale", "sigma", "range_mm", ...}``.
    """

    def __init__(self, mounts: list[SonarMount], params: GaugeParams | None = None) -> None:
        self.mounts = mounts
        self.params = params or GaugeParams()
        self.origin: tuple[float, float, float] | None = None
        self.end: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the run's last pose
        self.points: dict[int, list[tuple[float, float, bool]]] = {i: [] for i in self.params.sensors}
        self.measured = 0

    def add(self, pose: tuple[float, float, float], distances: list[int | None]) -> list[dict[str, Any]]:
        """One sweep at its odometry-frame ``pose``; returns the fits of a run that just ended."""
        done: list[dict[str, Any]] = []
        if self.origin is not None and abs(wrap(pose[2] - self.origin[2])) > 1e-6:
            done = self.finish()
        if self.origin is None:
            self.origin = pose
        moving = pose != self.end
        self.end = pose
        ox, oy, heading = self.origin
        travel = (pose[0] - ox) * math.cos(heading) + (pose[1] - oy) * math.sin(heading)
        p = self.params
        for i in p.sensors:
            if i < len(distances):
                r = distances[i]
                if r is not None and p.min_range_mm <= r <= p.max_range_mm:
                    late = range_lateness_mm(r, p.late_from_mm, p.late_mm_per_m)
                    self.points[i].append((travel, float(r) - late, moving))
        return done

    def finish(self) -> list[dict[str, Any]]:
        """End the current run (a turn began): the fits of its range series."""
        out = []
        for i, pts in self.points.items():
            fit = self._fit(i, pts)
            if fit is not None:
                out.append(fit)
        self.origin = None
        self.points = {i: [] for i in self.params.sensors}
        self.measured += len(out)
        return out

    def _travel_at_end(self) -> float:
        """The nominal travel of the run's last pose along its heading."""
        if self.origin is None:
            return 0.0
        ox, oy, heading = self.origin
        return (self.end[0] - ox) * math.cos(heading) + (self.end[1] - oy) * math.sin(heading)

    def _fit(self, sensor: int, pts: list[tuple[float, float, bool]]) -> dict[str, Any] | None:
        p = self.params
        if len(pts) < p.min_points:
            return None
        u = np.array([t for t, _, _ in pts])
        r = np.array([d for _, d, _ in pts])
        # sweeps on the move get an offset of their own: should the sonar's and the step
        # counters' stamps disagree by a little, moving points all shift alike along the line,
        # and the ones at rest (on it) would tilt the fit (the ring: 10 mm at 100 mm/s, 2 %)
        moving = np.array([m for _, _, m in pts], dtype=float)
        design = np.column_stack([u, np.ones(len(u)), moving])
        keep = np.ones(len(u), dtype=bool)
        for _ in range(3):  # a robust line: drop points far off, fit again
            if keep.sum() < p.min_points or np.ptp(u[keep]) < p.min_span_mm:
                return None
            columns = 3 if 0 < moving[keep].sum() < keep.sum() else 2
            a = design[keep][:, :columns]
            coefficients, *_ = np.linalg.lstsq(a, r[keep], rcond=None)
            slope, intercept = float(coefficients[0]), float(coefficients[1])
            offset = float(coefficients[2]) if columns == 3 else 0.0
            residual = r - (slope * u + intercept + offset * moving)
            new = np.abs(residual) <= max(p.outlier_mm, 3.0 * float(np.std(residual[keep])))
            if (new == keep).all():
                break
            keep = new
        n = int(keep.sum())
        if n < p.min_points or n < 0.7 * len(u) or np.ptp(u[keep]) < p.min_span_mm:
            return None
        sigma = float(np.std(residual[keep], ddof=columns)) if n > columns else float("inf")
        if sigma > p.max_sigma_mm:
            return None
        # the slope's variance: u's spread left after the other columns are fitted
        a = design[keep][:, :columns]
        spread = 1.0 / float(np.linalg.inv(a.T @ a)[0, 0])
        # the front range falls as the robot drives on, the rear one grows
        ahead = math.cos(self.mounts[sensor].angle) > 0
        scale = -slope if ahead else slope
        return {
            "sensor": sensor,
            "scale": float(scale),
            "sigma": max(math.sqrt(max(sigma, 5.0) ** 2 / spread), p.min_sigma_scale),
            "n": n,
            "span_mm": float(np.ptp(u[keep])),
            "range_mm": float(np.mean(r[keep])),
            # where the run ended — past the last point in range (a rear sonar's wall drops out of
            # range long before a run ends): the pose there is the one the beam is checked from
            "range_end_mm": float(slope * self._travel_at_end() + intercept + offset * moving[-1]),
            "end_pose": list(self.end),
            # how far (nominal) the run went on past its points' middle: where the ranges were read
            "back_mm": float(self._travel_at_end() - np.mean(u[keep])),
            "residual_mm": sigma,
        }
