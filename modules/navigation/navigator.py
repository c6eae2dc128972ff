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
  outer corners (the wall lost) drive past, turn left and pick the wall up again; at the first
  wall the floor's step is gauged (face it, back off, drive up again: the filter's travel fit); one lap
  (back near the start, judged by the best pose) closes the outline. Then the islands the lap
  saw on its right are gone round, drives into the interior no path came near find the ones it
  could not see, and the robot drives back to its start pose (``completeness()`` says how it went).
* :class:`Calibrate` — the calibration run: a 360° turn, the compass tells the error, main sends
  RECALC_GLIDE_FACTOR.

The seed's strategies as it built them (``--algorithms main=seed``): :class:`SeedExploreAvoid`
(the turn aborts at the CLOSE area's edge), and Explore 2 as :class:`SeedCalibrated` round
:class:`SeedLeftWall` (the calibration run first, then plain labyrinth-rule wall following).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from modules.mapping.vectorgen import SonarLayout
from modules.navigation.base import CLOSE_CM, DIAGONAL_STOP_CM, NAV, Navigator
from modules.navigation.frontier import SeenGrid
from modules.navigation.frontier_visits import FrontierVisits
from modules.navigation.homing import ReturnHome, route_home
from modules.navigation.islands import IslandVisits, interior_goal, linked_groups
from modules.navigation.pilot import (
    BLOCKING_TRIGGERS,
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
from modules.navigation.turns import TurnCheck, TurnJudging, wall_angle_deg
from modules.navigation.wall_settings import WallSettings
from modules.units import pose_to_wire

__all__ = [
    "NAV",
    "Calibrate",
    "ExploreAvoid",
    "ExploreLeftWall",
    "Navigator",
    "SeedCalibrated",
    "SeedExploreAvoid",
    "SeedLeftWall",
    "TurnCheck",
    "WallSettings",
    "interior_goal",
    "linked_groups",
    "route_home",
    "wall_angle_deg",
]


class ExploreAvoid(Navigator):
    """Explore 1: drive until something is CLOSE, turn 90° toward the side with more room."""

    mode = 1
    #: the turn stops when a front sonar reads this near. Ours: half the CLOSE area's edge, so that
    #: the turn away from the wall the drive stopped at (front ≤ 12 cm) is not stopped at once
    turn_close_cm = CLOSE_CM // 2

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
                abort=(Abort("front_within", self.turn_close_cm, "CLOSE"),),
                label="turn",
            )
        ]


