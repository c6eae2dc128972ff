"""Vector generation from the side sonars (seed §4.3.4), the seed's edge following and ours.

Internal convention: millimetres, radians, counter-clockwise, robot frame x forward / y left.

* :func:`observe_side` — the seed's side hypothesis from the two side sensors' behaviours:
  both LINEAR → WALL; one DEGRESSIVE and one LINEAR → CORNER; one PROGRESSIVE and one LINEAR →
  OBSTACLE; otherwise NONE. The confidence counts up (to 100) while the hypothesis stays; the
  distance area is the nearer of the two.
* :class:`SeedEdgeFollower` — the seed's vector generation: when WALL begins the **rear**
  sensor's reading and the current pose give the start point; when it ends the **front**
  sensor's last reading gives the end point. Nothing merges or closes its vectors. A vector
  also ends when vector generation stops (no forward move, scan off): the seed's copro only
  clears a flag there, but its pilot stops the scan after every forward command and its maps
  show the walls followed up to each turn, so a vector never spans a turn.
* :class:`WallTracker` — ours: every valid side reading becomes a global point (pose
  interpolated at the sweep's time stamp); points are grouped into straight runs by their
  distance to a robust line fit, and a run becomes one least-squares vector whose ends are the
  extreme inlier points projected onto the line. It does not depend on the behaviour classifier.
* :class:`VectorPostProcessor` — ours: holds the newest vector back per side, merges collinear
  pieces into it and closes the corner between consecutive walls at their lines' intersection.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from modules.description.robot import SONAR_MOUNTS, SonarMount
from tokenring import default_protocol

_ENUMS = default_protocol().enums
LINEAR = _ENUMS["behaviour"]["LINEAR"]
PROGRESSIVE = _ENUMS["behaviour"]["PROGRESSIVE"]
DEGRESSIVE = _ENUMS["behaviour"]["DEGRESSIVE"]
WALL = _ENUMS["contact"]["WALL"]
OBSTACLE = _ENUMS["contact"]["OBSTACLE"]
CORNER = _ENUMS["contact"]["CORNER"]
NONE = _ENUMS["contact"]["NONE"]
NO_CONTACT_AREA = _ENUMS["distance_area"]["NO_CONTACT"]
NO_CONTACT_CM = 255

Pose = tuple[float, float, float]  # x mm, y mm, heading rad (CCW, 0 along +X)
Point = tuple[float, float]
Vector = tuple[float, float, float, float]  # x1, y1, x2, y2 in mm


# ---------------------------------------------------------------------------------------------
# the hypothesis


@dataclass
class SideHypothesis:
    """What copro publishes per side: contact type, confidence 0..100, distance area."""

    contact: int = NONE
    confidence: int = 0
    area: int = NO_CONTACT_AREA


def classify_side(front_behaviour: int, rear_behaviour: int) -> int:
    """The seed's truth table for one side's pair of behaviours."""
    pair = {front_behaviour, rear_behaviour}
    if front_behaviour == LINEAR and rear_behaviour == LINEAR:
        return WALL
    if pair == {DEGRESSIVE, LINEAR}:
        return CORNER
    if pair == {PROGRESSIVE, LINEAR}:
        return OBSTACLE
    return NONE


def observe_side(
    front_behaviour: int, rear_behaviour: int, front_area: int, rear_area: int, previous: SideHypothesis
) -> SideHypothesis:
    """One observation of a side; the confidence grows while the hypothesis is unchanged."""
    contact = classify_side(front_behaviour, rear_behaviour)
    confidence = min(100, previous.confidence + 1) if contact == previous.contact else 1
    return SideHypothesis(contact, confidence, min(front_area, rear_area))


# ---------------------------------------------------------------------------------------------
# geometry


@dataclass(frozen=True)
class SideSensors:
    """Where one side's two sonars sit on the robot (robot frame, mm) and where they look (rad)."""

    front_xy: Point
    rear_xy: Point
    direction: float  # +pi/2 for the left side, -pi/2 for the right

    def point(self, pose: Pose, which: str, distance_mm: float) -> Point:
        """The global point a reading of ``distance_mm`` from the front or rear sensor marks."""
        sx, sy = self.front_xy if which == "front" else self.rear_xy
        lx = sx + distance_mm * math.cos(self.direction)
        ly = sy + distance_mm * math.sin(self.direction)
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        return (x + c * lx - s * ly, y + s * lx + c * ly)


