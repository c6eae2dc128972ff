"""The world's ground truth as a judge of the robot's motion in ring tests that drive it from a
screen (the console in tmux, the web view in Chromium): read by hand from ``world/truth``, never
through the code under test."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import msgpack

from tests.support.ringutil import wait_until

Pose = tuple[float, float, float]

#: a 6 m square hall: the robot starts in the middle, well away from every wall
OPEN_HALL = """
name: open-hall
start: {x: 3000, y: 3000, angle_deg: 0}
walls:
  - polygon: [[0, 0], [6000, 0], [6000, 6000], [0, 6000]]
"""


class Truth:
    """The world's ground truth pose (mm, mm, rad CCW) as it is published."""

    def __init__(self, session, ring: str) -> None:
        self.pose: Pose | None = None
        self.count = 0
        self._sub = session.declare_subscriber(f"tokenring/{ring}/world/truth", self._on)

    def _on(self, sample) -> None:
        data = msgpack.unpackb(sample.payload.to_bytes(), raw=False, strict_map_key=False)
        self.pose = (float(data["x_mm"]), float(data["y_mm"]), float(data["theta_rad"]))
        self.count += 1

    def wait(self, condition: Callable[[Pose], bool], what: str, timeout: float = 120.0) -> Pose:
        """The pose once ``condition`` holds for it (``what`` names it in the failure)."""
        return wait_until(lambda: self.pose if self.pose and condition(self.pose) else None, timeout, what)

    def settled(self, updates: int = 20, timeout: float = 120.0) -> Pose:
        """The pose once ``updates`` truth updates in a row left it where it was."""
        deadline = time.monotonic() + timeout
        same, last = 0, None
        while same < updates:
            assert time.monotonic() < deadline, f"the robot never stood still (true pose {self.pose})"
            seen = self.count
            while self.count == seen:
                time.sleep(0.02)
            same = same + 1 if last is not None and close(self.pose, last) else 0
            last = self.pose
        assert last is not None
        return last


def close(a: Pose | None, b: Pose | None, mm: float = 0.5, rad: float = 0.002) -> bool:
    """Two poses within ``mm`` and ``rad`` of each other."""
    return a is not None and b is not None and math.dist(a[:2], b[:2]) < mm and abs(a[2] - b[2]) < rad
