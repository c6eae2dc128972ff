"""The sonar's corrections of the floor's step scale: a straight drive's range series to a wall
(the filter's travel fit), turned back into the distance driven by the beam's incidence on the
known wall it meets; in exploration mode a fit waits for its wall to appear in the robot's map.
"""

from __future__ import annotations

import math
from typing import Any

from modules.localization.params import sonar_mounts
from modules.localization.walls import KnownWall, from_frame, ray_crossing

#: a step-scale fit waits this long (sensor time) for the robot's own map to show its wall
PENDING_TRAVEL_MS = 300_000


class TravelCorrections:
    """The step-scale corrections of :class:`~modules.localization.localizer.LocalizationCore` (a
    part of it, on its state: ``config``, ``ekf``, ``known_walls``, ``pending_travel``,
    ``travel``)."""

    def _correct_travel(self, travel: dict[str, Any], stamp: int) -> None:
        """A straight drive's step scale from a sonar's range series; the beam's incidence on the
        known wall it meets (if any) turns the range's change back into the distance driven."""
        ekf = self.ekf
        assert ekf is not None
        mount = sonar_mounts(self.config)[travel["sensor"]]
        pose = ekf.pose
        ex, ey, eh = travel.get("end", (0.0, 0.0, 0.0))
        end = (*from_frame((ex, ey), pose), pose[2] + eh)  # the robot where the run ended
        settings = self.config["filter"]["travel"]
        range_mm = travel["range_end_mm"]
        if settings["check_at"] == "points" and "back_mm" in travel:
            # the wall the ranges came from, seen from the middle of its points: extrapolated to the
            # run's end a rear beam's range can reach another wall, met squarely, far beyond them
            back = travel["back_mm"]
            end = (end[0] - back * math.cos(end[2]), end[1] - back * math.sin(end[2]), end[2])
            range_mm = travel["range_mm"]
        origin = from_frame((mount.x, mount.y), end)
        incidence = _beam_hit(origin, end[2] + mount.angle, range_mm, self.known_walls)
        if incidence is None and settings["wait_for_map"] and self.config["walls"]["mode"] == "exploration":
            # the wall ahead is mapped once the robot has gone along it: its incidence then
            self._expire_pending_travel(stamp)
            self.pending_travel.append((stamp, origin, end[2] + mount.angle, travel))
            return
        self._use_travel(travel, incidence, stamp)

    def _retry_pending_travel(self, wall: KnownWall, stamp: int) -> None:
        """A wall new to the robot's own map: the waiting fits whose beam met it are used now."""
        self._expire_pending_travel(stamp)
        waiting = []
        for pending in self.pending_travel:
            _, origin, direction, travel = pending
            incidence = _beam_hit(origin, direction, travel["range_end_mm"], [wall])
            if incidence is None:
                waiting.append(pending)
            else:
                self.travel["waited"] += 1
                self._use_travel(travel, incidence, stamp)
        self.pending_travel = waiting

    def _expire_pending_travel(self, stamp: int) -> None:
        """Fits that waited ``PENDING_TRAVEL_MS`` for their wall in vain: counted as unknown."""
        kept = [p for p in self.pending_travel if stamp - p[0] < PENDING_TRAVEL_MS]
        self.travel["unknown"] += len(self.pending_travel) - len(kept)
        self.pending_travel = kept

    def _use_travel(self, travel: dict[str, Any], incidence: float | None, stamp: int) -> None:
        """Correct the step scale with one fit, its wall met at ``incidence`` (None: not known)."""
        ekf = self.ekf
        assert ekf is not None
        settings = self.config["filter"]["travel"]
        sigma = math.hypot(travel["sigma"], settings["model_sigma"])
        if incidence is None:
            # a short or scattered series on such a wall reads the scale low on average
            if not settings["unknown_wall"] or travel["sigma"] > settings["unknown_wall_max_sigma"]:
                self.travel["unknown"] += 1
                return
            # a wall met φ off square reads the scale low by cos φ: a fit on a wall of unknown
            # incidence bounds the scale from below; one far below the filter's says nothing
            bound = ekf.step_scale - settings["unknown_wall_bound_sigma"] * sigma
            if settings["unknown_wall_bound"] and travel["scale"] < bound:
                self.travel["below_bound"] += 1
                return
            self.travel["assumed_square"] += 1
            incidence = 0.0  # no wall of the map there: taken as square on
        if incidence > math.radians(settings["max_incidence_deg"]):
            self.travel["oblique"] += 1
            return
        scale = travel["scale"] / math.cos(incidence)
        if ekf.correct_step_scale(scale, sigma):
            self.travel["used"] += 1
            self.message(
                "D", stamp, f"sonar {travel['sensor']}: step scale {scale:.4f} ± {travel['sigma']:.4f}"
            )
        else:
            self.travel["rejected"] += 1


def _beam_hit(
    origin: tuple[float, float], direction: float, range_mm: float, walls: list[KnownWall]
) -> float | None:
    """The incidence (rad, 0 = square on) of a beam on the nearest known wall it meets near the
    measured range (within 25 % or 150 mm); None when it meets none there."""
    best: tuple[float, float] | None = None
    for wall in walls:
        crossing = ray_crossing(origin, direction, wall)
        if crossing is None:
            continue
        t, u, sine = crossing  # along the beam, along the wall (0..1 on it)
        if t <= 0 or not -0.05 <= u <= 1.05:
            continue
        if abs(t - range_mm) > max(150.0, 0.25 * range_mm) and abs(t * sine - range_mm) > 150.0:
            continue
        incidence = math.acos(min(1.0, sine))
        if best is None or t < best[0]:
            best = (t, incidence)
    return best[1] if best is not None else None