@dataclass(frozen=True)
class SonarLayout:
    """Which of the eight sonars is which, and the side pairs' mounting (robot frame)."""

    front: tuple[int, ...]
    rear: tuple[int, ...]
    left_front: int
    left_rear: int
    right_front: int
    right_rear: int
    left: SideSensors
    right: SideSensors
    max_range_mm: float = 1500.0
    #: every pair's mounting (modules/description/robot.py's, of the ring's body)
    mounts: tuple[SonarMount, ...] = SONAR_MOUNTS

    def side(self, name: str) -> tuple[int, int, SideSensors]:
        if name == "left":
            return self.left_front, self.left_rear, self.left
        return self.right_front, self.right_rear, self.right


def default_layout(body: str = "ours") -> SonarLayout:
    """The robot's eight sonars as :mod:`modules.description.robot` mounts them on ``body``."""
    from modules.description import robot

    mounts = robot.sonar_mounts(body)

    def side(front: int, rear: int) -> SideSensors:
        f, r = mounts[front], mounts[rear]
        return SideSensors((f.x, f.y), (r.x, r.y), f.angle)

    return SonarLayout(
        front=(robot.FRONT_LEFT, robot.FRONT, robot.FRONT_RIGHT),
        rear=(robot.REAR,),
        left_front=robot.LEFT_FRONT,
        left_rear=robot.LEFT_REAR,
        right_front=robot.RIGHT_FRONT,
        right_rear=robot.RIGHT_REAR,
        left=side(robot.LEFT_FRONT, robot.LEFT_REAR),
        right=side(robot.RIGHT_FRONT, robot.RIGHT_REAR),
        max_range_mm=robot.SONAR_RANGE_MM,
        mounts=mounts,
    )


def fit_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Total least squares: (centroid, unit direction) of the best line through ``points``."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    return centroid, vt[0]


def line_residuals(points: np.ndarray, centroid: np.ndarray, direction: np.ndarray) -> np.ndarray:
    normal = np.array([-direction[1], direction[0]])
    return np.abs((points - centroid) @ normal)


def segment_from_points(points: np.ndarray, reference: Point | None = None) -> Vector:
    """The vector spanning ``points`` along their fitted line (oriented from ``reference`` on)."""
    centroid, direction = fit_line(points)
    t = (points - centroid) @ direction
    if reference is not None and float((np.asarray(reference) - centroid) @ direction) > 0:
        direction, t = -direction, -t
    a = centroid + direction * t.min()
    b = centroid + direction * t.max()
    return (float(a[0]), float(a[1]), float(b[0]), float(b[1]))


def vector_length(v: Vector) -> float:
    return math.hypot(v[2] - v[0], v[3] - v[1])


# ---------------------------------------------------------------------------------------------
# the seed's edge following


@dataclass
class SweepInput:
    """One sonar sweep as a side's vector generator sees it."""

    stamp_ms: int
    pose: Pose
    front_cm: int
    rear_cm: int
    contact: int  # this side's hypothesis after observe_side
    active: bool  # forward move, scanning on, more than 1 cm driven


class SeedEdgeFollower:
    """The seed's method for one side (seed §4.3.4): start at WALL's onset (rear), end at its
    end (front).

    "Ist nun das Verhalten beider Sensoren linear, so definiert der Meßwert des hinteren Sensors
    die Anfangsposition eines Vektors. Bei Änderung in nichtlineares Verhalten gibt der Meßwert
    des vorderen Sensors den Endpunkt an": the end is the front reading (and pose) of the last
    WALL sweep, the end of the steady run of readings; the reading that broke it lies past the
    wall. Each point is the sensor's mount plus its reading along the beam's axis, placed with
    the pose it is given (copro's seed mode: dead reckoning, seed §4.3.4)."""

    def __init__(self, sensors: SideSensors, emit: Callable[[Vector], None]) -> None:
        self.sensors = sensors
        self.emit = emit
        self.start: Point | None = None
        self.last_front: tuple[Pose, int] | None = None
        self.was_wall = False

    def feed(self, sweep: SweepInput) -> None:
        if not sweep.active:
            self._close()
            self.was_wall = False
            return
        wall = sweep.contact == WALL
        if wall and not self.was_wall and sweep.rear_cm != NO_CONTACT_CM:
            self.start = self.sensors.point(sweep.pose, "rear", sweep.rear_cm * 10.0)
        if not wall and self.was_wall:
            self._close()
        if wall and sweep.front_cm != NO_CONTACT_CM:
            self.last_front = (sweep.pose, sweep.front_cm)
        self.was_wall = wall

    def _close(self) -> None:
        if self.start is not None and self.last_front is not None:
            pose, cm = self.last_front
            end = self.sensors.point(pose, "front", cm * 10.0)
            vector = (*self.start, *end)
            if vector_length(vector) >= 10.0:  # under the wire's 1 cm it is no vector
                self.emit(vector)
        self.start = None
        self.last_front = None