class ExploreLeftWall(TurnJudging, IslandVisits, FrontierVisits, ReturnHome, Navigator):
    """Explore 2: keep the wall on the left.

    Phases: ``find`` (drive until a wall blocks the way, turn right: it is on the left now),
    ``follow`` (segments along the wall, each begun with a correction from the last one's side
    readings; the front blocked: inner corner, turn right; the wall lost: ``outer``), ``outer``
    (drive on past the wall's end, turn left), ``reacquire`` (drive until the left sonar finds the
    wall again; none: turn left again — the end of a thin wall or a pillar). Every turn of 10° or
    more is judged by the fused heading after ``settle_ms`` at rest and corrected (the floor's
    slip makes a turn ±10 %; the filter needs the compass at rest to know).

    Its parts, each in a module of its own: the judged turns (:class:`TurnJudging`), the islands
    and the probes into the interior (:class:`IslandVisits`), the places left to explore
    (:class:`FrontierVisits`), the way home (:class:`ReturnHome`); the phases of wall following
    are here."""

    mode = 2

    def __init__(self, layout: SonarLayout, settings: WallSettings | None = None) -> None:
        super().__init__(layout)
        self.s = settings or WallSettings()
        self.phase = "find"
        self.follow_mm = 0
        self.lap_start: tuple[float, float, float] | None = None  # where following began, heading
        self.laps = 0
        self.lap_short_mm: float | None = None  # the lap's start lies this far ahead
        self.rotation = 0.0  # rad turned since following began (left positive)
        self.last_heading: float | None = None
        self.islands: list[tuple[float, float]] = []  # where laps round an island began
        self.outer_tries = 0
        self.corrections: list[float] = []
        self.check: TurnCheck | None = None
        self.last_follow: Outcome | None = None
        self.turn_errors: list[float] = []  # degrees each checked turn missed by (before fixes)
        self.sightings: list[tuple[float, float]] = []  # right-side echoes on the lap (world mm)
        self.path: list[tuple[float, float]] = []  # where the current lap went
        self.outer_path: list[tuple[float, float]] = []  # the room's lap (its walls lie outside)
        self.circled: list[list[tuple[float, float]]] = []  # the paths round islands visited
        self.target: tuple[float, float] | None = None  # the island being approached or circled
        self.visits = 0
        self.unreached: list[tuple[float, float]] = []  # targets an approach did not run into
        self.trail: list[tuple[float, float]] = []  # everywhere the robot went (seen from)
        self.probes = 0
        self.probe_goals: list[tuple[float, float]] = []  # interior goals driven to (or tried)
        self.seen: SeenGrid | None = None  # what the sonars saw (made at the first pose)
        self.frontier_goals: list[tuple[float, float]] = []
        self.frontier_follow = False  # following a wall found beyond a frontier (not an island)
        self.goto: list[tuple[float, float]] = []  # waypoints to a place left to explore
        self.goto_moves_left = 0  # on the way there, before the place is given up
        self.goto_replans = 0  # ways there planned again after a mapped wall blocked this one
        self.home: tuple[float, float, float] | None = None  # the pose the exploration began at
        self.home_reached = False
        self.detours = 0
        self.detouring = False
        self.route: list[tuple[float, float]] | None = None  # waypoints home, the start last
        self.done_note = ""
        self.alerts = 0  # ALERTs in a row, escapes between them not counting
        #: inner turns that hit ALERT since one last turned: each is backed off and turned again
        #: from there (driving on first would take the robot back to where the turn touched)
        self.inner_alerts = 0
        self.retry_inner = False
        self.gauged = False  # the first wall reached: the floor gauged there (or, out of view, never)
        self.gauge_begun = False  # the gauge's moves sent: anything after them goes on with the lap

    # -- the moves ----------------------------------------------------------------------------
    def _front_stop(self) -> tuple[Abort, ...]:
        """A wall straight ahead ends a move; the diagonal sonars only stop it when very close
        (they see the followed wall, and islands passing by)."""
        return (
            Abort("ahead_within", self.s.front_stop_cm, "CLOSE"),
            Abort("front_within", DIAGONAL_STOP_CM, "CLOSE"),
        )

    def _lost_limit(self) -> int:
        return self.s.wall_cm + self.s.lost_margin_cm

    def _segment(self) -> Move:
        s = self.s
        length = s.segment_mm
        if self.lap_short_mm is not None:  # the lap's start is just ahead: end the segment there
            length = max(100, min(length, round(self.lap_short_mm) + 50))
            self.lap_short_mm = None
        return Move(
            FORWARD,
            length,
            s.speed_pct,
            scan=True,
            abort=(*self._front_stop(), Abort("left_beyond", self._lost_limit(), "CORNER", s.lost_sweeps)),
            label="follow",
        )

    def _forward(self, mm: int, label: str, *extra: Abort) -> Move:
        return Move(FORWARD, mm, self.s.speed_pct, abort=(*self._front_stop(), *extra), label=label)

    def _correction(self, with_distance: bool) -> float:
        """Degrees to turn left so the next segment runs parallel at the wanted distance, from
        the left sonar's readings over the last follow segment."""
        last = self.last_follow
        if last is None:
            return 0.0
        fit = side_slope(last.samples, self.layout.left_front, self._lost_limit())
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

    def _left_front_sees(self, sensors: Sensors) -> bool:
        return sensors.distances[self.layout.left_front] <= self._lost_limit()

    # -- the strategy -------------------------------------------------------------------------
    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        self.steps += 1
        s = self.s
        label = last.move.label if last is not None and last.move is not None else ""
        if self.home is None and sensors.pose is not None:
            self.home = sensors.pose
        if label == "follow":
            self.follow_mm += max(0, last.driven_mm)
            self.last_follow = last
        if last is not None:
            self.trail += [pose[:2] for pose in last.poses if pose is not None]
            self._see(last)
        if last is not None and self.lap_start is not None:
            self._record(last, label)
        if last is not None and last.reason == REASON["ALERT"]:
            return self._escape_alert(label, alert_lock)
        if last is not None and not label.startswith("escape"):
            self.alerts = 0
        if label == "inner":
            self.inner_alerts = 0
        if self.retry_inner and label in ("back off", "escape back") and self.phase == "follow":
            self.retry_inner = False
            ran_into = last is not None and last.reason in (REASON["STALL"], REASON["COLLISION"])
            if not ran_into:  # a back-off that ran into something is handled as any collision
                return self._inner(sensors)
        # (the gauge's back-off, however it ended, goes up to its wall: phase "gauge" below)
        if (
            last is not None
            and last.reason in (REASON["STALL"], REASON["COLLISION"])
            and label != "gauge back"
        ):
            return self._back_away(last, sensors)
        if self.check is not None:
            judged = self._judge(last, sensors)
            if judged is not None:
                self.state = NAV["TURN"]
                return judged
            label = "turned"
        if self.phase in ("home", "home_turn"):  # no lap ends on the way home, whatever it passes
            blocked = last is not None and last.trigger in BLOCKING_TRIGGERS
            return self._homeward(label, blocked, sensors)
        self._count_rotation(sensors)
        budget = s.frontier_follow_mm if self.frontier_follow else s.island_budget_mm
        if self.target is not None and self.lap_start is not None and self.follow_mm > budget:
            self.note = (
                "followed a wall beyond the seen space"
                if self.frontier_follow
                else "gave up going round an island"
            )
            return self._next_island(sensors)
        if self._lap_done(sensors):
            if self.target is not None:  # round the island visited: on to the next one
                self.circled.append(self.path)
                self.note = "went round an island"
                return self._next_island(sensors)
            if self.rotation > math.pi and len(self.islands) < s.max_islands:
                # a lap turning left all round had its wall outside: an island — leave it
                self.islands.append(self.lap_start[:2] if self.lap_start else (0.0, 0.0))
                self.circled.append(self.path)
                self.lap_start, self.follow_mm, self.laps = None, 0, 0
                self.path, self.sightings = [], []
                self.phase, self.last_follow = "find", None
                self.state = NAV["TURN"]
                self.note = "left an island"
                return self._turn(-90, "leave", sensors) or [self._forward(s.find_mm, "find")]
            self.note = "lap closed"
            self.outer_path = self.path
            return self._next_island(sensors)
        blocked = last is not None and last.trigger in BLOCKING_TRIGGERS
        handler = {
            "probe": self._plan_probe,
            "goto": self._plan_goto,
            "approach": self._plan_approach,
            "find": self._plan_find,
            "outer": self._plan_outer,
            "reacquire": self._plan_reacquire,
            "gauge": self._plan_gauge,
        }.get(self.phase, self._plan_follow)
        return handler(last, sensors, label, blocked)

    def _escape_alert(self, label: str, alert_lock: int) -> list[Move]:
        """The last move ended in ALERT: the escape the pilot's lock allows, backing off too after
        ALERTs in a row or an inner turn that touched (it is turned again from there)."""
        s = self.s
        self.state = NAV["BACK_OFF"]
        self.note = "alert"
        self.check = None
        self.alerts += 1
        escape = self.escape(alert_lock if alert_lock != STOPPED else REVERSE)
        inner = label == "inner" and self.phase == "follow"
        self.inner_alerts += inner
        self.retry_inner = inner and self.inner_alerts <= s.inner_retries
        backs_off = self.alerts >= s.alerts_before_back_off or self.retry_inner
        if backs_off and escape[0].direction != REVERSE:
            # away from what alerted: on forwards when it is behind (the lock allows only forward)
            away = FORWARD if escape[0].direction == FORWARD else REVERSE
            escape.append(Move(away, s.alert_back_mm, s.speed_pct, label="back off"))
        return escape

    def _back_away(self, last: Outcome, sensors: Sensors) -> list[Move]:
        """The last move ran into something (a stall or a collision): back away and turn right."""
        s = self.s
        self.state = NAV["BACK_OFF"]
        if self.phase not in ("home", "home_turn"):  # on the way home: aim again after it
            self.phase = "follow"
        self.last_follow = None
        # away from what the move ran into: backwards after a forward move, else forwards
        away = FORWARD if last.move is not None and last.move.direction == REVERSE else REVERSE
        return [Move(away, 80, s.speed_pct, label="back off"), *self._turn(-30, "away", sensors)]

    def _plan_find(
        self, last: Outcome | None, sensors: Sensors, label: str, blocked: bool
    ) -> list[Move] | None:
        """Drive until a wall blocks the way, then put it on the left."""
        s = self.s
        self.state = NAV["ENTRY"]
        if label == "find" and (blocked or last.done):
            self.rotation = 0.0
            self.phase = "follow"
            self.state = NAV["TURN"]
            return self._turn(-90, "inner", sensors, align=True) or [self._segment()]
        if label not in ("face", "turned", "leave") and not self.islands:
            facing = self._face_nearest(sensors)
            if facing:
                return facing
        return [self._forward(s.find_mm, "find")]

    def _plan_outer(
        self, last: Outcome | None, sensors: Sensors, label: str, blocked: bool
    ) -> list[Move] | None:
        """The wall ended: drive past its end, then turn left."""
        s = self.s
        if label == "clear":
            if blocked:  # something ahead already: an inner corner after all
                self.phase = "follow"
                return self._inner(sensors)
            self.phase = "reacquire"
            self.state = NAV["TURN"]
            return self._turn(90, "outer", sensors) or [self._reacquire()]
        self.state = NAV["FOLLOW_WALL"]
        return [self._forward(s.clear_mm, "clear")]

    def _plan_reacquire(
        self, last: Outcome | None, sensors: Sensors, label: str, blocked: bool
    ) -> list[Move] | None:
        """Drive until the left sonar finds the wall again."""
        s = self.s
        if label == "reacquire":
            if last.trigger == "left_within":
                self.phase, self.outer_tries = "follow", 0
                self.state = NAV["FOLLOW_WALL"]
                return [self._segment()]
            if blocked:
                self.phase = "follow"
                return self._inner(sensors)
            self.outer_tries += 1  # no wall: the end of a thin wall or a pillar — go round it
            if self.outer_tries >= 3:
                self.phase, self.outer_tries = "find", 0
                return [self._forward(s.find_mm, "find")]
            self.state = NAV["TURN"]
            return self._turn(90, "outer", sensors) or [self._reacquire()]
        self.state = NAV["FOLLOW_WALL"]
        return [self._reacquire()]

    def _plan_gauge(
        self, last: Outcome | None, sensors: Sensors, label: str, blocked: bool
    ) -> list[Move] | None:
        """Facing the first wall: back off and drive up to it again."""
        s = self.s
        if label == "gauge back":  # stopped by something behind, seen or run into: up to the wall
            return [self._forward(s.gauge_mm, "gauge ahead")]
        if label == "gauge ahead" or self.gauge_begun:  # (or interrupted): on with the lap
            self.phase = "follow"
            self.state = NAV["TURN"]
            return self._turn(-90, "inner", sensors, align=True) or [self._segment()]
        self.gauge_begun = True
        self.state = NAV["ENTRY"]
        return self._gauge_moves()

    def _plan_follow(
        self, last: Outcome | None, sensors: Sensors, label: str, blocked: bool
    ) -> list[Move] | None:
        """Along the wall on the left, segment by segment (the lap begins at the first)."""
        s = self.s
        if not self.gauged and self.lap_start is None and self.target is None:
            self.gauged = True
            if s.gauge_mm > 0 and self._left_front_sees(sensors):
                self.phase = "gauge"
                self.state = NAV["TURN"]
                self.note = "gauging the floor"
                return self._turn(90, "gauge", sensors)
        if self.lap_start is None and sensors.pose is not None:
            self.lap_start = sensors.pose
            if self.target is not None:  # round an island: count from here (not the turn onto it)
                self.rotation = 0.0
        if label == "follow" and blocked:
            return self._inner(sensors)
        if label == "follow" and last.trigger == "left_beyond":
            self.phase, self.last_follow = "outer", None
            self.state = NAV["FOLLOW_WALL"]
            return [self._forward(s.clear_mm, "clear")]
        self.state = NAV["FOLLOW_WALL"]
        if not self._left_front_sees(sensors):
            self.phase, self.last_follow = "reacquire", None
            return [self._reacquire()]
        if label == "follow":
            turn = self._turn(self._correction(with_distance=True), "align", sensors)
            if self.check is not None:  # a big correction: judged before the segment
                return turn
            return [*turn, self._segment()]
        return [self._segment()]

    def completeness(self) -> dict[str, object]:
        """How complete the map is, as far as the robot can tell: the room's outline closed by a
        lap, islands found and gone round, probes into the interior, whether any of the interior
        is still out of every sonar's sight (``interior_seen``), the places left to explore after
        them that it drove to, and how many are left (walls seen but not mapped, frontiers)."""
        outline = len(self.outer_path) >= 3
        islands = [ring for ring in self.circled if len(ring) >= 3]
        unseen = None
        if outline:
            here = self.trail[-1] if self.trail else self.outer_path[0]
            unseen = interior_goal(self.outer_path, self._seen_from(), islands, here, self.s)
        return {
            "outline_closed": outline,
            "islands_found": len(self.circled),  # gone round, or lapped while looking for the room
            "islands_gone_round": len(self.circled) - len(self.islands),
            "probes": self.probes,
            "places_explored": len(self.frontier_goals),
            "places_left": self._places_left(),
            "interior_seen": outline and unseen is None,
            "returned_home": self.home_reached,
        }

    # -- wall following -----------------------------------------------------------------------
    def _gauge_moves(self) -> list[Move]:
        """Straight back from the wall ahead and up to it again: the front sonar's ranges on a wall
        met square on, for the filter's travel gauge (one run: the heading does not change)."""
        s = self.s
        return [
            Move(
                REVERSE,
                s.gauge_mm,
                s.speed_pct,
                abort=(Abort("rear_within", s.front_stop_cm, "CLOSE"),),
                label="gauge back",
            ),
            self._forward(s.gauge_mm, "gauge ahead"),
        ]

    def _inner(self, sensors: Sensors) -> list[Move]:
        """The way ahead is blocked: turn right so the wall ahead is on the left."""
        self.state = NAV["TURN"]
        angle = -90.0 + self._correction(with_distance=False)
        self.last_follow = None
        return self._turn(angle, "inner", sensors, align=True)

    def _reacquire(self) -> Move:
        return self._forward(
            self.s.reacquire_mm, "reacquire", Abort("left_within", self._lost_limit() - 5, "NONE")
        )

    def _face_nearest(self, sensors: Sensors) -> list[Move]:
        """At the start: turn toward the nearest echo around (most likely a wall of the room, not
        an island in it), unless a front sonar has it already."""
        d = sensors.distances
        nearest = min(range(len(d)), key=lambda i: d[i])
        if d[nearest] > self.s.face_cm or nearest in self.layout.front:
            return []
        return self._turn(math.degrees(self.layout.mounts[nearest].angle), "face", sensors)

    def _count_rotation(self, sensors: Sensors) -> None:
        """The heading turned through since following began (positive: left), for telling a
        room's wall (a lap turns right all round) from an island's (it turns left)."""
        if sensors.pose is None:
            return
        if self.last_heading is not None:
            self.rotation += math.remainder(sensors.pose[2] - self.last_heading, 2 * math.pi)
        self.last_heading = sensors.pose[2]

    def _lap_done(self, sensors: Sensors) -> bool:
        """Back where following began, along the same wall: heading the same way, and level with
        the start or past it (so the first wall is mapped up to where its first vector began).
        Round an island: once round it and a follow segment along its first face again."""
        if self.lap_start is None or sensors.pose is None:
            return False
        if self.target is not None:
            last = self.last_follow
            return (
                self.rotation >= math.radians(self.s.island_turn_deg)
                and last is not None
                and last.driven_mm >= self.s.island_last_mm
            )
        if self.follow_mm < self.s.lap_min_mm:
            return False
        if abs(self.rotation) >= math.radians(self.s.lap_fallback_deg):
            # turned once round and more without passing the start where a plan could see it
            # (outer corners all the way round a pillar: clear, turn, reacquire): round it is
            self.laps += 1
            self.follow_mm = 0
            return self.laps >= self.s.max_laps
        x0, y0, heading0 = self.lap_start
        x, y, heading = sensors.pose
        if math.hypot(x - x0, y - y0) > self.s.lap_radius_mm:
            return False
        if abs(math.remainder(heading - heading0, 2 * math.pi)) > math.radians(45.0):
            return False
        along = (x - x0) * math.cos(heading0) + (y - y0) * math.sin(heading0)
        if along < -self.s.lap_overlap_mm:
            self.lap_short_mm = -along
            return False
        self.laps += 1
        self.follow_mm = 0
        return self.laps >= self.s.max_laps


