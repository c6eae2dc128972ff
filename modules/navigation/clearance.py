"""How far the body can go straight before it comes too near anything the sonars have shown.

The pilot's ALERT (a sonar under 4 cm) is what a sonar reads just before the body touches, and a
surface met at a grazing angle answers no sonar at all (its echo goes away), so the moment's
readings cannot keep the robot off the walls (issue 57). :class:`EchoMemory` remembers where the
echoes of the last sweeps came from, in world coordinates: each reading as a short arc across its
beam (the echo came from somewhere in it, not only on its axis), kept while the robot stays near
and for a while. :meth:`EchoMemory.free_mm` then says how far the robot's centre can go straight
ahead (or back) before its collision circle comes within a margin of any remembered echo — a
surface seen square-on by a side sonar while passing is still known when the nose later meets it
edge-on.

An arc at the echo's range is where the surface may be, and of an oblique wall most of it lies in
front of the wall (a beam 45° to a wall 30 cm off puts its far end 13 cm short of it). Each new
echo therefore clears the old points near its own beam's axis that lie short of it: the beam
went through them. Only the axis, and only with an echo: no echo proves nothing free (a wall met
at a grazing angle, a partition's end, answer none).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from modules.description.robot import ROBOT_RADIUS_MM, SONAR_MOUNTS, SonarMount, sonar_world_pose

NO_CONTACT_CM = 255

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class ClearanceSettings:
    margin_mm: float = 60.0  # the collision circle stops this far short of a remembered echo
    side_margin_mm: float = 25.0  # ... and passes echoes beside it this far off at the least
    #: a point the body would already overlap by this much is misplaced (the body is there)
    overlap_mm: float = 20.0
    #: an echo is placed within this of its beam's axis. The beam is 30° wide, but a surface
    #: seen square-on (what the memory is for) answers on the axis, and a corner at the beam's
    #: edge, placed across all of it, put phantom points in the free way beside it
    half_beam_deg: float = 7.5
    arc_points: int = 5  # points along that arc (3.75° apart)
    #: readings beyond this are too coarse to place: at 1 m the beam is half a metre wide, and
    #: a pillar's face seen there put points across the free way beside it
    range_mm: float = 800.0
    keep_ms: float = 120_000.0  # echoes older than this are forgotten (the pose drifts)
    merge_mm: float = 20.0  # points are kept one per cell this size, the newest
    merge_every: int = 8  # sweeps between merges
    clear_half_deg: float = 7.5  # an echo clears older points this near its beam's axis
    clear_short_mm: float = 60.0  # ... lying at least this much short of it
    max_points: int = 20_000


class EchoMemory:
    """Echo points of recent sweeps (world mm) and the free way straight ahead of a pose."""

    def __init__(
        self, settings: ClearanceSettings | None = None, mounts: tuple[SonarMount, ...] = SONAR_MOUNTS
    ) -> None:
        self.s = settings or ClearanceSettings()
        self.mounts = mounts
        half = math.radians(self.s.half_beam_deg)
        self._arc = np.linspace(-half, half, self.s.arc_points) if self.s.arc_points > 1 else np.zeros(1)
        self._points = np.zeros((0, 2))
        self._stamps = np.zeros(0)
        self._adds = 0

    def add(self, pose: Pose, distances_cm: Sequence[int], stamp_ms: float) -> None:
        """One sweep's readings at ``pose``: each echo as an arc of points across its beam."""
        parts = []
        beams = []
        for index, cm in enumerate(distances_cm[: len(self.mounts)]):
            if cm >= NO_CONTACT_CM or cm * 10.0 > self.s.range_mm:
                continue
            sx, sy, direction = sonar_world_pose(pose[0], pose[1], pose[2], index, self.mounts)
            angles = direction + self._arc
            reach = cm * 10.0
            parts.append(np.column_stack((sx + reach * np.cos(angles), sy + reach * np.sin(angles))))
            beams.append((sx, sy, direction, reach))
        keep = self._stamps >= stamp_ms - self.s.keep_ms
        keep &= self._not_passed(beams) & self._not_under(pose)
        points, stamps = self._points[keep], self._stamps[keep]
        if parts:
            new = np.vstack(parts)
            points = np.vstack((points, new))
            stamps = np.concatenate((stamps, np.full(len(new), float(stamp_ms))))
        self._points, self._stamps = points[-self.s.max_points :], stamps[-self.s.max_points :]
        self._adds += 1
        if self._adds % self.s.merge_every == 0:
            self._merge()

    def _not_under(self, pose: Pose) -> np.ndarray:
        """False for the points under the body: it stands there, so they were misplaced."""
        reach = ROBOT_RADIUS_MM - self.s.overlap_mm
        return np.hypot(self._points[:, 0] - pose[0], self._points[:, 1] - pose[1]) >= reach

    def _not_passed(self, beams: list[tuple[float, float, float, float]]) -> np.ndarray:
        """False for the points a beam's echo went past: near its axis, short of it."""
        keep = np.ones(len(self._points), dtype=bool)
        half = math.radians(self.s.clear_half_deg)
        for sx, sy, direction, reach in beams:
            dx, dy = self._points[:, 0] - sx, self._points[:, 1] - sy
            distance = np.hypot(dx, dy)
            off = np.abs(np.remainder(np.arctan2(dy, dx) - direction + math.pi, 2 * math.pi) - math.pi)
            keep &= ~((off <= half) & (distance < reach - self.s.clear_short_mm))
        return keep

    def _merge(self) -> None:
        """One point per ``merge_mm`` cell, the newest: a wall passed for minutes stays a line."""
        if len(self._points) == 0:
            return
        cells = np.floor(self._points / self.s.merge_mm).astype(np.int64)
        newest_first = np.arange(len(cells))[::-1]
        _, first = np.unique(cells[newest_first], axis=0, return_index=True)
        chosen = np.sort(newest_first[first])
        self._points, self._stamps = self._points[chosen], self._stamps[chosen]

    @property
    def points(self) -> np.ndarray:
        """The remembered echo points, (N, 2) world mm."""
        return self._points

    def free_mm(self, pose: Pose, reverse: bool = False) -> float:
        """How far the centre can go straight forward (``reverse``: back) from ``pose`` before the
        collision circle comes within the margin of a remembered echo; 0 if it is within it
        already on that side, inf if nothing lies in the way."""
        if len(self._points) == 0:
            return math.inf
        heading = pose[2] + (math.pi if reverse else 0.0)
        c, s = math.cos(heading), math.sin(heading)
        dx, dy = self._points[:, 0] - pose[0], self._points[:, 1] - pose[1]
        along, across = dx * c + dy * s, -dx * s + dy * c
        radius = ROBOT_RADIUS_MM
        # each point taken side_margin nearer the line the centre drives (the pose's sideways
        # error): the circle touches a point (a, b) once its centre is at a - sqrt(r² - b²)
        side = np.maximum(np.abs(across) - self.s.side_margin_mm, 0.0)
        in_lane = side < radius
        touch = along[in_lane] - np.sqrt(radius**2 - side[in_lane] ** 2)
        # one the body would overlap already lies where the body is: misplaced, not in the way
        touch = touch[touch > -self.s.overlap_mm]
        if len(touch) == 0:
            return math.inf
        return max(0.0, float(touch.min()) - self.s.margin_mm)