# ---------------------------------------------------------------------------------------------
# ours: robust straight runs of global points


@dataclass
class TrackerSettings:
    max_range_mm: float = 1000.0  # readings further away are too coarse (beam 30°) to map walls
    tolerance_mm: float = 35.0  # a point this far off the run's line does not belong to it
    gap_mm: float = 200.0  # a run may not jump along its line by more than this
    split_after: int = 3  # consecutive misfits that end a run
    min_points: int = 6
    min_length_mm: float = 100.0  # the seed's minimum object size
    #: how far past a wall's free end the beam still reads it, per mm of range: its echo from the
    #: edge stays strong out to about 14° off the axis (the world's beam: 80 mm at 30 cm, 140 at 60)
    edge_reach: float = 0.25


@dataclass
class _Run:
    points: list[Point] = field(default_factory=list)
    ranges: list[float] = field(default_factory=list)
    misfits: list[tuple[Point, float]] = field(default_factory=list)  # (point, range mm)
    line: tuple[np.ndarray, np.ndarray] | None = None
    start_free: bool = False  # the wall came into view (rather than the scan starting beside it)
    empty_since_fit: int = 0  # sweeps without any reading since the last point joined


class WallTracker:
    """Ours for one side: groups global side-sonar points into straight runs → vectors.

    A run outlasts the stops between moves while its wall goes on (its points are global). Its
    end is *free* when the wall went out of view there (the readings vanished or jumped beyond
    it) and *held* when vector generation ended beside it or a nearer wall took over. At a free
    end the beam kept reading the wall's edge for ``edge_reach`` × range past it, each point
    placed on the beam's axis: the vector is shortened by that much there."""

    def __init__(
        self, sensors: SideSensors, emit: Callable[[Vector], None], settings: TrackerSettings | None = None
    ) -> None:
        self.sensors = sensors
        self.emit = emit
        self.settings = settings or TrackerSettings()
        self.run = _Run()
        self.robot_xy: Point | None = None
        self.heading: float | None = None  # at the last sweep of vector generation
        self.empty_sweeps = 0  # consecutive sweeps without a usable reading on this side

    def feed(self, sweep: SweepInput) -> None:
        if not sweep.active:  # a stop between two moves: the run goes on if its wall does
            return
        if self.heading is None or abs(math.remainder(sweep.pose[2] - self.heading, 2 * math.pi)) > 0.35:
            self.empty_sweeps = 0  # looking elsewhere now: what was (not) seen before does not count
        self.heading = sweep.pose[2]
        self.robot_xy = sweep.pose[:2]
        usable = False
        for which, cm in (("rear", sweep.rear_cm), ("front", sweep.front_cm)):
            if cm == NO_CONTACT_CM or cm * 10.0 > self.settings.max_range_mm:
                continue
            usable = True
            self._add(self.sensors.point(sweep.pose, which, cm * 10.0), cm * 10.0)
        self.empty_sweeps = 0 if usable else self.empty_sweeps + 1
        if not usable and self.run.points:
            self.run.empty_since_fit += 1

    def finish(self) -> None:
        """The end of vector generation (FLUSH): the open run becomes a vector."""
        self._close(free_end=self.run.empty_since_fit >= 2)

    def _fits(self, p: Point) -> bool:
        run, s = self.run, self.settings
        if not run.points:
            return True
        if run.line is None:
            return math.dist(p, run.points[-1]) <= s.gap_mm
        centroid, direction = run.line
        q = np.asarray(p) - centroid
        normal = np.array([-direction[1], direction[0]])
        if abs(float(q @ normal)) > s.tolerance_mm:
            return False
        t = float(q @ direction)
        along = (np.asarray(run.points) - centroid) @ direction
        return float(along.min()) - s.gap_mm <= t <= float(along.max()) + s.gap_mm

    def _add(self, p: Point, range_mm: float, start_free: bool | None = None) -> None:
        run, s = self.run, self.settings
        if self._fits(p):
            if not run.points:
                # a wall coming into view (after sweeps without readings) has a free start
                run.start_free = self.empty_sweeps >= 1 if start_free is None else start_free
            run.points.append(p)
            run.ranges.append(range_mm)
            run.misfits = []  # isolated misfits were noise
            run.empty_since_fit = 0
            if len(run.points) >= 3:
                pts = np.asarray(run.points)
                centroid, direction = fit_line(pts)
                spread = float(np.ptp((pts - centroid) @ direction))
                run.line = (centroid, direction) if spread >= 30.0 else None
            return
        run.misfits.append((p, range_mm))
        if len(run.misfits) >= s.split_after:
            misfits = run.misfits
            run.misfits = []
            beyond = self._beyond(run, [q for q, _ in misfits])
            real = self._close(free_end=run.empty_since_fit >= 2 or beyond)
            # the next wall came into view: from nothing (the run was noise) or in front of this one
            for q, r in misfits:
                self._add(q, r, start_free=not real or not beyond)

    def _beyond(self, run: _Run, misfits: list[Point]) -> bool:
        """The misfits lie beyond the run's line as seen from the robot: its wall ended there."""
        if run.line is None or self.robot_xy is None:
            return False
        centroid, direction = run.line
        normal = np.array([-direction[1], direction[0]])
        robot_side = float((np.asarray(self.robot_xy) - centroid) @ normal)
        offsets = (np.asarray(misfits) - centroid) @ normal
        return bool(float(np.mean(offsets)) * robot_side < 0)

    def _close(self, free_end: bool = False) -> bool:
        """The run as a vector (if it makes one); False if it was too short to count as a wall."""
        run, s = self.run, self.settings
        self.run = _Run()
        if len(run.points) < s.min_points:
            return False
        pts = np.asarray(run.points)
        ranges = np.asarray(run.ranges)
        centroid, direction = fit_line(pts)
        keep = line_residuals(pts, centroid, direction) <= s.tolerance_mm / 2
        if keep.sum() >= s.min_points:
            pts, ranges = pts[keep], ranges[keep]
        vector = segment_from_points(pts, reference=run.points[0])
        reach = s.edge_reach * float(np.median(ranges))
        vector = trim_vector(vector, reach if run.start_free else 0.0, reach if free_end else 0.0)
        if vector_length(vector) >= s.min_length_mm:
            self.emit(vector)
        return True