class Calibrate(Navigator):
    """The calibration run: turn 360°, compare the compass, correct the glide factor; then face
    the start heading again.

    The 360° turn runs at the old glide factor, so it ends off by the very error it measures
    (about 13° on the office floor), and the motor, which counts its steps, believes
    it faces the start heading. Left so, every move after it runs that far off and the map is
    turned by it (the seed's robot measured no error: its compass's values went unused). So the run turns
    back by the error at the new factor and — when no filter keeps the pose (``--algorithms
    copro=seed``) — tells the motor its heading again with SET_GLOBAL_POSITION; with the filter
    the compass already carries the heading and main's self-localisation corrects the motor."""

    mode = 3

    #: an error under this is not turned back (the motor's step is 0.3°, the compass's noise 0.5°)
    square_min_cdeg = 100

    def __init__(self, layout: SonarLayout, speed_pct: int = 50) -> None:
        super().__init__(layout)
        self.state = NAV["CALIBRATE"]
        self.speed_pct = speed_pct
        self.before: int | None = None
        self.before_pose: tuple[float, float, float] | None = None
        self.squaring = False
        self.result: dict[str, float] | None = None

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        self.steps += 1
        if self.before is None and last is None:
            self.before = sensors.heading_cdeg
            self.before_pose = None if sensors.pose_filtered else sensors.pose
            return [Move(TURN_LEFT, 360, self.speed_pct, label="calibrate")]
        if self.squaring:
            self.squaring = False
            self.state = NAV["DONE"]
            if self.before_pose is not None and sensors.pose is not None and last is not None and last.done:
                x, y, _ = sensors.pose  # a turn on the spot: where it stands, as it faced first
                self.commands.append(
                    ("motor", "SET_GLOBAL_POSITION", pose_to_wire(x, y, self.before_pose[2]))
                )
            return None
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
        if abs(error_cdeg) < self.square_min_cdeg:
            return None
        self.squaring = True
        self.state = NAV["CALIBRATE"]
        back = TURN_RIGHT if error_cdeg > 0 else TURN_LEFT  # overturned to the left: back to the right
        return [Move(back, int(abs(error_cdeg) / 100.0 + 0.5), self.speed_pct, label="square")]


