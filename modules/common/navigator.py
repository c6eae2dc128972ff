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
from dataclasses import dataclass, field

import numpy as np

from modules.common.frontier import SeenGrid
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
from modules.common.units import pose_to_wire
from modules.common.vectorgen import SonarLayout
from modules.description.robot import SONAR_MOUNTS, SonarMount, sonar_world_pose
from tokenring import default_protocol

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


@dataclass
class WallSettings:
    wall_cm: int = 30  # the distance to keep from the left wall (side sonar reading)
    front_stop_cm: int = 25  # an obstacle this near ahead ends a segment: inner corner
    lost_margin_cm: int = 25  # the left sonar reading this much over wall_cm: the wall ended
    lost_sweeps: int = 2  # ... on this many sweeps in a row (one dropout is no corner)
    segment_mm: int = 600
    find_mm: int = 5000
    face_cm: int = 150  # at the start, an echo this near (not ahead) is turned to before driving
    reacquire_mm: int = 900
    clear_mm: int = 400  # drive on past an outer corner before turning left
    max_correction_deg: float = 15.0
    speed_pct: int = 100
    #: the floor's step length, gauged once at the first wall: turned to face it square on (the
    #: wall was just put parallel on the left), back off this far and drive up to it again. The
    #: filter's travel gauge fits the front sonar's ranges of the two moves; without it the lap's
    #: walls are drawn on an unmeasured step (1 % long floor: 60 mm at 6 m). 0: no gauging
    gauge_mm: int = 800
    #: ALERTs in a row with no other move finished between: the escape the lock allows backs
    #: off too (a turn with the nose at a wall's end touches it whichever way it goes first)
    alerts_before_back_off: int = 2
    alert_back_mm: int = 80
    #: an inner turn that hit ALERT (its nose at the corner's end) is backed off and turned again,
    #: this many times in a row; after that the escapes go on as for any ALERT
    inner_retries: int = 4
    lap_min_mm: int = 2500  # driven along walls before a lap can end
    lap_radius_mm: float = 450.0
    lap_overlap_mm: float = 0.0  # a lap ends this far short of its start at the latest
    max_laps: int = 1
    lap_fallback_deg: float = 630.0  # turned this far since following began: round it is, for sure
    max_islands: int = 3  # laps round an island (turning left all round) before giving up
    settle_ms: int = 1200  # at rest after a turn before it is judged by the fused heading
    check_min_deg: float = 10.0  # turns at least this big are checked (smaller ones slip < 1°)
    turn_tolerance_deg: float = 1.5
    max_fixes: int = 2
    align_cm: int = 60  # both left sonars this near: the wall on the left is in view for aligning
    align_min_deg: float = 6.0  # a wall this far off parallel after a turn is aligned by the sonars
    align_tolerance_deg: float = 2.5  # ... down to this (the pair's baseline is only 16 cm)
    search_deg: int = 120  # a turn looking for the wall to become parallel on the left, at most
    search_speed_pct: int = 40  # slow: the pair reads every 120 ms
    # free-standing obstacles: after the lap, go round what the right side saw inside it
    visit_islands: int = 3  # at most this many, nearest first (0: the lap ends the run)
    #: a right-side reading this near on a follow segment marks an obstacle. Not farther: going
    #: round the slanted room's round obstacle (1.0-1.3 m from the lap) with straight segments and
    #: 90° turns mapped junk on the ring (coverage/precision 85/85 and 60/62 % against 90/100 and
    #: 81/90 % without); an island with flat faces near the lap (the office pillar) is the case it serves
    sighting_cm: int = 90
    sighting_link_mm: float = 350.0  # sightings this near each other belong to one obstacle
    sighting_min: int = 8  # an obstacle needs this many sightings (one dropout is none)
    inside_margin_mm: float = 150.0  # ... lying this far inside the lap's path (the room's walls lie outside)
    #: sightings inside or this near the path round an island visited were of that island (a path
    #: mapped a few cm off left some of them outside it: a second visit mapped junk on the ring)
    circled_margin_mm: float = 700.0
    #: round an island: turned left this much (once round and onto the first face again, so that
    #: its corner with the last face closes) and a follow segment this long on that face
    island_turn_deg: float = 405.0
    island_last_mm: int = 150
    island_budget_mm: int = 5000  # driven along it without closing the lap: give up
    # the interior: after the lap and the islands it showed, drive through what no sonar came
    # near (a pillar 1.8 m from every wall is out of the lap's sight), up to ``max_probes`` drives
    max_probes: int = 8
    probe_cell_mm: float = 250.0  # the interior's grid
    probe_seen_mm: float = 900.0  # a cell this near a path driven counts as seen (sighting_cm)
    # what the lap cut off: after the probes, drive to where the space the sonars saw ends (a
    # frontier, :mod:`modules.common.frontier`) and follow the wall found there, this far
    max_frontiers: int = 6
    frontier_follow_mm: int = 4000
    frontier_tried_mm: float = 700.0  # a frontier this near one driven to is not tried again
    frontier_beyond_mm: float = 1000.0  # ... driven on past it into the unseen until blocked
    route_clearance_mm: float = 250.0  # the way there keeps this far from every echo
    frontier_arrived_mm: float = 600.0  # blocked this near the place: there (follow what blocks)
    #: moves on the way there at most: this many, and 3 more for each waypoint (aim, check, drive)
    goto_moves: int = 12
    #: a wall mapped already blocked the way short of the place: plan it again this often
    goto_replans: int = 2
    # done: back to where the exploration began, facing as it did then
    return_home: bool = True
    home_tolerance_mm: float = 200.0
    home_detours: int = 4  # something in the way home: turn right, drive on, aim again; this often
    detour_mm: int = 500
    #: the way home retraces the trail, cut short wherever a straight line stays this near it
    #: (the robot's centre drove there; the body is 188 mm out, the followed wall 300 mm away)
    home_corridor_mm: float = 100.0
    route_spacing_mm: float = 50.0  # the trail's points this far apart for the route
    waypoint_tolerance_mm: float = 120.0  # a waypoint on the way home this near is reached


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


