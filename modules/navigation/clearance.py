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
from collections import deque
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
    keep_mm: float = 2000.0  # echoes farther than this from the robot are forgotten
    keep_ms: float = 120_000.0  # ... and those older than this (the pose drifts)
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
        self._sweeps: deque[tuple[float, np.ndarray]] = deque()  # (stamp_ms, (N, 2) points)
        self._points = np.zeros((0, 2))

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
        self._clear_along(beams)
        self._clear_body(pose)
        if parts:
            self._sweeps.append((stamp_ms, np.vstack(parts)))
        self._forget(pose, stamp_ms)

    def _clear_body(self, pose: Pose) -> None:
        """Drop the remembered points under the body: it stands there, so they were misplaced."""
        reach = ROBOT_RADIUS_MM - self.s.overlap_mm
        for k, (stamp, points) in enumerate(self._sweeps):
            under = np.hypot(points[:, 0] - pose[0], points[:, 1] - pose[1]) < reach
            if under.any():
                self._sweeps[k] = (stamp, points[~under])

    def _clear_along(self, beams: list[tuple[float, float, float, float]]) -> None:
        """Drop the remembered points each beam's echo went past: near its axis, short of it."""
        if not beams or not self._sweeps:
            return
        half = math.radians(self.s.clear_half_deg)
        for k, (stamp, points) in enumerate(self._sweeps):
            keep = np.ones(len(points), dtype=bool)
            for sx, sy, direction, reach in beams:
                dx, dy = points[:, 0] - sx, points[:, 1] - sy
                distance = np.hypot(dx, dy)
                off = np.abs(np.remainder(np.arctan2(dy, dx) - direction + math.pi, 2 * math.pi) - math.pi)
                keep &= ~((off <= half) & (distance < reach - self.s.clear_short_mm))
            if not keep.all():
                self._sweeps[k] = (stamp, points[keep])

    def _forget(self, pose: Pose, stamp_ms: float) -> None:
        """Drop the sweeps older than ``keep_ms``; of the rest, keep the points near ``pose``."""
        while self._sweeps and stamp_ms - self._sweeps[0][0] > self.s.keep_ms:
            self._sweeps.popleft()
        points = np.vstack([p for _, p in self._sweeps]) if self._sweeps else np.zeros((0, 2))
        near = np.hypot(points[:, 0] - pose[0], points[:, 1] - pose[1]) <= self.s.keep_mm
        self._points = points[near][-self.s.max_points :]

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
