"""The navigators (seed §4.3.6): strategies as finite state machines that plan the pilot's moves.

Each :meth:`plan` call first handles how the pilot's last sequence ended (its abort), then
returns the next sequence of :class:`Move` s (or None when the strategy is finished) and sets
the next state — the seed's cooperative navigator/pilot alternation.

* :class:`ExploreAvoid` — Explore 1, the seed's pseudo code: DRIVE_FORWARD (on ALERT turn back a
  little; else drive forward, abort at CLOSE, generate vectors) → TURN (on ALERT drive back a
  little; else turn 90° toward the side with more room, abort at CLOSE) → DRIVE_FORWARD …
* :class:`ExploreLeftWall` — Explore 2, the seed's test strategy: follow the wall on the robot's
  left (labyrinth rule) with straight segments and turns on the spot. Ours: after every segment
  the course is corrected from the slope of the left sonar's readings over the distance driven
  (the angle to the wall) and the distance error; inner corners (the front blocked) turn right,
  outer corners (the wall lost) drive past, turn left and pick the wall up again; one lap
  (back near the start, judged by the best pose) ends the run.
* :class:`Calibrate` — the calibration run: a 360° turn, the compass tells the error, main sends
  RECALC_GLIDE_FACTOR.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from modules.common.pilot import (
    FORWARD,
    REASON,
    REVERSE,
    STOPPED,
    TURN_LEFT,
    TURN_RIGHT,
    Abort,
    Move,
    Outcome,
    Sensors,
    angle_of_slope,
    side_slope,
)
from modules.common.vectorgen import SonarLayout
from tokenring.protocol import default_protocol

NAV = default_protocol().enums["navigator"]
CLOSE_CM = 12  # the CLOSE area's upper edge
DIAGONAL_STOP_CM = 8  # the ±45° sonars stop a wall-following move only this close (passing a pillar)


class Navigator:
    """Base: the state (``navigator`` enum) and what main needs to know."""

    mode = 0

    def __init__(self, layout: SonarLayout) -> None:
        self.layout = layout
        self.state = NAV["ENTRY"]
        self.steps = 0
        self.commands: list[tuple[str, str, dict[str, int]]] = []  # extra commands for main to send
        self.note = ""

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        raise NotImplementedError

    @staticmethod
    def escape(alert_lock: int) -> list[Move]:
        """A small move in the only direction the pilot's ALERT lock allows."""
        if alert_lock in (TURN_LEFT, TURN_RIGHT):
            return [Move(alert_lock, 15, label="escape turn")]
        if alert_lock == FORWARD:
            return [Move(FORWARD, 40, label="escape forward")]
        return [Move(REVERSE, 60, label="escape back")]