# -- the seed's strategies (``--algorithms main=seed``) ---------------------------------------------
#: a locked-out plan this many times in a row: the strategy has no move the ALERT lock accepts
SEED_STUCK_REFUSALS = 4
NEAR_CM = 30  # the NEAR area's upper edge (seed §4.3.3: NEAR 10-30 cm)


def _refused(last: Outcome | None) -> bool:
    """The pilot refused the plan's first move: the ALERT lock allows another direction."""
    return last is not None and last.reason == REASON["ALERT"] and last.trigger == "locked"


#: ALERT outcomes in a row after which a seed strategy gives up: with any sonar aborting any
#: move, escapes included, a robot within 4 cm of a wall rocks between the two directions the
#: lock allows in turn, without end
SEED_STUCK_ALERTS = 12


class _SeedStuck:
    """Counts what ends a seed strategy: refused plans, or ALERT after ALERT."""

    def __init__(self) -> None:
        self.refusals = 0
        self.alerts = 0

    def stuck(self, last: Outcome | None) -> str:
        """Why the strategy must end now ("" if it may go on)."""
        self.refusals = self.refusals + 1 if _refused(last) else 0
        alert = last is not None and last.reason == REASON["ALERT"]
        self.alerts = self.alerts + 1 if alert else 0
        if self.refusals >= SEED_STUCK_REFUSALS:
            return "stuck: the ALERT lock refuses every move the strategy makes"
        if self.alerts >= SEED_STUCK_ALERTS:
            return f"stuck: {self.alerts} ALERTs in a row, every escape aborted by another sonar"
        return ""


