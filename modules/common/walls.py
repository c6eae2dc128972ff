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

from tokenring.errors import UsageError

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


def load_known_walls(name_or_path: str | Path) -> list[KnownWall]:
    """The known walls of a room: a bundled world name, a YAML world file or the seed's wall file.

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
    return walls


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


class WallDetector:
    """Collects sonar points in the odometry frame and fits wall lines (side regression, pairs)."""

    def __init__(self, mounts: list[SonarMount], params: DetectorParams) -> None:
        self.mounts = mounts
        self.params = params
        self.points: dict[int, deque[tuple[float, float]]] = {
            i: deque(maxlen=params.history) for i in params.side_sensors
        }
        self.pair_lines: dict[
            tuple[int, int], deque[tuple[float, float, tuple[float, float], tuple[float, float]]]
        ] = {pair: deque(maxlen=params.history) for pair in params.pairs}
        self.fitted = 0
        self.last_heading: float | None = None

    def point(self, index: int, distance: float, pose: tuple[float, float, float]) -> tuple[float, float]:
        mount = self.mounts[index]
        local = (mount.x + distance * math.cos(mount.angle), mount.y + distance * math.sin(mount.angle))
        return from_frame(local, pose)

    def add(self, stamp_ms: int, pose: tuple[float, float, float], distances: list[int | None]) -> None:
        """One sonar sample (distances in mm, None = no contact) taken at odometry-frame ``pose``."""
        limit = self.params.max_distance_mm
        turning = (
            self.last_heading is not None
            and abs(math.degrees(wrap(pose[2] - self.last_heading))) > self.params.max_turn_deg
        )
        self.last_heading = pose[2]
        if turning:  # a wall is fitted while driving past it, never while turning on the spot
            for history in (*self.points.values(), *self.pair_lines.values()):
                history.clear()
            return
        usable = {
            i: d for i, d in enumerate(distances) if d is not None and 0 < d <= limit and i < len(self.mounts)
        }
        for i, history in self.points.items():
            if i in usable:
                history.append(self.point(i, usable[i], pose))
            else:
                history.clear()  # the wall ended (or never was): a fit must not bridge a gap
        for (i, j), history in self.pair_lines.items():
            if i in usable and j in usable:
                p, q = self.point(i, usable[i], pose), self.point(j, usable[j], pose)
                alpha, d = hessian(*p, *q)
                history.append((alpha, d, p, q))
            else:
                history.clear()

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
        for pair, history in self.pair_lines.items():
            wall = self._fit_pairs(list(history), pose)
            if wall is not None:
                wall["sensors"] = list(pair)
                walls.append(wall)
                history.clear()
        self.fitted += len(walls)
        return walls

    def _fit_side(self, points: list[tuple[float, float]], pose: tuple[float, float, float]) -> dict | None:
        p = self.params
        n = p.min_points_side
        if len(points) < n:
            return None
        best = None
        while n <= len(points):
            fit = _orthogonal_fit(points[-n:])
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
        return {
            "kind": "pair",
            "alpha": alpha,
            "d": d,
            "cov": [var_a, 0.0, var_d],
            "n": best["n"],
            "p1": p1,
            "p2": p2,
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


def _report(
    kind: str, fit: dict, pose: tuple[float, float, float], sigma: float, p: DetectorParams
) -> dict[str, Any]:
    """A fitted line in the frame of ``pose`` with its covariance (var α, cov αd, var d)."""
    alpha, d = line_in_frame(fit["alpha"], fit["d"], pose)
    cx, cy = to_frame(fit["centroid"], pose)
    var_a = max(sigma**2 / fit["stt"], math.radians(p.min_sigma_alpha_deg) ** 2)
    tangential = -math.sin(alpha) * cx + math.cos(alpha) * cy  # the centroid's position along the line
    var_d = max(sigma**2 / fit["n"], p.min_sigma_d_mm**2)
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
                    self.points[i].append((travel, float(r), moving))
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
            "range_end_mm": float(slope * u[-1] + intercept + offset * moving[-1]),  # where the run ended
            "end_pose": list(self.end),
            "residual_mm": sigma,
        }
