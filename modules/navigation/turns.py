"""Explore 2's turns on the spot: each big one judged at rest by the fused heading and, where it
should have put a wall on the left, by the left sonar pair — then fixed, aligned or searched.

The floor's slip makes a turn ±10 %, and the filter needs the compass at rest to know: a turn of
``check_min_deg`` or more waits ``settle_ms`` at rest before :meth:`TurnJudging._judge` compares.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from modules.navigation.pilot import TURN_LEFT, TURN_RIGHT, Abort, Move, Outcome, Sensors


@dataclass
class TurnCheck:
    """A turn waiting to be judged at rest: by the heading it aims at (source, rad CCW; None: no
    goal) and, with ``align``, by the wall it should have put parallel on the left."""

    source: str | None
    goal: float | None
    fixes: int = 0
    settle_until: int | None = None
    align: bool = False
    searched: bool = False
    readings: list[tuple[int, int]] = field(default_factory=list)
    last_sweep: int | None = None
    sweeps_seen: int = 0


def wall_angle_deg(front_mm: float, rear_mm: float, baseline_mm: float) -> float:
    """The angle (degrees, positive: the wall falls away ahead) of a wall seen by two side sonars
    ``baseline_mm`` apart. Within ±15° of the normal both read the perpendicular distance; beyond,
    the nearest ray is the beam's edge, reading ``e / cos(|a| - 15°)`` — solved by bisection."""
    diff = front_mm - rear_mm

    def predicted(a: float) -> float:
        return baseline_mm * math.sin(a) / math.cos(max(0.0, abs(a) - math.radians(15.0)))

    lo, hi = -math.radians(70.0), math.radians(70.0)
    if diff <= predicted(lo):
        return math.degrees(lo)
    if diff >= predicted(hi):
        return math.degrees(hi)
    for _ in range(40):
        mid = (lo + hi) / 2.0
        if predicted(mid) < diff:
            lo = mid
        else:
            hi = mid
    return math.degrees((lo + hi) / 2.0)


class TurnJudging:
    """The turns of :class:`~modules.navigation.navigator.ExploreLeftWall` (a part of it, on its
    state: ``s``, ``layout``, ``check``, ``turn_errors``)."""

    def _turn(
        self, degrees: float, label: str, sensors: Sensors | None = None, align: bool = False
    ) -> list[Move]:
        """A turn on the spot by ``degrees`` (positive: left); nothing if under 2°. Turns of
        ``check_min_deg`` or more are judged afterwards by the fused heading (:meth:`_judge`);
        with ``align`` (the turn should put a wall on the left) by that wall when in view."""
        if abs(degrees) < 2.0:
            return []
        heading = self._heading(sensors) if sensors is not None else None
        if abs(degrees) >= self.s.check_min_deg and (heading is not None or align):
            goal = heading[1] + math.radians(degrees) if heading is not None else None
            self.check = TurnCheck(heading[0] if heading else None, goal, align=align)
        direction = TURN_LEFT if degrees > 0 else TURN_RIGHT
        return [Move(direction, round(abs(degrees)), self.s.speed_pct, label=label)]

    @staticmethod
    def _heading(sensors: Sensors) -> tuple[str, float] | None:
        """(source, heading rad CCW) — the filtered pose's, else the compass's (offset cancels out)."""
        if sensors.pose_filtered and sensors.pose is not None:
            return "filter", sensors.pose[2]
        if sensors.heading_cdeg is not None:
            return "compass", -math.radians(sensors.heading_cdeg / 100.0)
        return None

    def _judge(self, last: Outcome | None, sensors: Sensors) -> list[Move] | None:
        """While a turn is being judged: [] to wait at rest, a fixing turn, or None when done."""
        check = self.check
        assert check is not None
        if check.settle_until is None:
            check.settle_until = sensors.stamp_ms + self.s.settle_ms
        if sensors.sweep != check.last_sweep:
            check.last_sweep = sensors.sweep
            check.sweeps_seen += 1
            if check.sweeps_seen > 2:  # the first sweeps may have pinged while still turning
                lay = self.layout
                check.readings.append((sensors.distances[lay.left_front], sensors.distances[lay.left_rear]))
        if sensors.stamp_ms < check.settle_until:
            return []
        self.check = None
        angle = self._wall_on_left(check.readings) if check.align else None
        if angle is not None:
            aligned = self._align(check, angle, sensors)
            if aligned is not None:
                return aligned
        heading = self._heading(sensors)
        if heading is not None and check.goal is not None and heading[0] == check.source:
            error = math.degrees(math.remainder(check.goal - heading[1], 2 * math.pi))
            if check.fixes == 0:
                self.turn_errors.append(error)
            if abs(error) > self.s.turn_tolerance_deg and check.fixes < self.s.max_fixes:
                self.check = TurnCheck(
                    check.source, check.goal, check.fixes + 1, align=check.align, searched=check.searched
                )
                label = last.move.label if last is not None and last.move is not None else "fix"
                return [
                    Move(
                        TURN_LEFT if error > 0 else TURN_RIGHT,
                        max(1, round(abs(error))),
                        self.s.speed_pct,
                        label=label,
                    )
                ]
        if check.align and angle is None and not check.searched:
            return self._search(check, sensors)
        return None

    def _wall_on_left(self, readings: list[tuple[int, int]]) -> float | None:
        """The left wall's angle (degrees, positive: falling away ahead) from readings at rest;
        None unless both left sonars saw it on most sweeps."""
        seen = [(f, r) for f, r in readings if f <= self.s.align_cm and r <= self.s.align_cm]
        if len(seen) < max(3, len(readings) // 2):
            return None
        front = sum(f for f, _ in seen) / len(seen) * 10.0
        rear = sum(r for _, r in seen) / len(seen) * 10.0
        lay = self.layout.left
        return wall_angle_deg(front, rear, math.dist(lay.front_xy, lay.rear_xy))

    def _align(self, check: TurnCheck, angle: float, sensors: Sensors) -> list[Move] | None:
        """After a turn that should have put a wall on the left, the wall in view ``angle``° off
        parallel: turn parallel when off by more than the heading can be trusted for (after a
        search, down to the pair's own resolution). None: nothing to do by the wall."""
        s = self.s
        limit = s.align_min_deg if check.goal is not None and not check.searched else s.align_tolerance_deg
        if abs(angle) < limit or check.fixes > s.max_fixes:
            return None
        heading = self._heading(sensors)
        self.check = TurnCheck(
            heading[0] if heading else None, None, check.fixes + 1, align=True, searched=True
        )
        direction = TURN_LEFT if angle > 0 else TURN_RIGHT
        return [Move(direction, max(1, round(abs(angle))), s.speed_pct, label="align")]

    def _search(self, check: TurnCheck, sensors: Sensors) -> list[Move]:
        """The wall is not in view after the turn: a wall ahead means the turn was too short, none
        means too long — turn slowly until the left pair reads alike (``left_parallel``)."""
        s = self.s
        blocked = min(sensors.distances[i] for i in self.layout.front) <= s.front_stop_cm + 20
        heading = self._heading(sensors)
        self.check = TurnCheck(heading[0] if heading else None, None, check.fixes, align=True, searched=True)
        return [
            Move(
                TURN_RIGHT if blocked else TURN_LEFT,
                s.search_deg if blocked else s.search_deg // 2,
                s.search_speed_pct,
                abort=(Abort("left_parallel", s.align_cm, "NONE"),),
                label="search",
            )
        ]
