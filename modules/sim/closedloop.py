"""The robot at work without a ring: main's navigator and pilot, copro's vectorizer and Localizer,
and stand-ins for motor, sonar and compass, all stepped on one simulated clock in one process.

The ring runs these same classes inside node processes and passes their data through the token;
here the "token" is a dict of the channels' latest values, read by main and copro every
``visit_ms`` (default ``VISIT_MS``; the ring's round at ``--speed K``, which scales the wire too,
is 110-140 ms at speed 20 on two shared cores: ``bench.mapping`` prints it). The world is the
simulator's own: :class:`TrackedRobot` (per-move slip), the sonar echo envelopes with the
threshold + tangent contact, the magnetic field with its anomalies. What is left out: the
compass's bridges and calibration (its heading is the field's direction with σ 1° of noise and
the module's short mean; only the ring's lag in telling it that the motors run is kept) and the
wire's latencies. A run of the office takes seconds, so
navigation, filter and vector generation can be tuned on many drives before the ring confirms.

``python -m bench.closedloop`` (:mod:`bench.closedloop`) runs and scores it from the command line.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

VISIT_MS = 20  # main and copro see the token this often (an 8-node round at 2.5 Mbit/s)
TICK_MS = 10  # the simulation's step
COMPASS_PERIOD_MS = 100
COMPASS_SIGMA_DEG = 1.0  # SPEC §5
COMPASS_MEAN = 3  # the compass module's short circular mean (reset while turning, starting, stopping)
#: the compass module hears of a start or stop through motor.data, a token round late: on the ring
#: at speed 20 a round takes 130 ms (median; 90 % within 190, bench.mapping's recording); until then
#: it subtracts the motors' running field wrongly (modules/world/magnetics.py MOTOR_RUNNING_UT)
COMPASS_HEARS_MOTOR_MS = 130
TRUTH_PERIOD_MS = 100


@dataclass
class MotorMove:
    seq: int
    direction: int
    total: int  # half-steps per track
    signs: tuple[int, int]
    rate_hz: float
    start_ms: float
    issued: int = 0


class SimMotor:
    """modules/motor.py's moves on the simulated robot: steps on the clock, dead reckoning,
    POSITION_REACHED (via ``notify``) when a move ends."""

    def __init__(self, robot: Any, notify: Callable[[int, int], None]) -> None:
        from modules.sensors.odometry import DeadReckoning

        self.robot = robot
        self.notify = notify
        pose = robot.pose
        self.odometry = DeadReckoning(pose.x, pose.y, pose.theta)
        self.move: MotorMove | None = None
        self.seq = 0
        self.move_seq = 0
        self.state = 0  # IDLE
        self.direction = 0
        self.speed_pct = 0
        self.distance_mm = 0.0
        self.steps = [0, 0]
        self.stamp_ms = 0.0
        self.moves = {"done": 0, "aborted": 0, "collision": 0, "stalled": 0}

    def command(self, name: str, now_ms: float, **args: Any) -> None:
        from modules.navigation.pilot import FORWARD, REVERSE, TURN_LEFT, TURN_RIGHT
        from modules.sensors.odometry import step_rate_hz, steps_for_angle, steps_for_distance

        if name == "MOTORS_ON":  # an action file's e: the drive is on (no one here switches it off)
            return
        self.seq += 1
        if self.move is not None:
            self._finish(2)  # ABORTED
        if name == "STOP":
            self.state, self.direction, self.speed_pct = 0, 0, 0
            return
        speed = int(args["speed_pct"])
        if name in ("MOVE_FORWARD", "MOVE_REVERSE"):
            n = steps_for_distance(args["distance_mm"])
            signs, direction = ((1, 1), FORWARD) if name == "MOVE_FORWARD" else ((-1, -1), REVERSE)
        else:
            n = steps_for_angle(args["angle_deg"], self.odometry.glide)
            signs, direction = ((-1, 1), TURN_LEFT) if name == "TURN_LEFT" else ((1, -1), TURN_RIGHT)
        self.move_seq = self.seq
        self.distance_mm = 0.0
        self.move = MotorMove(self.seq, direction, n, signs, step_rate_hz(speed), now_ms)
        self.state, self.direction, self.speed_pct = 1, direction, speed
        if n == 0:
            self._finish(0)

    def tick(self, now_ms: float) -> None:
        from modules.description.robot import STEP_MM

        move = self.move
        self.stamp_ms = now_ms
        if move is None:
            return
        due = min(move.total, math.floor((now_ms - move.start_ms) / 1000.0 * move.rate_hz))
        new = due - move.issued
        if new > 0:
            left, right = new * move.signs[0], new * move.signs[1]
            result = self.robot.apply_steps(left, right, move.rate_hz, move.seq)
            move.issued = due
            self.steps[0] += left
            self.steps[1] += right
            self.odometry.apply(left, right)
            self.distance_mm += new * STEP_MM
            if result.blocked:
                self._finish(1)  # COLLISION
                return
            if result.stalled:
                self._finish(3)
                return
        if move.issued >= move.total:
            self._finish(0)

    def _finish(self, status: int) -> None:
        move = self.move
        assert move is not None
        self.move = None
        self.state = {0: 0, 2: 0, 3: 2, 1: 3}[status]  # IDLE, STALLED, COLLISION
        self.direction, self.speed_pct = 0, 0
        self.moves[{0: "done", 1: "collision", 2: "aborted", 3: "stalled"}[status]] += 1
        self.notify(status, move.seq)

    def data(self) -> dict[str, Any]:
        from modules.units import pose_to_wire

        return {
            **pose_to_wire(self.odometry.x, self.odometry.y, self.odometry.theta),
            "direction": self.direction,
            "speed_pct": self.speed_pct,
            "distance_mm": round(self.distance_mm),
            "steps_left": self.steps[0],
            "steps_right": self.steps[1],
            "stamp_ms": int(self.stamp_ms),
            "move_seq": self.move_seq,
            "state": self.state,
        }


class SimSonar:
    """modules/sonar.py: eight pairs pinged 15 ms apart, threshold + tangent, areas, behaviours."""

    def __init__(self, world: Any, rng: np.random.Generator) -> None:
        from modules.description.robot import SONAR_COUNT
        from modules.sensors.sonar import NO_CONTACT, make_classifier

        self.world = world
        self.rng = rng
        self.classifiers = [make_classifier(False) for _ in range(SONAR_COUNT)]
        self.areas = [NO_CONTACT] * SONAR_COUNT
        self.pending: list[int] = [255] * SONAR_COUNT
        self.sweep = 0
        self.next_pair = 0
        self.sweep_start = 0.0
        self.published: dict[str, Any] | None = None

    def tick(self, now_ms: float, pose: Any) -> None:
        from modules.description.robot import SONAR_COUNT, SONAR_SLOT_MS, sonar_world_pose
        from modules.sensors.sonar import contact_tangent, distance_area
        from modules.world import echo

        while now_ms >= self.sweep_start + self.next_pair * SONAR_SLOT_MS:
            i = self.next_pair
            sx, sy, direction = sonar_world_pose(pose.x, pose.y, pose.theta, i)
            self.pending[i] = contact_tangent(echo.envelope(self.world, sx, sy, direction, self.rng))
            self.next_pair += 1
            if self.next_pair == SONAR_COUNT:
                self.sweep = (self.sweep + 1) & 0xFFFF
                behaviours = []
                for k, cm in enumerate(self.pending):
                    self.areas[k] = distance_area(cm, self.areas[k])
                    behaviours.append(self.classifiers[k].observe(cm))
                self.published = {
                    "distances": list(self.pending),
                    "behaviours": behaviours,
                    "areas": list(self.areas),
                    "sweep": self.sweep,
                    "stamp_ms": int(self.sweep_start),
                }
                self.sweep_start += SONAR_COUNT * SONAR_SLOT_MS
                self.next_pair = 0


class SimCompass:
    """The heading the calibrated compass module publishes: the direction of the horizontal field
    (Earth + anomalies) with σ 1°, its 3-sample circular mean reset while turning; for a token
    round after the motors start or stop, their running field wrongly kept or subtracted."""

    def __init__(self, world: Any, rng: np.random.Generator) -> None:
        self.world = world
        self.rng = rng
        self.recent: list[float] = []
        self.motion: deque[tuple[float, bool]] = deque()  # (time, motors on) for the lag
        self.last_heard = False
        self.sample = 0
        self.next_ms = 0.0
        self.state = 1  # OK
        self.published: dict[str, Any] | None = None

    def tick(self, now_ms: float, pose: Any, turning: bool, moving: bool = False) -> None:
        from modules.sensors.compass import circular_mean
        from modules.units import heading_to_cdeg
        from modules.world.magnetics import MOTOR_RUNNING_UT

        self.motion.append((now_ms, moving))
        while len(self.motion) > 1 and self.motion[1][0] <= now_ms - COMPASS_HEARS_MOTOR_MS:
            self.motion.popleft()
        if now_ms < self.next_ms:
            return
        self.next_ms += COMPASS_PERIOD_MS
        w = self.world
        bx, by = w.earth_field_ut * math.cos(w.north), w.earth_field_ut * math.sin(w.north)
        for a in w.anomalies:
            fade = math.exp(-((pose.x - a.x) ** 2 + (pose.y - a.y) ** 2) / (2 * a.radius**2))
            bx, by = bx + a.bx * fade, by + a.by * fade
        heard = self.motion[0][1]  # what motor.data said a round ago
        if heard != moving:  # the running field is there but not subtracted, or the reverse
            sign = 1.0 if moving else -1.0
            c, sn = math.cos(pose.theta), math.sin(pose.theta)
            rx, ry = MOTOR_RUNNING_UT  # robot frame (forward, left) -> world
            bx, by = bx + sign * (c * rx - sn * ry), by + sign * (sn * rx + c * ry)
        heading = (math.atan2(by, bx) - pose.theta) % (2 * math.pi)  # from north, clockwise
        if self.state in (1, 2):  # OK or DISTURBED: the module's rule on the field's strength
            from modules.compass import DISTURBED_RATIO

            off = abs(math.hypot(bx, by) / w.earth_field_ut - 1.0)
            self.state = 2 if off > DISTURBED_RATIO else 1
        heading += math.radians(self.rng.normal(0.0, COMPASS_SIGMA_DEG))
        restart = turning or heard != self.last_heard
        self.last_heard = heard
        self.recent = [heading] if restart else [*self.recent[-(COMPASS_MEAN - 1) :], heading]
        self.sample = (self.sample + 1) & 0xFFFF
        self.published = {
            "heading_cdeg": heading_to_cdeg(circular_mean(self.recent) % (2 * math.pi)),
            "state": self.state,
            "sample": self.sample,
            "stamp_ms": int(now_ms),
        }


@dataclass
class Run:
    """What a closed-loop run produced."""

    vectors: np.ndarray
    variants: dict[tuple[str, str], np.ndarray]
    truth_path: np.ndarray
    pose_path: np.ndarray
    finished: str
    sim_seconds: float
    moves: dict[str, int]
    pose_errors: dict[str, float] = field(default_factory=dict)
    log: list[str] = field(default_factory=list)
    #: bumper contacts (a failure, never a way to find walls) and the footprint's closest approach
    #: to any surface (mm; None in a room without one)
    collisions: int = 0
    closest_mm: float | None = None
    alerts: int = 0  # move sequences the pilot ended by ALERT
    contacts: list[dict[str, float]] = field(default_factory=list)  # each collision's geometry
    home: bool = False  # the navigator says it is back at its start


class ClosedLoop:
    """One exploration of ``world`` by main's navigator, with copro's Localizer and vectorizer."""

    def __init__(
        self,
        world: str,
        seed: int = 1,
        mode: int = 2,
        method: int | None = None,
        localizer: bool = True,
        localizer_config: dict[str, Any] | None = None,
        calibrate: bool = True,
        start_deg: float | None = None,
        visit_ms: float = VISIT_MS,
    ) -> None:
        from modules.description import load_world
        from modules.mapping.vectorgen import OUR_METHOD, SEED_METHOD, PoseHistory, Vectorizer, default_layout
        from modules.navigation.navigator import ExploreAvoid, ExploreLeftWall
        from modules.navigation.pilot import Pilot
        from modules.world.physics import TrackedRobot

        self.world = load_world(world)
        if start_deg is not None:  # another start heading: the calibration turns end elsewhere
            import dataclasses

            start = dataclasses.replace(self.world.start, theta=math.radians(start_deg))
            self.world = dataclasses.replace(self.world, start=start)
        rng = np.random.default_rng(seed)
        self.robot = TrackedRobot(self.world, rng)
        self.now = 0.0
        self.motor = SimMotor(self.robot, self._position_reached)
        self.sonar = SimSonar(self.world, np.random.default_rng(seed + 1000))
        self.compass = SimCompass(self.world, np.random.default_rng(seed + 2000))
        self.layout = default_layout()
        self.pilot = Pilot(self.layout, self._send)
        self.navigator = ExploreLeftWall(self.layout) if mode == 2 else ExploreAvoid(self.layout)
        self.method = OUR_METHOD if method is None else method
        self.vectors: list[tuple[float, float, float, float]] = []
        self.vectorizer = Vectorizer(self.layout, self.method, self._emit)
        # the same sweeps through both methods on both poses (what bench.mapping replays)
        self.variants: dict[tuple[str, str], tuple[Vectorizer, list[tuple[float, float, float, float]]]] = {}
        for name, variant_method in (("seed", SEED_METHOD), ("ours", OUR_METHOD)):
            for source in ("dead reckoning", "filter") if localizer else ("dead reckoning",):
                out: list[tuple[float, float, float, float]] = []
                self.variants[(name, source)] = (Vectorizer(self.layout, variant_method, out.append), out)
        self.history = PoseHistory()
        self.scanning = False
        self.core = None
        if localizer:
            from modules.copro import EXPLORATION_CONFIG
            from modules.localization.config import load_config
            from modules.localization.localizer import LocalizationCore

            self.core = LocalizationCore(load_config(localizer_config or EXPLORATION_CONFIG))
        self.last_seen: dict[str, Any] = {}
        self.pose: tuple[float, float, float] | None = None
        self.pose_stamp = 0
        self.pose_filtered = False
        self.last_outcome: Any = None
        self.truth: list[tuple[float, float, float, float]] = []
        self.poses: list[tuple[float, float, float]] = []
        self.errors: list[tuple[float, float]] = []
        self.next_truth = 0.0
        self.last_sweep: int | None = None
        self.counter = 0
        self.calibration_turns = 8 if calibrate else 0
        self.visit_ms = visit_ms
        self.log: list[str] = []
        self.alerts = 0

    # -- the ring's commands ------------------------------------------------------------------
    def _send(self, target: str, command: str, **args: Any) -> None:
        if target == "motor":
            self.motor.command(command, self.now, **args)
        elif target == "copro":
            if command == "START_SCAN":
                self.scanning = True
            elif command == "STOP_SCAN":
                self.scanning = False
                for vectorizer in self._vectorizers():
                    vectorizer.end_scan()
            elif command == "FLUSH":
                for vectorizer in self._vectorizers():
                    vectorizer.flush()

    def _vectorizers(self) -> list[Any]:
        return [self.vectorizer, *(v for v, _ in self.variants.values())]

    def _position_reached(self, status: int, seq: int) -> None:
        if self.calibration_turns <= 0:
            self.pilot.note_position_reached(status, seq)

    def _emit(self, vector: tuple[float, float, float, float]) -> None:
        self.vectors.append(vector)
        if self.core is not None:
            self.core.event("map_wall", x1=vector[0], y1=vector[1], x2=vector[2], y2=vector[3])

    # -- one visit of copro and of main ------------------------------------------------------
    def _copro(self) -> None:
        from modules.localization.sync import Sample
        from modules.mapping.vectorgen import OUR_METHOD
        from modules.units import pose_from_wire, pose_to_wire

        motor = self.motor.data()
        self.history.add(motor["stamp_ms"], pose_from_wire(motor["x_mm"], motor["y_mm"], motor["angle_cdeg"]))
        pose = self.history.latest()
        self.pose_stamp, self.pose_filtered = motor["stamp_ms"], False
        if self.core is not None:
            channels = {"odometry": motor, "compass": self.compass.published, "sonar": self.sonar.published}
            fields = {
                "odometry": ("steps_left", "steps_right", "x_mm", "y_mm", "angle_cdeg", "state"),
                "compass": ("heading_cdeg", "state"),
                "sonar": ("distances",),
            }
            seqs = {"compass": "sample", "sonar": "sweep"}
            for sensor, values in channels.items():
                if values is None:
                    continue
                key = (values["stamp_ms"], values.get(seqs.get(sensor, ""), None))
                if self.last_seen.get(sensor) == key:
                    continue
                self.last_seen[sensor] = key
                picked = {f: values[f] for f in fields[sensor]}
                self.core.feed(
                    Sample(sensor, int(values["stamp_ms"]), picked, values.get(seqs.get(sensor, "")))
                )
            self.core.maybe_sync(self.counter)
            got = self.core.pose()
            if got.source == "ekf":
                wire = pose_to_wire(got.x_mm, got.y_mm, got.heading)
                pose = pose_from_wire(wire["x_mm"], wire["y_mm"], wire["angle_cdeg"])
                self.pose_stamp, self.pose_filtered = got.stamp_ms, True
        self.pose = pose
        sonar = self.sonar.published
        if sonar is not None and sonar["sweep"] != self.last_sweep:
            self.last_sweep = sonar["sweep"]
            active = (
                self.scanning and motor["direction"] == 1 and motor["distance_mm"] > 10 and pose is not None
            )
            at_sweep = self._pose_at(sonar["stamp_ms"], pose)
            self.vectorizer.sweep(sonar, at_sweep if self.method == OUR_METHOD else pose, bool(active))
            if at_sweep is not None:
                self.poses.append(at_sweep)
            dr_now, dr_at = self.history.latest(), self.history.at(sonar["stamp_ms"])
            for (name, source), (vectorizer, _) in self.variants.items():
                if source == "filter":
                    if not self.pose_filtered:
                        continue
                    chosen = at_sweep if name == "ours" else pose
                else:
                    chosen = dr_at if name == "ours" else dr_now
                vectorizer.sweep(sonar, chosen, bool(active))

    def _pose_at(self, stamp_ms: int, pose: Any) -> Any:
        """copro's: dead reckoning at the sweep, the filter's pose carried there by dead reckoning."""
        at_sweep = self.history.at(stamp_ms)
        if at_sweep is None or pose is None:
            return pose
        if not self.pose_filtered:
            return at_sweep
        return self.history.carry(pose, self.pose_stamp, stamp_ms)

    def _main(self) -> str | None:
        from modules.navigation.pilot import REASON, Sensors

        sonar = self.sonar.published
        motor = self.motor.data()
        compass = self.compass.published
        left, right = self.vectorizer.hypotheses["left"], self.vectorizer.hypotheses["right"]
        sensors = Sensors(
            distances=list(sonar["distances"]) if sonar else [255] * 8,
            sweep=sonar["sweep"] if sonar else 0,
            left_contact=left.contact,
            right_contact=right.contact,
            motor_state=motor["state"],
            motor_direction=motor["direction"],
            move_seq=motor["move_seq"],
            distance_mm=motor["distance_mm"],
            stamp_ms=motor["stamp_ms"],
            sweep_ms=sonar["stamp_ms"] if sonar else None,
            pose=self.pose,
            pose_ms=self.pose_stamp if self.pose is not None else None,
            heading_cdeg=compass["heading_cdeg"] if compass else None,
            pose_filtered=self.pose_filtered,
            ready=bool(sonar and sonar["sweep"]),
        )
        outcome = self.pilot.step(sensors)
        if outcome is not None:
            self.last_outcome = outcome
            if outcome.reason == REASON["ALERT"] and outcome.trigger != "locked":
                self.alerts += 1
        if self.pilot.busy or not sensors.ready:
            return None
        nav = self.navigator
        moves = nav.plan(self.last_outcome, sensors, self.pilot.alert_lock)
        for target, command, args in nav.commands:
            self._send(target, command, **args)
        nav.commands.clear()
        ended = self.last_outcome
        self.last_outcome = None
        if moves is None:
            return nav.note or "done"
        if moves:
            why = f"{ended.reason_name}/{ended.trigger}" if ended is not None else "start"
            self.log.append(
                f"{self.now / 1000:7.1f} s {why}: " + ", ".join(f"{m.label} {m.amount}" for m in moves)
            )
        self.pilot.start(moves, sensors, keep_clear=nav.keeps_clear)
        return None

    # -- the clock -----------------------------------------------------------------------------
    def run(self, minutes: float = 30.0, progress: Callable[[str], None] | None = None) -> Run:
        from modules.description.robot import MOTOR_TICK_MS
        from modules.navigation.pilot import TURN_LEFT, TURN_RIGHT

        end_ms = minutes * 60_000.0
        finished = "time is up"
        next_visit = next_motor = 0.0
        calibrating_until = 0.0
        while self.now < end_ms:
            pose = self.robot.pose
            if self.now >= next_motor:
                self.motor.tick(self.now)
                next_motor += MOTOR_TICK_MS
            self.sonar.tick(self.now, pose)
            turning = self.motor.direction in (TURN_LEFT, TURN_RIGHT)
            if self.calibration_turns > 0:
                self.compass.state = 3
            elif self.compass.state == 3:
                self.compass.state = 1
            self.compass.tick(self.now, pose, turning, self.motor.move is not None)
            if self.now >= self.next_truth:
                self.truth.append((self.now, pose.x, pose.y, pose.theta))
                if self.core is not None:
                    from modules.localization.sync import Sample

                    self.core.feed(
                        Sample("truth", int(self.now), {"x": pose.x, "y": pose.y, "theta": pose.theta})
                    )
                self.next_truth += TRUTH_PERIOD_MS
            if self.now >= next_visit:
                next_visit += self.visit_ms
                self.counter = (self.counter + 1) & 0xFF
                self._copro()
                if self.calibration_turns > 0:  # the compass's CALIBRATE: 8 turns of 45°
                    if self.motor.move is None and self.now >= calibrating_until:
                        self.motor.command("TURN_LEFT", self.now, angle_deg=45, speed_pct=50)
                        self.calibration_turns -= 1
                        calibrating_until = self.now + 500
                else:
                    ended = self._main()
                    if ended is not None:
                        finished = ended
                        break
                if self.pose is not None and self.pose_filtered:
                    self.errors.append(
                        (
                            math.hypot(self.pose[0] - pose.x, self.pose[1] - pose.y),
                            math.degrees(math.remainder(self.pose[2] - pose.theta, 2 * math.pi)),
                        )
                    )
            self.now += TICK_MS
        for vectorizer in self._vectorizers():
            vectorizer.flush()
        errs = np.asarray(self.errors).reshape(-1, 2)
        pose_errors = {}
        if len(errs):
            pose_errors = {
                "position_median_mm": float(np.median(errs[:, 0])),
                "position_max_mm": float(np.max(errs[:, 0])),
                "heading_median_deg": float(np.median(np.abs(errs[:, 1]))),
                "heading_p95_deg": float(np.percentile(np.abs(errs[:, 1]), 95)),
            }
        if (
            self.core is not None
            and self.core.ekf is not None
            and "step_scale" in self.core.ekf_params.estimate
        ):
            # the filter's step scale at the end beside the floor's (each move draws its own about it)
            pose_errors["step_scale_end"] = float(self.core.ekf.step_scale)
            pose_errors["floor_step_scale"] = float(self.world.floor.step_scale)
        return Run(
            vectors=np.asarray(self.vectors, dtype=float).reshape(-1, 4),
            variants={
                k: np.asarray(out, dtype=float).reshape(-1, 4) for k, (_, out) in self.variants.items()
            },
            truth_path=np.asarray(self.truth, dtype=float).reshape(-1, 4)[:, 1:3],
            pose_path=np.asarray(self.poses, dtype=float).reshape(-1, 3)[:, :2],
            finished=finished,
            sim_seconds=self.now / 1000.0,
            moves=dict(self.motor.moves),
            pose_errors=pose_errors,
            log=self.log,
            collisions=self.robot.collisions,
            closest_mm=self.robot.closest_mm if math.isfinite(self.robot.closest_mm) else None,
            alerts=self.alerts,
            contacts=list(self.robot.contacts),
            home=bool(getattr(self.navigator, "home_reached", False)),
        )


def explore(
    world: str,
    seed: int,
    seed_method: bool = False,
    dead_reckoning: bool = False,
    walls: str | None = None,
    minutes: float = 30.0,
    start_deg: float | None = None,
    out: str | None = None,
    variant_pngs: bool = False,
    overrides: dict[str, Any] | None = None,
    visit_ms: float = VISIT_MS,
) -> dict[str, Any]:
    """One closed-loop exploration, scored: the map as the robot made it and the four variants
    (seed/ours × dead reckoning/filter) of the same drive; PNGs to ``out``. ``overrides`` are
    Localizer settings laid over exploration mode's (copro's ``EXPLORATION_CONFIG``); ``visit_ms``
    how often main and copro see the token."""
    from modules.pc.mapfiles import load_truth, write_map
    from modules.pc.mapscore import score_map

    config = None
    if walls or overrides:
        from modules.copro import EXPLORATION_CONFIG
        from modules.localization.config import layered

        config = layered(EXPLORATION_CONFIG, overrides or {})
        if walls:
            config = layered(config, {"walls": {"mode": walls}})
    loop = ClosedLoop(
        world,
        seed,
        method=0 if seed_method else None,
        localizer=not dead_reckoning,
        localizer_config=config,
        start_deg=start_deg,
        visit_ms=visit_ms,
    )
    run = loop.run(minutes)
    name, truth = load_truth(world)
    rows = []
    for (method, source), vectors in [(("as run", "as run"), run.vectors), *run.variants.items()]:
        score = score_map(vectors, truth)
        rows.append({"room": name, "seed": seed, "method": method, "pose": source, **score})
        if out and (method == "as run" or variant_pngs):
            Path(out).mkdir(parents=True, exist_ok=True)
            tag = "" if method == "as run" else f"-{method}-{'ekf' if source == 'filter' else 'dr'}"
            write_map(
                vectors,
                str(Path(out) / f"{name}-seed{seed}{tag}.png"),
                truth,
                name,
                title=f"{name}, closed loop, seed {seed}, {method}, {source}",
                paths={"true": run.truth_path, "mapping pose": run.pose_path},
            )
    return {
        "room": name,
        "seed": seed,
        "finished": run.finished,
        "sim_seconds": run.sim_seconds,
        "moves": run.moves,
        "collisions": run.collisions,
        "closest_mm": None if run.closest_mm is None else round(run.closest_mm, 1),
        "alerts": run.alerts,
        "contacts": run.contacts,
        "home": run.home,
        "pose_errors": run.pose_errors,
        "log": run.log,
        "rows": rows,
    }