def trim_vector(v: Vector, start_mm: float, end_mm: float) -> Vector:
    """``v`` shortened by ``start_mm`` at its start and ``end_mm`` at its end (never below a
    quarter of its length)."""
    length = vector_length(v)
    if length <= 0.0 or start_mm + end_mm <= 0.0:
        return v
    scale = min(1.0, 0.75 * length / (start_mm + end_mm))
    a, b = start_mm * scale / length, end_mm * scale / length
    dx, dy = v[2] - v[0], v[3] - v[1]
    return (v[0] + a * dx, v[1] + a * dy, v[2] - b * dx, v[3] - b * dy)


# ---------------------------------------------------------------------------------------------
# ours: collinear merge and corner closing


def _angle_between(a: Vector, b: Vector) -> float:
    """Unsigned angle between two vectors' lines, 0..pi/2."""
    ta = math.atan2(a[3] - a[1], a[2] - a[0])
    tb = math.atan2(b[3] - b[1], b[2] - b[0])
    d = abs((ta - tb + math.pi / 2) % math.pi - math.pi / 2)
    return d


def _point_line_distance(p: Point, v: Vector) -> float:
    dx, dy = v[2] - v[0], v[3] - v[1]
    length = math.hypot(dx, dy) or 1.0
    return abs((p[0] - v[0]) * dy - (p[1] - v[1]) * dx) / length


