"""Explore 2's way home: when nothing is left to explore, back to the pose the exploration began
at, facing as it did then — along the trail retraced (:func:`route_home`), round what is in the
way with a few detours.
"""

from __future__ import annotations

import math

import numpy as np

from modules.navigation.base import NAV
from modules.navigation.pilot import Move, Sensors


class ReturnHome:
    """The way home of :class:`~modules.navigation.navigator.ExploreLeftWall` (a part of it, on its
    state: ``home``, ``home_reached``, ``route``, ``detours``, ``detouring``, ``done_note``)."""

    def _go_home(self, sensors: Sensors) -> list[Move] | None:
        """Aim at the next waypoint home and drive there; at the start: turn to its heading; then
        done. The waypoints retrace the trail (:func:`route_home`): a straight line to the start
        runs into the walls of a room with a notch or a partition between."""
        assert self.home is not None and sensors.pose is not None
        x, y, heading = sensors.pose
        hx, hy, home_heading = self.home
        self.state = NAV["HOME"]
        if math.dist((x, y), (hx, hy)) <= self.s.home_tolerance_mm:
            self.phase = "home_turn"
            turn = math.degrees(math.remainder(home_heading - heading, 2 * math.pi))
            return self._turn(turn, "home turn", sensors) or self._homeward("home turn", False, sensors)
        tx, ty = self._waypoint(sensors)
        bearing = math.degrees(math.remainder(math.atan2(ty - y, tx - x) - heading, 2 * math.pi))
        return self._turn(bearing, "aim", sensors) or [self._home_move(sensors)]

    def _waypoint(self, sensors: Sensors) -> tuple[float, float]:
        """The next point on the way home (planned on the first call, and again after a detour):
        the trail retraced, unless that runs through a wall the sonars saw (a wall inside the
        lap, which counts as free) — then the way through space seen free."""
        assert self.home is not None and sensors.pose is not None
        s = self.s
        if self.route is None:
            here, home = sensors.pose[:2], self.home[:2]
            self.route = route_home(
                self.trail,
                here,
                home,
                s.home_corridor_mm,
                s.route_spacing_mm,
                outline=self.outer_path,
                islands=self.circled,
            )
            if self.seen is not None and self.seen.crosses_echo([here, *self.route]):
                seen_way = self.seen.route(here, home, s.route_clearance_mm)
                if seen_way is not None:
                    self.route = [*seen_way[:-1], home]
        while len(self.route) > 1 and math.dist(sensors.pose[:2], self.route[0]) <= s.waypoint_tolerance_mm:
            self.route.pop(0)
        return self.route[0] if self.route else self.home[:2]

    def _home_move(self, sensors: Sensors) -> Move:
        assert self.home is not None and sensors.pose is not None
        return self._forward(max(50, round(math.dist(sensors.pose[:2], self._waypoint(sensors)))), "home")

    def _homeward(self, label: str, blocked: bool, sensors: Sensors) -> list[Move] | None:
        """The way home, one plan at a time: drive, go round what is in the way, the last turn."""
        s = self.s
        if self.phase == "home_turn" and label in ("home turn", "turned"):
            self.home_reached = True
            self.state = NAV["DONE"]
            self.note = f"{self.done_note}; back at the start"
            return None
        if self.detouring:  # turned away from what blocked the way: drive on, then aim again
            self.detouring = False
            self.state = NAV["HOME"]
            return [self._forward(s.detour_mm, "detour")]
        if label == "home" and blocked:
            if self._detours_used_up():
                return None
            self.detouring = True
            self.route = None  # planned again from wherever the detour ends
            return self._turn(-90, "detour", sensors) or self._homeward("detour", False, sensors)
        if sensors.pose is None:
            return None
        if label in ("aim", "turned"):
            self.state = NAV["HOME"]
            return [self._home_move(sensors)]
        if label in ("back off", "away") and self._detours_used_up():  # ran into something
            return None
        return self._go_home(sensors)  # after a drive, a detour or an escape: aim again

    def _detours_used_up(self) -> bool:
        """One more detour on the way home; past ``home_detours`` the run ends where it is."""
        self.detours += 1
        if self.detours <= self.s.home_detours:
            return False
        self.state = NAV["DONE"]
        self.note = f"{self.done_note}; could not get back to the start"
        return True


def route_home(
    trail: list[tuple[float, float]],
    here: tuple[float, float],
    home: tuple[float, float],
    corridor_mm: float,
    spacing_mm: float = 50.0,
    outline: list[tuple[float, float]] | None = None,
    islands: list[list[tuple[float, float]]] | None = None,
) -> list[tuple[float, float]]:
    """Waypoints from ``here`` to ``home`` (where the trail began), ``home`` last: the trail
    retraced backwards, each leg going as far back along it as a straight line can while it
    stays in free space (string pulling). Free is within ``corridor_mm`` of the trail, and inside
    the lap along the room's walls (``outline``) but outside the laps round ``islands``."""
    import shapely  # the world generator's geometry library; only main's homing needs it here

    points: list[tuple[float, float]] = [home]
    for p in trail:
        if math.dist(p, points[-1]) >= spacing_mm:
            points.append(p)
    if len(points) < 2:
        return [home]
    free = shapely.LineString(points).buffer(corridor_mm)
    if outline is not None and len(outline) >= 3:
        room = shapely.make_valid(shapely.Polygon(outline))
        for ring in islands or []:
            if len(ring) >= 3:
                room = room.difference(shapely.make_valid(shapely.Polygon(ring)).buffer(corridor_mm))
        free = free.union(room)
    shapely.prepare(free)
    nodes = np.asarray(points, dtype=float)
    last = int(np.argmin(np.hypot(*(nodes - np.asarray(here, dtype=float)).T)))
    route: list[tuple[float, float]] = []
    at = (float(here[0]), float(here[1]))
    while last > 0:
        legs = shapely.linestrings([[at, tuple(node)] for node in nodes[: last + 1]])
        inside = np.flatnonzero(shapely.covers(free, legs))
        reach = int(inside[0]) if len(inside) else last  # outside (a pose fix): to the trail first
        if reach == last and route:
            reach = last - 1  # consecutive trail points are always joined in free space
        at = (float(nodes[reach][0]), float(nodes[reach][1]))
        route.append(at)
        last = reach
    return route or [home]