class SeedExploreAvoid(ExploreAvoid):
    """Explore 1 as the seed's ``navigator_1`` (seed §4.3.6): the turn, too, aborts "bei
    Annaeherung im CLOSE-Bereich" — a front sonar at the CLOSE area's edge (12 cm). After a drive
    stopped there the turn stops at once; the robot nibbles round until the front reads beyond.

    With :class:`SeedPilot` an escape still in ALERT is aborted and locks the opposite of the
    escape: neither "turn back" nor "drive back" is accepted any more. The seed's automaton would
    plan refused moves forever; this one ends the run (``note``) after a few refusals in a row."""

    turn_close_cm = CLOSE_CM

    def __init__(self, layout: SonarLayout, drive_mm: int = 3000, speed_pct: int = 100) -> None:
        super().__init__(layout, drive_mm, speed_pct)
        self.ends = _SeedStuck()

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        stuck = self.ends.stuck(last)
        if stuck:
            self.state = NAV["DONE"]
            self.note = stuck
            return None
        return super().plan(last, sensors, alert_lock)


@dataclass
class SeedWallSettings:
    """The plain left-wall follower's distances: the seed's distance areas (seed §4.3.3)."""

    close_cm: int = CLOSE_CM  # a front sonar in the CLOSE area: the way ahead is blocked
    lost_cm: int = NEAR_CM  # the left front sonar beyond the NEAR area: the wall ended
    segment_mm: int = 3000  # one follow move, as long as Explore 1's drive
    find_mm: int = 3000
    clear_mm: int = 400  # past the wall's end by about the robot's length (38 cm) before turning
    reacquire_mm: int = 1000
    speed_pct: int = 100