def line_intersection(a: Vector, b: Vector) -> Point | None:
    """Where the infinite lines through ``a`` and ``b`` cross (None if parallel)."""
    x1, y1, x2, y2 = a
    x3, y3, x4, y4 = b
    den = (x1 - x2) * (y3 - y4) - (y1 - y2) * (x3 - x4)
    if abs(den) < 1e-9:
        return None
    t = ((x1 - x3) * (y3 - y4) - (y1 - y3) * (x3 - x4)) / den
    return (x1 + t * (x2 - x1), y1 + t * (y2 - y1))


@dataclass
class PostSettings:
    merge_angle_rad: float = math.radians(6.0)
    merge_offset_mm: float = 50.0
    merge_gap_mm: float = 400.0
    corner_min_angle_rad: float = math.radians(30.0)
    corner_reach_mm: float = 600.0


class VectorPostProcessor:
    """Holds back the newest vector of a side to merge collinear pieces and close corners."""

    def __init__(self, send: Callable[[Vector], None], settings: PostSettings | None = None) -> None:
        self.send = send
        self.settings = settings or PostSettings()
        self.pending: Vector | None = None
        self.corners_closed = 0
        self.merged = 0

    def add(self, v: Vector) -> None:
        p, s = self.pending, self.settings
        if p is None:
            self.pending = v
            return
        if self._collinear(p, v):
            self.pending = self._merge(p, v)
            self.merged += 1
            return
        if _angle_between(p, v) >= s.corner_min_angle_rad:
            corner = line_intersection(p, v)
            if (
                corner is not None
                and math.dist(corner, p[2:]) <= s.corner_reach_mm
                and math.dist(corner, v[:2]) <= s.corner_reach_mm
                and self._extends_end(p, corner)
                and self._extends_start(v, corner)
            ):
                p = (p[0], p[1], *corner)
                v = (*corner, v[2], v[3])
                self.corners_closed += 1
        self.send(p)
        self.pending = v

    def flush(self) -> None:
        if self.pending is not None:
            self.send(self.pending)
            self.pending = None

    def _collinear(self, a: Vector, b: Vector) -> bool:
        s = self.settings
        if _angle_between(a, b) > s.merge_angle_rad:
            return False
        if max(_point_line_distance(b[:2], a), _point_line_distance(b[2:], a)) > s.merge_offset_mm:
            return False
        ends_a, ends_b = (a[:2], a[2:]), (b[:2], b[2:])
        gap = min(math.dist(p, q) for p in ends_a for q in ends_b)
        overlap = self._overlaps(a, b)
        return overlap or gap <= s.merge_gap_mm

    @staticmethod
    def _overlaps(a: Vector, b: Vector) -> bool:
        d = np.array([a[2] - a[0], a[3] - a[1]])
        length = float(np.hypot(*d)) or 1.0
        d /= length
        tb = sorted(float((np.array(q) - np.array(a[:2])) @ d) for q in (b[:2], b[2:]))
        return tb[1] >= 0.0 and tb[0] <= length

    @staticmethod
    def _merge(a: Vector, b: Vector) -> Vector:
        """One vector along the length-weighted line of both, spanning both."""
        la, lb = vector_length(a), vector_length(b)
        pts = np.array([a[:2], a[2:], b[:2], b[2:]])
        weights = np.array([la, la, lb, lb]) + 1e-6
        centroid = (pts * weights[:, None]).sum(axis=0) / weights.sum()
        da = np.array([a[2] - a[0], a[3] - a[1]]) / (la or 1.0)
        db = np.array([b[2] - b[0], b[3] - b[1]]) / (lb or 1.0)
        if da @ db < 0:
            db = -db
        direction = da * la + db * lb
        direction /= np.linalg.norm(direction) or 1.0
        t = (pts - centroid) @ direction
        start = centroid + direction * t.min()
        end = centroid + direction * t.max()
        return (float(start[0]), float(start[1]), float(end[0]), float(end[1]))

    @staticmethod
    def _extends_end(v: Vector, corner: Point) -> bool:
        """The corner lies beyond (or near) ``v``'s end rather than behind its start."""
        return math.dist(corner, v[2:]) <= math.dist(corner, v[:2])

    @staticmethod
    def _extends_start(v: Vector, corner: Point) -> bool:
        return math.dist(corner, v[:2]) <= math.dist(corner, v[2:])


# ---------------------------------------------------------------------------------------------
# pose history for interpolation at a sweep's time stamp