class ExploreLeftWall(Navigator):
    """Explore 2: keep the wall on the left.

    Phases: ``find`` (drive until a wall blocks the way, turn right: it is on the left now),
    ``follow`` (segments along the wall, each begun with a correction from the last one's side
    readings; the front blocked: inner corner, turn right; the wall lost: ``outer``), ``outer``
    (drive on past the wall's end, turn left), ``reacquire`` (drive until the left sonar finds the
    wall again; none: turn left again — the end of a thin wall or a pillar). Every turn of 10° or
    more is judged by the fused heading after ``settle_ms`` at rest and corrected (the floor's
    slip makes a turn ±10 %; the filter needs the compass at rest to know)."""

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
            self.state = NAV["BACK_OFF"]
            if self.phase not in ("home", "home_turn"):  # on the way home: aim again after it
                self.phase = "follow"
            self.last_follow = None
            # away from what the move ran into: backwards after a forward move, else forwards
            away = FORWARD if last.move is not None and last.move.direction == REVERSE else REVERSE
            return [Move(away, 80, s.speed_pct, label="back off"), *self._turn(-30, "away", sensors)]
        if self.check is not None:
            judged = self._judge(last, sensors)
            if judged is not None:
                self.state = NAV["TURN"]
                return judged
            label = "turned"
        if self.phase in ("home", "home_turn"):  # no lap ends on the way home, whatever it passes
            blocked = last is not None and last.trigger in ("ahead_within", "front_within")
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
        blocked = last is not None and last.trigger in ("ahead_within", "front_within")

        if self.phase == "probe":  # a drive into the interior: something in the way is an island
            if label == "probe":
                if blocked and self._island_ahead(sensors):
                    self.target = self.probe_goals[-1]
                    self.visits += 1
                    self.note = "found an island inside"
                    self.commands.append(("copro", "FLUSH", {}))
                    return self._onto_island(sensors)
                return self._next_island(sensors)
            self.state = NAV["ENTRY"]
            return [self._probe_move(sensors)]

        if self.phase == "goto":  # the way to a place left to explore, through space seen free
            if label == "goto" and blocked:
                if self._known_ahead(sensors):  # a wall mapped already: nothing new there
                    replanned = self._replan_goto(sensors)
                    return replanned if replanned is not None else self._next_island(sensors)
                return self._onto_island(sensors)  # there, or a wall nobody followed: follow it
            return self._goto_next(sensors)

        if self.phase == "approach":  # drive to the island chosen until it blocks the way
            if label == "approach":
                if blocked and self.frontier_follow and self._known_ahead(sensors):
                    return self._next_island(sensors)  # a wall mapped already: nothing new there
                if blocked:  # it is ahead: put it on the left and go round it
                    return self._onto_island(sensors)
                assert self.target is not None
                if not self.frontier_follow:
                    self.unreached.append(self.target)  # missed it (or it was not there)
                return self._next_island(sensors)
            self.state = NAV["ENTRY"]
            return [self._approach(sensors)]

        if self.phase == "find":  # drive until a wall blocks the way, then put it on the left
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

        if self.phase == "outer":  # the wall ended: drive past its end, then turn left
            if label == "clear":
                if blocked:  # something ahead already: an inner corner after all
                    self.phase = "follow"
                    return self._inner(sensors)
                self.phase = "reacquire"
                self.state = NAV["TURN"]
                return self._turn(90, "outer", sensors) or [self._reacquire()]
            self.state = NAV["FOLLOW_WALL"]
            return [self._forward(s.clear_mm, "clear")]

        if self.phase == "reacquire":  # drive until the left sonar finds the wall again
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

        if self.phase == "gauge":  # facing the first wall: back off and drive up to it again
            if label == "gauge back":  # stopped by something behind, seen or run into: up to the wall
                return [self._forward(s.gauge_mm, "gauge ahead")]
            if label == "gauge ahead" or self.gauge_begun:  # (or interrupted): on with the lap
                self.phase = "follow"
                self.state = NAV["TURN"]
                return self._turn(-90, "inner", sensors, align=True) or [self._segment()]
            self.gauge_begun = True
            self.state = NAV["ENTRY"]
            return self._gauge_moves()

        # phase follow
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

    # -- islands: free-standing obstacles seen on the right during the lap ---------------------
    def _record(self, last: Outcome, label: str) -> None:
        """The lap's path, and on the room's lap the right side's echoes of follow segments
        (on a probe into the interior, every sonar's)."""
        lay = self.layout
        for (_, distances), pose in zip(last.samples, last.poses, strict=False):
            if pose is None:
                continue
            self.path.append(pose[:2])
            if label == "probe":
                self.sightings += [
                    sonar_point(pose, i, distances[i] * 10.0, lay.mounts)
                    for i in range(len(distances))
                    if distances[i] <= self.s.sighting_cm
                ]
                continue
            if label != "follow" or self.target is not None:
                continue
            for index, which in ((lay.right_front, "front"), (lay.right_rear, "rear")):
                if distances[index] <= self.s.sighting_cm:
                    self.sightings.append(lay.right.point(pose, which, distances[index] * 10.0))

    def _islands(self) -> list[tuple[float, float, int]]:
        """Obstacles seen on the right inside the room's lap and not yet visited: (x, y, sightings)
        — groups of sightings linked by ``sighting_link_mm``, their centroids."""
        s = self.s
        outer = self.outer_path
        if len(outer) < 3:
            return []
        points = [
            p
            for p in self.sightings
            if point_in_polygon(p, outer)
            and distance_to_path(p, outer) >= s.inside_margin_mm
            and not any(
                point_in_polygon(p, ring) or distance_to_path(p, ring) < s.circled_margin_mm
                for ring in self.circled
                if len(ring) >= 3
            )
        ]
        found = []
        for group in linked_groups(points, s.sighting_link_mm):
            if len(group) < s.sighting_min:
                continue
            cx = sum(p[0] for p in group) / len(group)
            cy = sum(p[1] for p in group) / len(group)
            if all(math.dist((cx, cy), u) > s.sighting_link_mm for u in self.unreached):
                found.append((cx, cy, len(group)))
        return found

    def _next_island(self, sensors: Sensors) -> list[Move] | None:
        """After a lap: turn toward the nearest island not yet visited, or end the run."""
        s = self.s
        self.target, self.frontier_follow = None, False
        islands = self._islands() if self.visits < s.visit_islands and sensors.pose is not None else []
        if not islands:
            probe = self._next_probe(sensors)
            if probe is not None:
                return probe
            frontier = self._next_frontier(sensors)
            if frontier is not None:
                return frontier
            gone_round = len(self.circled) - len(self.islands)
            self.done_note = f"lap closed, {gone_round} island(s) gone round" if self.visits else "lap closed"
            self.note = self.done_note
            if s.return_home and self.home is not None and sensors.pose is not None:
                self.phase, self.last_follow, self.target = "home", None, None
                return self._go_home(sensors)
            self.state = NAV["DONE"]
            return None
        x, y, heading = sensors.pose
        tx, ty, _ = min(islands, key=lambda i: math.dist((x, y), i[:2]))
        self.target = (tx, ty)
        self.path = []
        self.visits += 1
        self.phase, self.last_follow = "approach", None
        self.commands.append(("copro", "FLUSH", {}))  # the room's last wall is not the island's neighbour
        self.state = NAV["TURN"]
        bearing = math.degrees(math.remainder(math.atan2(ty - y, tx - x) - heading, 2 * math.pi))
        return self._turn(bearing, "aim", sensors) or [self._approach(sensors)]

    def _next_probe(self, sensors: Sensors) -> list[Move] | None:
        """Turn toward the interior's largest stretch no path came near, or None: all seen."""
        s = self.s
        if self.probes >= s.max_probes or sensors.pose is None or len(self.outer_path) < 3:
            return None
        islands = [ring for ring in self.circled if len(ring) >= 3]
        goal = interior_goal(self.outer_path, self._seen_from(), islands, sensors.pose[:2], s)
        if goal is None:
            return None
        self.probes += 1
        self.probe_goals.append(goal)
        self.phase, self.last_follow = "probe", None
        x, y, heading = sensors.pose
        self.state = NAV["TURN"]
        self.note = f"probing the interior ({self.probes})"
        bearing = math.degrees(math.remainder(math.atan2(goal[1] - y, goal[0] - x) - heading, 2 * math.pi))
        return self._turn(bearing, "aim", sensors) or [self._probe_move(sensors)]

    def _see(self, last: Outcome) -> None:
        """Every sweep of the last moves into the grid of what the sonars saw."""
        lay = self.layout
        scanning = last.move is not None and last.move.scan
        sides = (lay.left_front, lay.left_rear, lay.right_front, lay.right_rear)
        before: tuple[float, float, float] | None = None
        for (_, distances), pose in zip(last.samples, last.poses, strict=False):
            if pose is None:
                continue
            if self.seen is None:
                self.seen = SeenGrid(pose[:2], mounts=lay.mounts)
            straight = before is not None and abs(math.remainder(pose[2] - before[2], 2 * math.pi)) < 0.06
            self.seen.add(pose, distances, sides if scanning and straight else ())
            before = pose

    def _next_frontier(self, sensors: Sensors) -> list[Move] | None:
        """Set off for the nearest place left to explore not tried yet — a wall seen but not
        mapped, else a frontier — along a way through space seen free; None: none left, or
        ``max_frontiers`` tried (one with no known way there counts). What blocks the way there
        is followed as an island is, for ``frontier_follow_mm``, unless it is mapped already."""
        s = self.s
        if len(self.frontier_goals) >= s.max_frontiers or sensors.pose is None or self.seen is None:
            return None
        here = sensors.pose[:2]
        for goals in self._untried_places():  # walls first: the map
            for goal in sorted(goals, key=lambda g: math.dist(here, g)):
                self.frontier_goals.append(goal)
                route = self.seen.route(here, goal, s.route_clearance_mm)
                if route is not None and len(self.frontier_goals) <= s.max_frontiers:
                    self.target, self.frontier_follow = goal, True
                    self._set_way(route)
                    self.lap_start, self.follow_mm, self.goto_replans = None, 0, 0
                    self.path = []
                    self.phase, self.last_follow = "goto", None
                    self.commands.append(("copro", "FLUSH", {}))
                    self.note = f"to a place left to explore ({len(self.frontier_goals)})"
                    return self._goto_next(sensors)
        return None

    def _goto_next(self, sensors: Sensors) -> list[Move] | None:
        """Aim at the next waypoint on the way to the place left to explore and drive there;
        past the last one, aim at the place itself and drive on until something blocks the way."""
        s = self.s
        assert self.target is not None
        if sensors.pose is None:
            return self._next_island(sensors)
        here = sensors.pose[:2]
        while self.goto and math.dist(here, self.goto[0]) <= s.waypoint_tolerance_mm:
            self.goto.pop(0)
        self.goto_moves_left -= 1
        if self.goto_moves_left < 0:
            return self._next_island(sensors)
        x, y, heading = sensors.pose
        tx, ty = self.goto[0] if self.goto else self.target
        bearing = math.degrees(math.remainder(math.atan2(ty - y, tx - x) - heading, 2 * math.pi))
        self.state = NAV["ENTRY"]
        if not self.goto:
            self.phase = "approach"
            return self._turn(bearing, "aim", sensors) or [self._approach(sensors)]
        return self._turn(bearing, "aim", sensors) or [
            self._forward(max(50, round(math.dist(here, (tx, ty)))), "goto")
        ]

    def _set_way(self, route: list[tuple[float, float]]) -> None:
        """The waypoints to the place, and the moves allowed to get there (3 per waypoint)."""
        self.goto = route
        self.goto_moves_left = self.s.goto_moves + 3 * len(route)

    def _replan_goto(self, sensors: Sensors) -> list[Move] | None:
        """A mapped wall blocked the way short of the place: plan the way again from here, the
        echo that blocked it now on the grid (a partition's end the first plan cut past), up to
        ``goto_replans`` times; None: at the place already, out of replans, or no way known."""
        s = self.s
        if sensors.pose is None or self.seen is None or self.target is None:
            return None
        here = sensors.pose[:2]
        if self.goto_replans >= s.goto_replans or math.dist(here, self.target) <= s.frontier_arrived_mm:
            return None
        route = self.seen.route(here, self.target, s.route_clearance_mm)
        if route is None:
            return None
        self.goto_replans += 1
        self._set_way(route)
        self.note = f"to a place left to explore ({len(self.frontier_goals)}), another way"
        return self._goto_next(sensors)

    def _untried_places(self) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
        """The places left to explore not tried yet: walls seen but not mapped, and frontiers
        farther than ``probe_seen_mm`` from every path (nearer ones the probes count as seen: an
        empty room's middle has no echo to show it free)."""
        if self.seen is None:
            return [], []
        s = self.s
        trail = np.asarray(self._seen_from(), dtype=float)
        far = [f for f in self.seen.frontiers() if np.hypot(*(trail - (f.x, f.y)).T).min() > s.probe_seen_mm]
        walls, frontiers = (
            [
                (f.x, f.y)
                for f in found
                if all(math.dist((f.x, f.y), g) > s.frontier_tried_mm for g in self.frontier_goals)
            ]
            for found in (self.seen.unmapped_walls(), far)
        )
        return walls, frontiers

    def _places_left(self) -> int:
        """Places left to explore that :meth:`_next_frontier` would still go to."""
        walls, frontiers = self._untried_places()
        return len(walls) + len(frontiers)

    def _known_ahead(self, sensors: Sensors) -> bool:
        """What blocks the way lies on a wall mapped already (a side sonar followed it), away
        from the place left to explore (its unmapped stretch may begin next to a mapped one)."""
        if sensors.pose is None or self.seen is None or self.target is None:
            return False
        point = self._point_ahead(sensors)
        if math.dist(point, self.target) <= self.s.frontier_arrived_mm:
            return False
        return self.seen.mapped_near(point)

    # -- home: back to the start pose when done -------------------------------------------------
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

    def _seen_from(self) -> list[tuple[float, float]]:
        """Where the sonars looked from: the trail (every few cm is plenty) and the probes' goals
        (one that could not be reached is not tried again)."""
        return self.trail[:: max(1, len(self.trail) // 4000)] + self.probe_goals

    def _probe_move(self, sensors: Sensors) -> Move:
        goal = self.probe_goals[-1]
        distance = math.dist(sensors.pose[:2], goal) if sensors.pose is not None else self.s.find_mm
        return self._forward(max(100, round(distance)), "probe")

    def _island_ahead(self, sensors: Sensors) -> bool:
        """What stopped a probe lies inside the room's lap, away from its walls and the islands
        gone round: a free-standing obstacle nobody saw yet."""
        if sensors.pose is None:
            return False
        point = self._point_ahead(sensors)
        outer = self.outer_path
        return (
            point_in_polygon(point, outer)
            and distance_to_path(point, outer) >= self.s.inside_margin_mm
            and not any(
                point_in_polygon(point, ring) or distance_to_path(point, ring) < self.s.inside_margin_mm
                for ring in self.circled
                if len(ring) >= 3
            )
        )

    def _point_ahead(self, sensors: Sensors) -> tuple[float, float]:
        """Where the nearest echo of the front sonars came from (the pose known)."""
        assert sensors.pose is not None
        index = min(self.layout.front, key=lambda i: sensors.distances[i])
        return sonar_point(sensors.pose, index, sensors.distances[index] * 10.0, self.layout.mounts)

    def _onto_island(self, sensors: Sensors) -> list[Move]:
        """An island blocks the way: turn so it is on the left and follow it, a lap of its own."""
        self.rotation, self.follow_mm, self.laps = 0.0, 0, 0
        self.lap_start, self.path = None, []
        self.phase = "follow"
        self.state = NAV["TURN"]
        return self._turn(-90, "inner", sensors, align=True) or [self._segment()]

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

    def _approach(self, sensors: Sensors) -> Move:
        assert self.target is not None
        distance = math.dist(sensors.pose[:2], self.target) if sensors.pose is not None else self.s.find_mm
        beyond = self.s.frontier_beyond_mm if self.frontier_follow else 300.0
        return self._forward(round(distance + beyond), "approach")

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


def sonar_point(
    pose: tuple[float, float, float],
    index: int,
    distance_mm: float,
    mounts: tuple[SonarMount, ...] = SONAR_MOUNTS,
) -> tuple[float, float]:
    """The world point a reading of sonar ``index`` (on ``mounts``) marks, the robot at ``pose``."""
    sx, sy, direction = sonar_world_pose(pose[0], pose[1], pose[2], index, mounts)
    return (sx + distance_mm * math.cos(direction), sy + distance_mm * math.sin(direction))


def interior_goal(
    outer: list[tuple[float, float]],
    seen_from: list[tuple[float, float]],
    islands: list[list[tuple[float, float]]],
    here: tuple[float, float],
    s: WallSettings,
) -> tuple[float, float] | None:
    """Where to drive next to see the interior: the cell inside the room's lap with the most
    unseen cells around it (nearer ones first among equals), or None when every cell lies within
    ``probe_seen_mm`` of a path driven. Cells inside an island gone round do not count."""
    poly = np.asarray(outer, dtype=float)
    step = s.probe_cell_mm
    (x0, y0), (x1, y1) = poly.min(axis=0), poly.max(axis=0)
    gx, gy = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    cells = np.column_stack([gx.ravel(), gy.ravel()])
    inside = _inside(cells, poly)
    for ring in islands:
        inside &= ~_inside(cells, np.asarray(ring, dtype=float))
    cells = cells[inside]
    if len(cells) == 0:
        return None
    trail = np.asarray(seen_from or [here], dtype=float)
    near = np.full(len(cells), np.inf)
    for chunk in range(0, len(trail), 500):
        part = trail[chunk : chunk + 500]
        near = np.minimum(near, np.sqrt(((cells[:, None, :] - part[None, :, :]) ** 2).sum(-1)).min(axis=1))
    unseen = cells[near > s.probe_seen_mm]
    if len(unseen) == 0:
        return None
    around = (np.sqrt(((unseen[:, None, :] - unseen[None, :, :]) ** 2).sum(-1)) <= s.probe_seen_mm).sum(
        axis=1
    )
    distance = np.sqrt(((unseen - np.asarray(here)) ** 2).sum(-1))
    best = int(np.argmax(around - distance / 1000.0))
    return float(unseen[best, 0]), float(unseen[best, 1])


def _inside(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd rule for many points at once (arrays (N, 2) and (M, 2))."""
    x, y = points[:, 0][:, None], points[:, 1][:, None]
    ax, ay = polygon[:, 0][None, :], polygon[:, 1][None, :]
    bx, by = np.roll(polygon[:, 0], -1)[None, :], np.roll(polygon[:, 1], -1)[None, :]
    crosses = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = ax + (y - ay) * (bx - ax) / np.where(by != ay, by - ay, 1.0)
    return (crosses & (x < xint)).sum(axis=1) % 2 == 1


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


def point_in_polygon(p: tuple[float, float], polygon: list[tuple[float, float]]) -> bool:
    """Whether ``p`` lies inside the closed path ``polygon`` (even-odd rule)."""
    return bool(_inside(np.array([p], dtype=float), np.asarray(polygon, dtype=float))[0])


def linked_groups(points: list[tuple[float, float]], link: float) -> list[list[tuple[float, float]]]:
    """The points split into groups in which each lies within ``link`` of another (single linkage)."""
    groups = []
    unassigned = list(points)
    while unassigned:
        group = [unassigned.pop()]
        frontier = list(group)
        while frontier:
            q = frontier.pop()
            near, far = [], []
            for p in unassigned:
                (near if math.dist(p, q) <= link else far).append(p)
            unassigned = far
            group += near
            frontier += near
        groups.append(group)
    return groups


def distance_to_path(p: tuple[float, float], path: list[tuple[float, float]]) -> float:
    """The distance from ``p`` to the nearest point of ``path`` (its points, dense along the way)."""
    return min(math.dist(p, q) for q in path)


class Calibrate(Navigator):
    """The calibration run: turn 360°, compare the compass, correct the glide factor; then face
    the start heading again.

    The 360° turn runs at the old glide factor, so it ends off by the very error it measures
    (13° on the office floor at world seed 1), and the motor, which counts its steps, believes
    it faces the start heading. Left so, every move after it runs that far off and the map is
    turned by it (the seed's robot measured no error: it had no compass fitted). So the run turns
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
#: lock allows in turn (1766 escapes in 120 s on a loaded machine before this limit)
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