class ExploreAvoid(Navigator):
    """Explore 1: drive until something is CLOSE, turn 90° toward the side with more room."""

    mode = 1

    def __init__(self, layout: SonarLayout, drive_mm: int = 3000, speed_pct: int = 100) -> None:
        super().__init__(layout)
        self.drive_mm = drive_mm
        self.speed_pct = speed_pct

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        self.steps += 1
        alert = last is not None and last.reason == REASON["ALERT"]
        if self.state == NAV["ENTRY"]:
            self.state = NAV["DRIVE_FORWARD"]
        if self.state == NAV["DRIVE_FORWARD"]:
            self.state = NAV["TURN"]
            if alert:
                # "turn back a little": the lock names the opposite of the turn that hit ALERT
                lock = alert_lock if alert_lock in (TURN_LEFT, TURN_RIGHT) else TURN_LEFT
                return [Move(lock, 15, self.speed_pct, label="turn back")]
            return [
                Move(
                    FORWARD,
                    self.drive_mm,
                    self.speed_pct,
                    scan=True,
                    abort=(Abort("front_within", CLOSE_CM, "CLOSE"),),
                    label="drive",
                )
            ]
        self.state = NAV["DRIVE_FORWARD"]
        if alert:
            return [Move(REVERSE, 50, self.speed_pct, label="back off")]
        d = sensors.distances
        lay = self.layout
        left = min(d[lay.left_front], d[lay.left_rear])
        right = min(d[lay.right_front], d[lay.right_rear])
        direction = TURN_LEFT if left > right else TURN_RIGHT
        return [
            Move(
                direction,
                90,
                self.speed_pct,
                abort=(Abort("front_within", CLOSE_CM // 2, "CLOSE"),),
                label="turn",
            )
        ]


@dataclass
class WallSettings:
    wall_cm: int = 30  # the distance to keep from the left wall (side sonar reading)
    front_stop_cm: int = 25  # an obstacle this near ahead ends a segment: inner corner
    lost_margin_cm: int = 25  # the left sonar reading this much over wall_cm: the wall ended
    segment_mm: int = 600
    find_mm: int = 5000
    reacquire_mm: int = 900
    clear_mm: int = 420  # drive on past an outer corner before turning left
    max_correction_deg: float = 20.0
    speed_pct: int = 100
    lap_min_mm: int = 5000  # driven along walls before a lap can end
    lap_radius_mm: float = 450.0
    max_laps: int = 1


class ExploreLeftWall(Navigator):
    """Explore 2: keep the wall on the left."""

    mode = 2

    def __init__(self, layout: SonarLayout, settings: WallSettings | None = None) -> None:
        super().__init__(layout)
        self.s = settings or WallSettings()
        self.phase = "find"
        self.follow_mm = 0
        self.lap_start: tuple[float, float] | None = None
        self.laps = 0
        self.outer_tries = 0
        self.corrections: list[float] = []

    # -- the moves ----------------------------------------------------------------------------
    def _front_stop(self) -> tuple[Abort, ...]:
        """A wall straight ahead ends a move; the diagonal sonars only stop it when very close
        (they see the followed wall, and islands passing by)."""
        return (
            Abort("ahead_within", self.s.front_stop_cm, "CLOSE"),
            Abort("front_within", DIAGONAL_STOP_CM, "CLOSE"),
        )

    def _segment(self) -> Move:
        s = self.s
        return Move(
            FORWARD,
            s.segment_mm,
            s.speed_pct,
            scan=True,
            abort=(*self._front_stop(), Abort("left_beyond", s.wall_cm + s.lost_margin_cm, "CORNER")),
            label="follow",
        )

    def _turn(self, degrees: float, label: str, sensors: Sensors | None = None) -> list[Move]:
        """A turn on the spot by ``degrees`` (positive: left); nothing if under 2°.

        Ours: with a heading to check against (the filter's, else the compass), the goal is kept
        and :meth:`_turn_fix` corrects what the floor's slip (±10 %) left over."""
        if abs(degrees) < 2.0:
            return []
        heading = self._heading(sensors) if sensors is not None else None
        self.turn_goal = None if heading is None else (heading[0], heading[1] + math.radians(degrees))
        self.turn_fixes = 0
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

    def _turn_fix(self, last: Outcome | None, sensors: Sensors) -> list[Move] | None:
        """A correcting turn after a turn that missed its goal by more than 2.5° (twice at most)."""
        goal = getattr(self, "turn_goal", None)
        if (
            goal is None
            or last is None
            or last.move is None
            or last.move.direction not in (TURN_LEFT, TURN_RIGHT)
        ):
            return None
        heading = self._heading(sensors)
        if heading is None or heading[0] != goal[0] or self.turn_fixes >= 2 or not last.done:
            self.turn_goal = None
            return None
        error = math.degrees(math.remainder(goal[1] - heading[1], 2 * math.pi))
        if abs(error) <= 2.5:
            self.turn_goal = None
            return None
        self.turn_fixes += 1
        direction = TURN_LEFT if error > 0 else TURN_RIGHT
        return [Move(direction, max(1, round(abs(error))), self.s.speed_pct, label=last.move.label)]

    def _correction(self, last: Outcome | None, with_distance: bool) -> float:
        """Degrees to turn left so the next segment runs parallel at the wanted distance."""
        if last is None or last.move is None or last.move.label != "follow":
            return 0.0
        fit = side_slope(last.samples, self.layout.left_front, self.s.wall_cm + self.s.lost_margin_cm)
        if fit is None:
            return 0.0
        slope, reading_mm = fit
        angle = angle_of_slope(slope)
        if with_distance:
            error_mm = reading_mm - self.s.wall_cm * 10.0
            angle += math.degrees(math.atan2(error_mm, 2.0 * self.s.segment_mm))
        angle = max(-self.s.max_correction_deg, min(self.s.max_correction_deg, angle))
        self.corrections.append(angle)
        return angle

    def _left_wall_seen(self, sensors: Sensors) -> bool:
        limit = self.s.wall_cm + self.s.lost_margin_cm
        d = sensors.distances
        return d[self.layout.left_front] <= limit and d[self.layout.left_rear] <= limit

    # -- the strategy -------------------------------------------------------------------------
    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        self.steps += 1
        s = self.s
        if last is not None and last.move is not None and last.move.label == "follow":
            self.follow_mm += max(0, last.driven_mm)
        if last is not None and last.reason == REASON["ALERT"]:
            self.state = NAV["BACK_OFF"]
            self.note = "alert"
            return self.escape(alert_lock if alert_lock != STOPPED else REVERSE)
        if last is not None and last.reason in (REASON["STALL"], REASON["COLLISION"]):
            self.state = NAV["BACK_OFF"]
            self.phase = "follow"
            return [Move(REVERSE, 80, s.speed_pct, label="back off"), *self._turn(-30, "away", sensors)]
        fix = self._turn_fix(last, sensors)
        if fix is not None:
            return fix
        if self._lap_done(sensors):
            self.state = NAV["DONE"]
            self.note = "lap closed"
            return None

        if self.phase == "find":  # drive until a wall blocks the way, then put it on the left
            self.state = NAV["ENTRY"]
            if (
                last is not None
                and last.move is not None
                and last.move.label == "find"
                and (last.trigger in ("ahead_within", "front_within") or last.done)
            ):
                self.phase = "follow"
                self.state = NAV["TURN"]
                return self._turn(-90, "inner", sensors)
            return [
                Move(
                    FORWARD,
                    s.find_mm,
                    s.speed_pct,
                    abort=self._front_stop(),  # a wall ahead, not an island passing by
                    label="find",
                )
            ]

        if self.phase == "outer":
            self.phase = "reacquire"
            self.state = NAV["TURN"]
            return [
                Move(FORWARD, s.clear_mm, s.speed_pct, abort=self._front_stop(), label="clear"),
                *self._turn(90, "outer", sensors),
            ]

        if self.phase == "reacquire":
            if last is not None and last.move is not None and last.move.label == "reacquire":
                if last.trigger == "left_within" or self._left_wall_seen(sensors):
                    self.phase = "follow"
                    self.outer_tries = 0
                elif last.trigger in ("ahead_within", "front_within"):
                    self.phase = "follow"
                    self.state = NAV["TURN"]
                    return self._turn(-90, "inner", sensors)
                else:  # no wall: the end of a thin wall or a pillar — go round it
                    self.outer_tries += 1
                    if self.outer_tries >= 3:
                        self.phase, self.outer_tries = "find", 0
                        return self.plan(None, sensors, alert_lock)
                    self.state = NAV["TURN"]
                    return self._turn(90, "outer", sensors)
            else:
                self.state = NAV["FOLLOW_WALL"]
                return [
                    Move(
                        FORWARD,
                        s.reacquire_mm,
                        s.speed_pct,
                        abort=(
                            *self._front_stop(),
                            Abort("left_within", s.wall_cm + s.lost_margin_cm - 5, "NONE"),
                        ),
                        label="reacquire",
                    )
                ]

        # phase follow
        if self.lap_start is None and sensors.pose is not None:
            self.lap_start = sensors.pose[:2]
        followed = last is not None and last.move is not None and last.move.label == "follow"
        if followed and last.trigger in ("ahead_within", "front_within"):
            self.state = NAV["TURN"]
            return self._turn(-90 + self._correction(last, with_distance=False), "inner", sensors)
        if followed and last.trigger == "left_beyond":
            self.phase = "outer"
            return self.plan(None, sensors, alert_lock)
        self.state = NAV["FOLLOW_WALL"]
        if not self._left_wall_seen(sensors) and not followed:
            self.phase = "reacquire"
            return self.plan(None, sensors, alert_lock)
        return [*self._turn(self._correction(last, with_distance=True), "align", sensors), self._segment()]

    def _lap_done(self, sensors: Sensors) -> bool:
        if self.lap_start is None or sensors.pose is None or self.follow_mm < self.s.lap_min_mm:
            return False
        if math.dist(self.lap_start, sensors.pose[:2]) > self.s.lap_radius_mm:
            return False
        self.laps += 1
        self.follow_mm = 0
        return self.laps >= self.s.max_laps


class Calibrate(Navigator):
    """The calibration run: turn 360°, compare the compass, correct the glide factor."""

    mode = 3

    def __init__(self, layout: SonarLayout, speed_pct: int = 50) -> None:
        super().__init__(layout)
        self.state = NAV["CALIBRATE"]
        self.speed_pct = speed_pct
        self.before: int | None = None
        self.result: dict[str, float] | None = None

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        self.steps += 1
        if self.before is None and last is None:
            self.before = sensors.heading_cdeg
            return [Move(TURN_LEFT, 360, self.speed_pct, label="calibrate")]
        self.state = NAV["DONE"]
        if last is None or not last.done or self.before is None or sensors.heading_cdeg is None:
            self.note = "calibration needs a completed turn and a compass"
            return None
        # a left (counter-clockwise) turn lowers the clockwise compass heading: after 360° + e
        # it reads before - e
        error_cdeg = (self.before - sensors.heading_cdeg + 18000) % 36000 - 18000
        self.result = {"error_deg": error_cdeg / 100.0}
        self.commands.append(
            ("motor", "RECALC_GLIDE_FACTOR", {"target_deg": 360, "error_cdeg": int(error_cdeg)})
        )
        return None