class PoseHistory:
    """Recent time-stamped poses; :meth:`at` interpolates (heading along the shorter arc)."""

    def __init__(self, size: int = 256) -> None:
        self.samples: deque[tuple[int, Pose]] = deque(maxlen=size)

    def add(self, stamp_ms: int, pose: Pose) -> None:
        if self.samples and stamp_ms < self.samples[-1][0]:
            self.samples.clear()  # the clock restarted
        if self.samples and stamp_ms == self.samples[-1][0]:
            self.samples[-1] = (stamp_ms, pose)
        else:
            self.samples.append((stamp_ms, pose))

    def latest(self) -> Pose | None:
        return self.samples[-1][1] if self.samples else None

    def at(self, stamp_ms: int) -> Pose | None:
        if not self.samples:
            return None
        if stamp_ms >= self.samples[-1][0]:
            return self.samples[-1][1]
        if stamp_ms <= self.samples[0][0]:
            return self.samples[0][1]
        items = self.samples
        for (t0, p0), (t1, p1) in zip(items, list(items)[1:], strict=False):
            if t0 <= stamp_ms <= t1:
                f = (stamp_ms - t0) / (t1 - t0) if t1 > t0 else 1.0
                dth = (p1[2] - p0[2] + math.pi) % (2 * math.pi) - math.pi
                return (p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]), p0[2] + f * dth)
        return self.samples[-1][1]

    def carry(self, pose: Pose, from_ms: int, to_ms: int) -> Pose:
        """``pose`` (valid at ``from_ms``, e.g. the filter's) moved on by the recorded motion
        until ``to_ms``: that motion in the robot's frame, applied in the pose's frame."""
        a, b = self.at(from_ms), self.at(to_ms)
        if a is None or b is None:
            return pose
        dx, dy = b[0] - a[0], b[1] - a[1]
        c, s = math.cos(a[2]), math.sin(a[2])
        forward, left = c * dx + s * dy, -s * dx + c * dy
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        return (x + c * forward - s * left, y + s * forward + c * left, th + (b[2] - a[2]))


# ---------------------------------------------------------------------------------------------
# both sides, one method: what copro runs per sweep (and the mapping benchmark replays)

SEED_METHOD, OUR_METHOD = 0, 1


class Vectorizer:
    """Both sides' hypotheses and vector generation by the seed's method or ours."""

    def __init__(self, layout: SonarLayout, method: int, send: Callable[[Vector], None]) -> None:
        self.layout = layout
        self.method = method
        self.hypotheses = {"left": SideHypothesis(), "right": SideHypothesis()}
        self.post = {side: VectorPostProcessor(send) for side in ("left", "right")}
        self.generators: dict[str, SeedEdgeFollower | WallTracker] = {}
        for side in ("left", "right"):
            _, _, sensors = layout.side(side)
            if method == SEED_METHOD:
                self.generators[side] = SeedEdgeFollower(sensors, send)
            else:
                self.generators[side] = WallTracker(sensors, self.post[side].add)

    def sweep(self, sonar: dict, pose: Pose | None, active: bool) -> None:
        """One sonar sweep (``sonar.data`` decoded): hypotheses, then vectors where they apply."""
        for side in ("left", "right"):
            front, rear, _ = self.layout.side(side)
            h = observe_side(
                sonar["behaviours"][front],
                sonar["behaviours"][rear],
                sonar["areas"][front],
                sonar["areas"][rear],
                self.hypotheses[side],
            )
            self.hypotheses[side] = h
            self.generators[side].feed(
                SweepInput(
                    sonar["stamp_ms"],
                    pose or (0.0, 0.0, 0.0),
                    sonar["distances"][front],
                    sonar["distances"][rear],
                    h.contact,
                    bool(active and pose is not None),
                )
            )

    def end_scan(self) -> None:
        idle = SweepInput(0, (0.0, 0.0, 0.0), NO_CONTACT_CM, NO_CONTACT_CM, NONE, False)
        for generator in self.generators.values():
            generator.feed(idle)

    def flush(self) -> None:
        self.end_scan()
        for generator in self.generators.values():
            if isinstance(generator, WallTracker):
                generator.finish()
        for post in self.post.values():
            post.flush()

    @property
    def corners_closed(self) -> int:
        return sum(p.corners_closed for p in self.post.values())

    @property
    def merged(self) -> int:
        return sum(p.merged for p in self.post.values())
