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
    margin_mm: float = 60.0  # the collision circle keeps this far from every remembered echo
    half_beam_deg: float = 15.0  # an echo came from somewhere within this of its beam's axis
    arc_points: int = 7  # points along that arc (about 5° apart)
    range_mm: float = 1500.0  # readings beyond this are too coarse to place
    keep_mm: float = 2000.0  # echoes farther than this from the robot are forgotten
    keep_ms: float = 120_000.0  # ... and those older than this (the pose drifts)
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
        for index, cm in enumerate(distances_cm[: len(self.mounts)]):
            if cm >= NO_CONTACT_CM or cm * 10.0 > self.s.range_mm:
                continue
            sx, sy, direction = sonar_world_pose(pose[0], pose[1], pose[2], index, self.mounts)
            angles = direction + self._arc
            reach = cm * 10.0
            parts.append(np.column_stack((sx + reach * np.cos(angles), sy + reach * np.sin(angles))))
        if parts:
            self._sweeps.append((stamp_ms, np.vstack(parts)))
        self._forget(pose, stamp_ms)

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
        reach = ROBOT_RADIUS_MM + self.s.margin_mm
        in_lane = np.abs(across) < reach
        ahead = along > 0.0
        blocking = in_lane & ahead
        if not blocking.any():
            return math.inf
        # the circle touches a point (a, b) of its lane once its centre is at a - sqrt(r² - b²)
        free = along[blocking] - np.sqrt(reach**2 - across[blocking] ** 2)
        return max(0.0, float(free.min()))
