"""Explore 2's places left to explore after the lap, the islands and the probes: walls the sonars
saw but no side sonar mapped, and frontiers where the space seen free ends
(:class:`~modules.navigation.frontier.SeenGrid`). The robot drives to each along a way through
space seen free and follows the wall it finds there, unless that wall is mapped already.
"""

from __future__ import annotations

import math

import numpy as np

from modules.navigation.base import NAV
from modules.navigation.frontier import SeenGrid
from modules.navigation.pilot import Move, Outcome, Sensors


class FrontierVisits:
    """The places left to explore of :class:`~modules.navigation.navigator.ExploreLeftWall` (a part
    of it, on its state: ``seen``, ``frontier_goals``, ``frontier_follow``, ``goto``,
    ``goto_moves_left``, ``goto_replans``, ``target``)."""

    def _plan_goto(
        self, last: Outcome | None, sensors: Sensors, label: str, blocked: bool
    ) -> list[Move] | None:
        """The way to a place left to explore, through space seen free."""
        if label == "goto" and blocked:
            if self._known_ahead(sensors):  # a wall mapped already: nothing new there
                replanned = self._replan_goto(sensors)
                return replanned if replanned is not None else self._next_island(sensors)
            return self._onto_island(sensors)  # there, or a wall nobody followed: follow it
        return self._goto_next(sensors)

    def _see(self, last: Outcome) -> None:
        """Every sweep of the last moves into the grid of what the sonars saw."""
        lay = self.layout
        scanning = last.move is not None and last.move.scan
        sides = (lay.left_front, lay.left_rear, lay.right_front, lay.right_rear)
        before: tuple[float, float, float] | None = None
        for (_, distances), pose in zip(last.samples, last.poses, strict=False):
            if pose is None:
                continue
            if self.seen is None:
                self.seen = SeenGrid(pose[:2], mounts=lay.mounts)
            straight = before is not None and abs(math.remainder(pose[2] - before[2], 2 * math.pi)) < 0.06
            self.seen.add(pose, distances, sides if scanning and straight else ())
            before = pose

    def _next_frontier(self, sensors: Sensors) -> list[Move] | None:
        """Set off for the nearest place left to explore not tried yet — a wall seen but not
        mapped, else a frontier — along a way through space seen free; None: none left, or
        ``max_frontiers`` tried (one with no known way there counts). What blocks the way there
        is followed as an island is, for ``frontier_follow_mm``, unless it is mapped already."""
        s = self.s
        if len(self.frontier_goals) >= s.max_frontiers or sensors.pose is None or self.seen is None:
            return None
        here = sensors.pose[:2]
        for goals in self._untried_places():  # walls first: the map
            for goal in sorted(goals, key=lambda g: math.dist(here, g)):
                self.frontier_goals.append(goal)
                route = self.seen.route(here, goal, s.route_clearance_mm)
                if route is not None and len(self.frontier_goals) <= s.max_frontiers:
                    self.target, self.frontier_follow = goal, True
                    self._set_way(route)
                    self.lap_start, self.follow_mm, self.goto_replans = None, 0, 0
                    self.path = []
                    self.phase, self.last_follow = "goto", None
                    self.commands.append(("copro", "FLUSH", {}))
                    self.note = f"to a place left to explore ({len(self.frontier_goals)})"
                    return self._goto_next(sensors)
        return None

    def _goto_next(self, sensors: Sensors) -> list[Move] | None:
        """Aim at the next waypoint on the way to the place left to explore and drive there;
        past the last one, aim at the place itself and drive on until something blocks the way."""
        s = self.s
        assert self.target is not None
        if sensors.pose is None:
            return self._next_island(sensors)
        here = sensors.pose[:2]
        while self.goto and math.dist(here, self.goto[0]) <= s.waypoint_tolerance_mm:
            self.goto.pop(0)
        self.goto_moves_left -= 1
        if self.goto_moves_left < 0:
            return self._next_island(sensors)
        x, y, heading = sensors.pose
        tx, ty = self.goto[0] if self.goto else self.target
        bearing = math.degrees(math.remainder(math.atan2(ty - y, tx - x) - heading, 2 * math.pi))
        self.state = NAV["ENTRY"]
        if not self.goto:
            self.phase = "approach"
            return self._turn(bearing, "aim", sensors) or [self._approach(sensors)]
        return self._turn(bearing, "aim", sensors) or [
            self._forward(max(50, round(math.dist(here, (tx, ty)))), "goto")
        ]

    def _set_way(self, route: list[tuple[float, float]]) -> None:
        """The waypoints to the place, and the moves allowed to get there (3 per waypoint)."""
        self.goto = route
        self.goto_moves_left = self.s.goto_moves + 3 * len(route)

    def _replan_goto(self, sensors: Sensors) -> list[Move] | None:
        """A mapped wall blocked the way short of the place: plan the way again from here, the
        echo that blocked it now on the grid (a partition's end the first plan cut past), up to
        ``goto_replans`` times; None: at the place already, out of replans, or no way known."""
        s = self.s
        if sensors.pose is None or self.seen is None or self.target is None:
            return None
        here = sensors.pose[:2]
        if self.goto_replans >= s.goto_replans or math.dist(here, self.target) <= s.frontier_arrived_mm:
            return None
        route = self.seen.route(here, self.target, s.route_clearance_mm)
        if route is None:
            return None
        self.goto_replans += 1
        self._set_way(route)
        self.note = f"to a place left to explore ({len(self.frontier_goals)}), another way"
        return self._goto_next(sensors)

    def _untried_places(self) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
        """The places left to explore not tried yet: walls seen but not mapped, and frontiers
        farther than ``probe_seen_mm`` from every path (nearer ones the probes count as seen: an
        empty room's middle has no echo to show it free)."""
        if self.seen is None:
            return [], []
        s = self.s
        trail = np.asarray(self._seen_from(), dtype=float)
        far = [f for f in self.seen.frontiers() if np.hypot(*(trail - (f.x, f.y)).T).min() > s.probe_seen_mm]
        walls, frontiers = (
            [
                (f.x, f.y)
                for f in found
                if all(math.dist((f.x, f.y), g) > s.frontier_tried_mm for g in self.frontier_goals)
            ]
            for found in (self.seen.unmapped_walls(), far)
        )
        return walls, frontiers

    def _places_left(self) -> int:
        """Places left to explore that :meth:`_next_frontier` would still go to."""
        walls, frontiers = self._untried_places()
        return len(walls) + len(frontiers)

    def _known_ahead(self, sensors: Sensors) -> bool:
        """What blocks the way lies on a wall mapped already (a side sonar followed it), away
        from the place left to explore (its unmapped stretch may begin next to a mapped one)."""
        if sensors.pose is None or self.seen is None or self.target is None:
            return False
        point = self._point_ahead(sensors)
        if math.dist(point, self.target) <= self.s.frontier_arrived_mm:
            return False
        return self.seen.mapped_near(point)
