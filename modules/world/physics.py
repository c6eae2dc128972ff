"""Geometry of the simulated room: ray casting for the sonar and the tracked robot's motion.

Motion follows SPEC §5: the motor module's half-steps move the tracks; the common part of the
left and right steps drives straight (true step length off by a systematic +1 % and 0.5 % random
per move), the difference turns on the spot (true half-steps per degree drawn per turn within
±10 % of the floor's glide factor). The robot is a circle for collisions: a move that would
bring it closer to a wall than its radius stops where it touches (and is reported).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from modules.description.robot import MAX_STEP_RATE_HZ, STEP_MM
from modules.description.room import Pose, World

STALL_TOLERANCE = 1.02  # step rates up to 2 % above the start-stop limit still run


@dataclass
class RayHits:
    """Per ray: distance to the first surface (inf: none), incidence angle at it (0 = head-on)."""

    distance: np.ndarray
    incidence: np.ndarray


def cast_rays(world: World, x: float, y: float, angles: np.ndarray, max_range: float = 3000.0) -> RayHits:
    """First surface hit by rays from (x, y) at ``angles`` (radians CCW), walls and circles alike."""
    dx, dy = np.cos(angles), np.sin(angles)
    best = np.full(angles.shape, np.inf)
    incidence = np.zeros(angles.shape)
    seg = world.segments()
    if len(seg):
        ax, ay = seg[:, 0][None, :], seg[:, 1][None, :]
        ex, ey = (seg[:, 2] - seg[:, 0])[None, :], (seg[:, 3] - seg[:, 1])[None, :]
        rdx, rdy = dx[:, None], dy[:, None]
        denom = rdx * ey - rdy * ex
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((ax - x) * ey - (ay - y) * ex) / denom  # along the ray
            u = ((ax - x) * rdy - (ay - y) * rdx) / denom  # along the segment
        valid = (np.abs(denom) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
        t = np.where(valid, t, np.inf)
        nearest = np.argmin(t, axis=1)
        dist = t[np.arange(len(angles)), nearest]
        length = np.hypot(ex[0, nearest], ey[0, nearest])
        # the angle between the ray and the wall's normal: |sin| of the ray-to-wall angle
        cos_inc = np.abs(denom[np.arange(len(angles)), nearest]) / np.where(length > 0, length, 1.0)
        wall_inc = np.arccos(np.clip(cos_inc, 0.0, 1.0))
        closer = dist < best
        best = np.where(closer, dist, best)
        incidence = np.where(closer, wall_inc, incidence)
    for cx, cy, r in world.circle_array():
        fx, fy = x - cx, y - cy
        b = fx * dx + fy * dy
        c = fx * fx + fy * fy - r * r
        disc = b * b - c
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        valid = (disc >= 0) & (t > 1e-9)
        t = np.where(valid, t, np.inf)
        finite = np.where(valid, t, 0.0)
        hx, hy = x + finite * dx - cx, y + finite * dy - cy
        cos_inc = np.abs(hx * dx + hy * dy) / r
        closer = t < best
        best = np.where(closer, t, best)
        incidence = np.where(closer, np.arccos(np.clip(cos_inc, 0.0, 1.0)), incidence)
    best = np.where(best <= max_range, best, np.inf)
    return RayHits(best, incidence)


@dataclass
class MoveResult:
    """What one batch of half-steps did to the robot."""

    distance: float = 0.0  # mm driven (signed, forward positive)
    rotation: float = 0.0  # radians turned (CCW positive)
    blocked: bool = False  # stopped by a wall or obstacle
    stalled: bool = False  # step rate above the start-stop limit: no motion


class TrackedRobot:
    """The true pose of the robot and how half-steps move it."""

    def __init__(self, world: World, rng: np.random.Generator) -> None:
        self.world = world
        self.rng = rng
        self.pose = world.start
        self.move_id: int | None = None
        self.step_mm = STEP_MM * world.floor.step_scale
        self.glide = world.floor.glide_factor
        self.collisions = 0
        self.stalls = 0
        #: the closest the footprint (the collision circle) came to any surface, mm: 0 is contact
        self.closest_mm = max(0.0, world.clearance(self.pose.x, self.pose.y) - world.robot_radius)
        #: every contact: where, the heading, and where on the body it touched (bearing from the
        #: heading, degrees, + to the left) — what a sonar layout has to cover
        self.contacts: list[dict[str, float]] = []

    def new_move(self, move_id: int) -> None:
        """Draw this move's true step length and true glide factor (SPEC §5)."""
        floor = self.world.floor
        self.move_id = move_id
        self.step_mm = STEP_MM * floor.step_scale * (1.0 + self.rng.normal(0.0, floor.step_noise))
        self.glide = floor.glide_factor * (1.0 + self.rng.uniform(-floor.glide_spread, floor.glide_spread))

    def apply_steps(self, left: int, right: int, rate_hz: float, move_id: int) -> MoveResult:
        """Move by ``left``/``right`` half-steps (signed, + = that track forward) at ``rate_hz``."""
        if move_id != self.move_id:
            self.new_move(move_id)
        if left == 0 and right == 0:
            return MoveResult()
        if rate_hz > MAX_STEP_RATE_HZ * STALL_TOLERANCE:
            self.stalls += 1
            return MoveResult(stalled=True)
        distance = (left + right) / 2 * self.step_mm
        rotation = math.radians((right - left) / 2 / self.glide)
        return self._integrate(distance, rotation)

    def _integrate(self, distance: float, rotation: float) -> MoveResult:
        pieces = max(1, math.ceil(abs(distance) / 5.0), math.ceil(abs(math.degrees(rotation))))
        d_piece, r_piece = distance / pieces, rotation / pieces
        x, y, theta = self.pose.x, self.pose.y, self.pose.theta
        radius = self.world.robot_radius
        clearance = self.world.clearance(x, y)
        done = 0.0
        for _ in range(pieces):
            mid = theta + r_piece / 2
            nx, ny = x + d_piece * math.cos(mid), y + d_piece * math.sin(mid)
            if d_piece:
                new_clearance = self.world.clearance(nx, ny)
                if new_clearance < radius and new_clearance < clearance:
                    frac = self._touch(x, y, mid, d_piece, radius, clearance)
                    x, y = x + frac * d_piece * math.cos(mid), y + frac * d_piece * math.sin(mid)
                    theta += frac * r_piece
                    done += frac
                    self.pose = Pose(x, y, theta)
                    self.collisions += 1
                    self.closest_mm = 0.0
                    self._record_contact(x, y, theta, d_piece)
                    return MoveResult(done * d_piece, done * r_piece, blocked=True)
                clearance = new_clearance
                self.closest_mm = min(self.closest_mm, max(0.0, clearance - radius))
            x, y, theta = nx, ny, theta + r_piece
            done += 1
        self.pose = Pose(x, y, theta)
        return MoveResult(distance, rotation)

    def _record_contact(self, x: float, y: float, theta: float, step: float) -> None:
        touched = self.world.nearest_point(x, y)
        if touched is None:
            return
        bearing = math.degrees(
            math.remainder(math.atan2(touched[1] - y, touched[0] - x) - theta, 2 * math.pi)
        )
        self.contacts.append(
            {
                "x_mm": round(x, 1),
                "y_mm": round(y, 1),
                "heading_deg": round(math.degrees(theta) % 360.0, 1),
                "bearing_deg": round(bearing, 1),
                "reverse": step < 0,
            }
        )

    def _touch(
        self, x: float, y: float, heading: float, step: float, radius: float, clearance: float
    ) -> float:
        """How far (0..1) along a piece the robot gets before it touches (bisection, 0.1 mm)."""
        lo, hi = 0.0, 1.0
        while (hi - lo) * abs(step) > 0.1:
            mid = (lo + hi) / 2
            c = self.world.clearance(x + mid * step * math.cos(heading), y + mid * step * math.sin(heading))
            if c < radius and c < clearance:
                hi = mid
            else:
                lo = mid
        return lo