class SeedLeftWall(Navigator):
    """Explore 2 as the seed's test strategy (seed §4.4): "ein einfaches Wall-Following ..., das
    versucht, immer der vom Roboter aus gesehenen linken Wand zu folgen. Im Grunde der
    Algorithmus zum Verlassen eines Labyrinths." The labyrinth rule with straight moves and 90°
    turns, nothing else: drive until blocked, turn right; follow (vectors on) until blocked (turn
    right) or the wall is lost (drive past its end, turn left, drive until the left sees a wall;
    none: turn left again). No course correction, no turn checks, no lap end (the seed's run
    went on until stopped), no islands, no return home."""

    mode = 2

    def __init__(self, layout: SonarLayout, settings: SeedWallSettings | None = None) -> None:
        super().__init__(layout)
        self.s = settings or SeedWallSettings()
        self.phase = "find"
        self.ends = _SeedStuck()

    def _blocked(self) -> Abort:
        return Abort("front_within", self.s.close_cm, "CLOSE")

    def _follow(self) -> list[Move]:
        s = self.s
        self.phase = "follow"
        self.state = NAV["FOLLOW_WALL"]
        lost = Abort("left_beyond", s.lost_cm, "CORNER")
        return [
            Move(FORWARD, s.segment_mm, s.speed_pct, scan=True, abort=(self._blocked(), lost), label="follow")
        ]

    def _right_turn(self) -> list[Move]:
        """Blocked ahead: turn right, the wall ahead is on the left now."""
        self.phase = "follow"
        self.state = NAV["TURN"]
        return [Move(TURN_RIGHT, 90, self.s.speed_pct, label="inner")]

    def _round_the_end(self, clear: bool) -> list[Move]:
        """The wall on the left ended: (past its end,) turn left, drive until the left sees one."""
        s = self.s
        self.phase = "reacquire"
        self.state = NAV["TURN"]
        found = Abort("left_within", s.lost_cm, "NONE")
        moves = (
            [Move(FORWARD, s.clear_mm, s.speed_pct, abort=(self._blocked(),), label="clear")] if clear else []
        )
        return [
            *moves,
            Move(TURN_LEFT, 90, s.speed_pct, label="outer"),
            Move(FORWARD, s.reacquire_mm, s.speed_pct, abort=(self._blocked(), found), label="reacquire"),
        ]

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        self.steps += 1
        s = self.s
        stuck = self.ends.stuck(last)
        if stuck:
            self.state = NAV["DONE"]
            self.note = stuck
            return None
        if last is not None and last.reason == REASON["ALERT"]:
            # seed §4.3.6: "Es ist dann Aufgabe des Navigators", the direction the lock allows
            self.state = NAV["BACK_OFF"]
            return self.escape(alert_lock if alert_lock != STOPPED else REVERSE)
        label = last.move.label if last is not None and last.move is not None else ""
        blocked = last is not None and (
            last.trigger == "front_within" or last.reason in (REASON["STALL"], REASON["COLLISION"])
        )
        if self.phase == "find":
            self.state = NAV["ENTRY"]
            if label == "find" and blocked:
                return self._right_turn()
            return [Move(FORWARD, s.find_mm, s.speed_pct, abort=(self._blocked(),), label="find")]
        if blocked:
            return self._right_turn()
        if self.phase == "reacquire" and label == "reacquire" and last is not None:
            if last.trigger == "left_within":
                return self._follow()
            return self._round_the_end(clear=False)  # no wall: the end of a thin wall, round it
        if label == "follow" and last is not None and last.trigger == "left_beyond":
            return self._round_the_end(clear=True)
        if self.phase == "reacquire" and label in ("clear", "outer"):  # a sequence cut short
            return self._round_the_end(clear=False)
        return self._follow()


