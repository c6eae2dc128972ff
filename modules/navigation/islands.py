"""Explore 2's islands: free-standing obstacles seen on the right during the room's lap, or run
into by drives into the interior no path came near (a pillar far from every wall is out of the
lap's sight); each is approached, put on the left and gone round, a lap of its own.

After the lap :meth:`IslandVisits._next_island` picks what comes next: the nearest island not
visited, else a probe into the interior, else a place left to explore
(:mod:`modules.navigation.frontier_visits`), else the way home (:mod:`modules.navigation.homing`).
"""

from __future__ import annotations

import math

import numpy as np

from modules.description.robot import SONAR_MOUNTS, SonarMount, sonar_world_pose
from modules.navigation.base import NAV
from modules.navigation.pilot import Move, Outcome, Sensors
from modules.navigation.wall_settings import WallSettings


class IslandVisits:
    """The islands and probes of :class:`~modules.navigation.navigator.ExploreLeftWall` (a part of
    it, on its state: the lap's ``path`` and ``sightings``, ``outer_path``, ``circled``,
    ``target``, ``visits``, ``unreached``, ``probes``, ``probe_goals``, ``trail``)."""

    def _plan_probe(
        self, last: Outcome | None, sensors: Sensors, label: str, blocked: bool
    ) -> list[Move] | None:
        """A drive into the interior: something in the way is an island."""
        if label == "probe":
            if blocked and self._island_ahead(sensors):
                self.target = self.probe_goals[-1]
                self.visits += 1
                self.note = "found an island inside"
                self.commands.append(("copro", "FLUSH", {}))
                return self._onto_island(sensors)
            return self._next_island(sensors)
        self.state = NAV["ENTRY"]
        return [self._probe_move(sensors)]

    def _plan_approach(
        self, last: Outcome | None, sensors: Sensors, label: str, blocked: bool
    ) -> list[Move] | None:
        """Drive to the island chosen until it blocks the way."""
        if label == "approach":
            if blocked and self.frontier_follow and self._known_ahead(sensors):
                return self._next_island(sensors)  # a wall mapped already: nothing new there
            if blocked:  # it is ahead: put it on the left and go round it
                return self._onto_island(sensors)
            assert self.target is not None
            if not self.frontier_follow:
                self.unreached.append(self.target)  # missed it (or it was not there)
            return self._next_island(sensors)
        self.state = NAV["ENTRY"]
        return [self._approach(sensors)]

    def _record(self, last: Outcome, label: str) -> None:
        """The lap's path, and on the room's lap the right side's echoes of follow segments
        (on a probe into the interior, every sonar's)."""
        lay = self.layout
        for (_, distances), pose in zip(last.samples, last.poses, strict=False):
            if pose is None:
                continue
            self.path.append(pose[:2])
            if label == "probe":
                self.sightings += [
                    sonar_point(pose, i, distances[i] * 10.0, lay.mounts)
                    for i in range(len(distances))
                    if distances[i] <= self.s.sighting_cm
                ]
                continue
            if label != "follow" or self.target is not None:
                continue
            for index, which in ((lay.right_front, "front"), (lay.right_rear, "rear")):
                if distances[index] <= self.s.sighting_cm:
                    self.sightings.append(lay.right.point(pose, which, distances[index] * 10.0))

    def _islands(self) -> list[tuple[float, float, int]]:
        """Obstacles seen on the right inside the room's lap and not yet visited: (x, y, sightings)
        — groups of sightings linked by ``sighting_link_mm``, their centroids."""
        s = self.s
        outer = self.outer_path
        if len(outer) < 3:
            return []
        points = [
            p
            for p in self.sightings
            if point_in_polygon(p, outer)
            and distance_to_path(p, outer) >= s.inside_margin_mm
            and not any(
                point_in_polygon(p, ring) or distance_to_path(p, ring) < s.circled_margin_mm
                for ring in self.circled
                if len(ring) >= 3
            )
        ]
        found = []
        for group in linked_groups(points, s.sighting_link_mm):
            if len(group) < s.sighting_min:
                continue
            cx = sum(p[0] for p in group) / len(group)
            cy = sum(p[1] for p in group) / len(group)
            if all(math.dist((cx, cy), u) > s.sighting_link_mm for u in self.unreached):
                found.append((cx, cy, len(group)))
        return found

    def _next_island(self, sensors: Sensors) -> list[Move] | None:
        """After a lap: turn toward the nearest island not yet visited, or end the run."""
        s = self.s
        self.target, self.frontier_follow = None, False
        islands = self._islands() if self.visits < s.visit_islands and sensors.pose is not None else []
        if not islands:
            probe = self._next_probe(sensors)
            if probe is not None:
                return probe
            frontier = self._next_frontier(sensors)
            if frontier is not None:
                return frontier
            gone_round = len(self.circled) - len(self.islands)
            self.done_note = f"lap closed, {gone_round} island(s) gone round" if self.visits else "lap closed"
            self.note = self.done_note
            if s.return_home and self.home is not None and sensors.pose is not None:
                self.phase, self.last_follow, self.target = "home", None, None
                return self._go_home(sensors)
            self.state = NAV["DONE"]
            return None
        x, y, heading = sensors.pose
        tx, ty, _ = min(islands, key=lambda i: math.dist((x, y), i[:2]))
        self.target = (tx, ty)
        self.path = []
        self.visits += 1
        self.phase, self.last_follow = "approach", None
        self.commands.append(("copro", "FLUSH", {}))  # the room's last wall is not the island's neighbour
        self.state = NAV["TURN"]
        bearing = math.degrees(math.remainder(math.atan2(ty - y, tx - x) - heading, 2 * math.pi))
        return self._turn(bearing, "aim", sensors) or [self._approach(sensors)]

    def _next_probe(self, sensors: Sensors) -> list[Move] | None:
        """Turn toward the interior's largest stretch no path came near, or None: all seen."""
        s = self.s
        if self.probes >= s.max_probes or sensors.pose is None or len(self.outer_path) < 3:
            return None
        islands = [ring for ring in self.circled if len(ring) >= 3]
        goal = interior_goal(self.outer_path, self._seen_from(), islands, sensors.pose[:2], s)
        if goal is None:
            return None
        self.probes += 1
        self.probe_goals.append(goal)
        self.phase, self.last_follow = "probe", None
        x, y, heading = sensors.pose
        self.state = NAV["TURN"]
        self.note = f"probing the interior ({self.probes})"
        bearing = math.degrees(math.remainder(math.atan2(goal[1] - y, goal[0] - x) - heading, 2 * math.pi))
        return self._turn(bearing, "aim", sensors) or [self._probe_move(sensors)]

    def _seen_from(self) -> list[tuple[float, float]]:
        """Where the sonars looked from: the trail (every few cm is plenty) and the probes' goals
        (one that could not be reached is not tried again)."""
        return self.trail[:: max(1, len(self.trail) // 4000)] + self.probe_goals

    def _probe_move(self, sensors: Sensors) -> Move:
        goal = self.probe_goals[-1]
        distance = math.dist(sensors.pose[:2], goal) if sensors.pose is not None else self.s.find_mm
        return self._forward(max(100, round(distance)), "probe")

    def _island_ahead(self, sensors: Sensors) -> bool:
        """What stopped a probe lies inside the room's lap, away from its walls and the islands
        gone round: a free-standing obstacle nobody saw yet."""
        if sensors.pose is None:
            return False
        point = self._point_ahead(sensors)
        outer = self.outer_path
        return (
            point_in_polygon(point, outer)
            and distance_to_path(point, outer) >= self.s.inside_margin_mm
            and not any(
                point_in_polygon(point, ring) or distance_to_path(point, ring) < self.s.inside_margin_mm
                for ring in self.circled
                if len(ring) >= 3
            )
        )

    def _point_ahead(self, sensors: Sensors) -> tuple[float, float]:
        """Where the nearest echo of the front sonars came from (the pose known)."""
        assert sensors.pose is not None
        index = min(self.layout.front, key=lambda i: sensors.distances[i])
        return sonar_point(sensors.pose, index, sensors.distances[index] * 10.0, self.layout.mounts)

    def _onto_island(self, sensors: Sensors) -> list[Move]:
        """An island blocks the way: turn so it is on the left and follow it, a lap of its own."""
        self.rotation, self.follow_mm, self.laps = 0.0, 0, 0
        self.lap_start, self.path = None, []
        self.phase = "follow"
        self.state = NAV["TURN"]
        return self._turn(-90, "inner", sensors, align=True) or [self._segment()]

    def _approach(self, sensors: Sensors) -> Move:
        assert self.target is not None
        distance = math.dist(sensors.pose[:2], self.target) if sensors.pose is not None else self.s.find_mm
        beyond = self.s.frontier_beyond_mm if self.frontier_follow else 300.0
        return self._forward(round(distance + beyond), "approach")


def sonar_point(
    pose: tuple[float, float, float],
    index: int,
    distance_mm: float,
    mounts: tuple[SonarMount, ...] = SONAR_MOUNTS,
) -> tuple[float, float]:
    """The world point a reading of sonar ``index`` (on ``mounts``) marks, the robot at ``pose``."""
    sx, sy, direction = sonar_world_pose(pose[0], pose[1], pose[2], index, mounts)
    return (sx + distance_mm * math.cos(direction), sy + distance_mm * math.sin(direction))


def interior_goal(
    outer: list[tuple[float, float]],
    seen_from: list[tuple[float, float]],
    islands: list[list[tuple[float, float]]],
    here: tuple[float, float],
    s: WallSettings,
) -> tuple[float, float] | None:
    """Where to drive next to see the interior: the cell inside the room's lap with the most
    unseen cells around it (nearer ones first among equals), or None when every cell lies within
    ``probe_seen_mm`` of a path driven. Cells inside an island gone round do not count."""
    poly = np.asarray(outer, dtype=float)
    step = s.probe_cell_mm
    (x0, y0), (x1, y1) = poly.min(axis=0), poly.max(axis=0)
    gx, gy = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    cells = np.column_stack([gx.ravel(), gy.ravel()])
    inside = _inside(cells, poly)
    for ring in islands:
        inside &= ~_inside(cells, np.asarray(ring, dtype=float))
    cells = cells[inside]
    if len(cells) == 0:
        return None
    trail = np.asarray(seen_from or [here], dtype=float)
    near = np.full(len(cells), np.inf)
    for chunk in range(0, len(trail), 500):
        part = trail[chunk : chunk + 500]
        near = np.minimum(near, np.sqrt(((cells[:, None, :] - part[None, :, :]) ** 2).sum(-1)).min(axis=1))
    unseen = cells[near > s.probe_seen_mm]
    if len(unseen) == 0:
        return None
    around = (np.sqrt(((unseen[:, None, :] - unseen[None, :, :]) ** 2).sum(-1)) <= s.probe_seen_mm).sum(
        axis=1
    )
    distance = np.sqrt(((unseen - np.asarray(here)) ** 2).sum(-1))
    best = int(np.argmax(around - distance / 1000.0))
    return float(unseen[best, 0]), float(unseen[best, 1])


def _inside(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd rule for many points at once (arrays (N, 2) and (M, 2))."""
    x, y = points[:, 0][:, None], points[:, 1][:, None]
    ax, ay = polygon[:, 0][None, :], polygon[:, 1][None, :]
    bx, by = np.roll(polygon[:, 0], -1)[None, :], np.roll(polygon[:, 1], -1)[None, :]
    crosses = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = ax + (y - ay) * (bx - ax) / np.where(by != ay, by - ay, 1.0)
    return (crosses & (x < xint)).sum(axis=1) % 2 == 1


def point_in_polygon(p: tuple[float, float], polygon: list[tuple[float, float]]) -> bool:
    """Whether ``p`` lies inside the closed path ``polygon`` (even-odd rule)."""
    return bool(_inside(np.array([p], dtype=float), np.asarray(polygon, dtype=float))[0])


def linked_groups(points: list[tuple[float, float]], link: float) -> list[list[tuple[float, float]]]:
    """The points split into groups in which each lies within ``link`` of another (single linkage)."""
    groups = []
    unassigned = list(points)
    while unassigned:
        group = [unassigned.pop()]
        frontier = list(group)
        while frontier:
            q = frontier.pop()
            near, far = [], []
            for p in unassigned:
                (near if math.dist(p, q) <= link else far).append(p)
            unassigned = far
            group += near
            frontier += near
        groups.append(group)
    return groups


def distance_to_path(p: tuple[float, float], path: list[tuple[float, float]]) -> float:
    """The distance from ``p`` to the nearest point of ``path`` (its points, dense along the way)."""
    return min(math.dist(p, q) for q in path)