class SeedCalibrated(Navigator):
    """A strategy begun with the calibration run, as the seed extended its test strategy (seed
    §4.4: "um eine Kalibrierungsfahrt erweitert. Sie versucht am Anfang den Gleitfaktor durch
    eine 360° Drehung zu bestimmen"): :class:`Calibrate` first, then ``strategy``."""

    def __init__(self, layout: SonarLayout, strategy: Navigator) -> None:
        super().__init__(layout)
        self.calibration: Calibrate | None = Calibrate(layout)
        self.strategy = strategy
        self.mode = strategy.mode
        self.state = NAV["CALIBRATE"]
        self.result: dict[str, float] | None = None
        self.calibration_steps = 0

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        calibration = self.calibration
        if calibration is not None:
            moves = calibration.plan(last, sensors, alert_lock)
            self.commands += calibration.commands
            calibration.commands.clear()
            self.steps = self.calibration_steps = calibration.steps
            self.state = calibration.state
            if moves is not None:
                return moves
            self.result, self.note, self.calibration = calibration.result, calibration.note, None
            last = None  # the calibration turn is no outcome of the strategy's
        strategy = self.strategy
        moves = strategy.plan(last, sensors, alert_lock)
        self.commands += strategy.commands
        strategy.commands.clear()
        self.steps = self.calibration_steps + strategy.steps
        self.state = strategy.state
        self.note = strategy.note or self.note
        return moves
