"""The pilot (seed §4.3.6): executes the navigator's moves, watches sensors and abort conditions.

A move is a motor command (forward/reverse in mm, turn in degrees) with an optional special
command — vector generation on copro around it — and abort conditions (a distance reached, the
wall lost, a corner seen). The pilot always aborts on ALERT (a relevant sonar under 4 cm) and
then **locks**: it refuses every direction except the opposite of the one that caused the ALERT
until the navigator commands that one.

Which sonars are relevant to ALERT: the three front ones for forward moves, the rear one for
reverse moves, all of them for turns on the spot. An ALERT already present when an *escape*
move (the direction the lock allows) starts does not abort that move — it is what it escapes.
:class:`SeedPilot` (``--algorithms main=seed``) is the seed's rule instead: any sonar, any move.

Straight moves keep clear of what the sonars have shown (:class:`~modules.navigation.clearance.
EchoMemory`, issue 57): a move is commanded no farther than the free way ahead of the body, and
one whose way closes while it runs (an echo it did not have at its start) is stopped while the
reaction — a sweep, main's visit, the STOP's way to the motor, all measured — still fits. Either
ends the sequence with abort reason CLOSE and trigger ``clearance``: something is in the way, as
for a front sonar's abort, though no sonar need read it now (a partition's end met edge-on
returns no echo). Escapes from ALERT are exempt: the ALERT rule guards them.

A move the motor refuses because its drive is off (ERROR MOTORS_OFF, handed over by main as
:meth:`Pilot.note_error`, or motor.data's state OFF on several samples after the send), or one a
MOTORS_OFF ended under way, ends the sequence with abort reason MOTORS_OFF: nothing is retried.

The pilot does no I/O itself: it is stepped with a :class:`Sensors` snapshot and sends through
a callable, so it is unit-tested with synthetic data and driven by main's program on the ring.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from modules.description.robot import SONAR_COUNT, SONAR_SLOT_MS
from modules.mapping.vectorgen import NO_CONTACT_CM, PoseHistory, SonarLayout
from modules.navigation.clearance import EchoMemory
from tokenring import default_protocol

_E = default_protocol().enums
STOPPED = _E["direction"]["STOPPED"]
FORWARD = _E["direction"]["FORWARD"]
REVERSE = _E["direction"]["REVERSE"]
TURN_LEFT = _E["direction"]["TURN_LEFT"]
TURN_RIGHT = _E["direction"]["TURN_RIGHT"]
DIRECTION_NAMES = {v: k for k, v in _E["direction"].items()}
OPPOSITE = {FORWARD: REVERSE, REVERSE: FORWARD, TURN_LEFT: TURN_RIGHT, TURN_RIGHT: TURN_LEFT}
MOTOR_COMMAND = {
    FORWARD: ("MOVE_FORWARD", "distance_mm"),
    REVERSE: ("MOVE_REVERSE", "distance_mm"),
    TURN_LEFT: ("TURN_LEFT", "angle_deg"),
    TURN_RIGHT: ("TURN_RIGHT", "angle_deg"),
}
REASON = _E["abort_reason"]
REASON_NAMES = {v: k for k, v in REASON.items()}
AREA = _E["distance_area"]
MOTOR_STATE = _E["motor_state"]
MOVE_STATUS = _E["move_status"]
ERROR_CODE = _E["error_code"]
MOTOR_CODES = {name: c.code for name, c in default_protocol().nodes["motor"].command.commands.items()}
#: the trigger of a MOTORS_OFF outcome: what the operator has to do
MOTORS_OFF_TRIGGER = "motors are off: MOTORS_ON first"
CONTACT = _E["contact"]

#: the seed's ALERT area: under 4 cm
ALERT_CM = 4

#: the triggers that say something is in the way ahead: a front sonar's abort, or the clearance
BLOCKING_TRIGGERS = frozenset({"ahead_within", "front_within", "clearance"})


@dataclass(frozen=True)
class Abort:
    """An abort condition: ``kind`` over a sensor group, with a threshold in cm.

    kinds: ``front_within`` (a front sonar reads ≤ cm), ``ahead_within`` (the straight-ahead
    one), ``rear_within``, ``left_within``,
    ``right_within`` (the side's front sonar ≤ cm), ``left_parallel`` (both left sonars ≤ cm and
    within 1 cm of each other: the robot runs parallel to a wall), ``left_beyond`` / ``right_beyond`` (the
    side's front sonar reads more than cm or nothing), ``corner_left`` / ``corner_right``
    (copro reports CORNER on that side). ``sweeps``: the condition must hold on this many
    consecutive sonar sweeps (a single dropout of a side sonar is no corner)."""

    kind: str
    cm: int = 0
    reason: str = "CLOSE"
    sweeps: int = 1


@dataclass(frozen=True)
class Move:
    direction: int
    amount: int  # mm for straight moves, degrees for turns
    speed_pct: int = 100
    scan: bool = False
    abort: tuple[Abort, ...] = ()
    label: str = ""


@dataclass
class Sensors:
    """What the pilot and navigator see at one step (decoded from the token)."""

    distances: list[int] = field(default_factory=lambda: [NO_CONTACT_CM] * 8)
    sweep: int = 0
    left_contact: int = 0
    right_contact: int = 0
    motor_state: int = 0
    motor_direction: int = 0
    move_seq: int = 0
    distance_mm: int = 0
    stamp_ms: int = 0
    sweep_ms: int | None = None  # when the sweep's first pair was pinged (sonar's stamp)
    pose: tuple[float, float, float] | None = None
    pose_ms: int | None = None  # the time ``pose`` is of (the filter's lags the motor's)
    heading_cdeg: int | None = None  # compass, navigation convention (north, clockwise)
    pose_filtered: bool = False  # ``pose`` is the EKF's (its heading fuses the compass)
    ready: bool = True  # sonar and motor have published: nothing is planned on empty channels


@dataclass
class Outcome:
    """How a move sequence ended: DONE, or the abort reason and the move it happened in."""

    reason: int
    move: Move | None = None
    index: int = 0
    driven_mm: int = 0
    samples: list[tuple[int, list[int]]] = field(default_factory=list)  # (distance_mm, distances)
    trigger: str = ""
    poses: list[tuple[float, float, float] | None] = field(default_factory=list)  # the pose at each sample

    @property
    def done(self) -> bool:
        return self.reason == REASON["DONE"]

    @property
    def reason_name(self) -> str:
        return REASON_NAMES.get(self.reason, str(self.reason))


@dataclass
class PilotSettings:
    settle_visits: int = 3  # visits a stop may take before the pilot trusts the motor's idle state
    stop_timeout_ms: int = 3000  # simulated time to wait for the motor after STOP
    move_margin_s: float = 8.0  # simulated slack on top of a move's nominal duration
    mm_per_s_at_full: float = 100.0  # start-stop maximum: 10 cm/s = 100 %
    turn_mm_per_deg: float = 6.5 * 0.5419  # track travel per degree of turn (glide factor 6.5)
    #: a forward move with an ``ahead_within`` abort goes at most this far past where that abort
    #: should stop it (as seen at its start): normally a sweep, main's reaction and the STOP take
    #: 25-40 mm; when the ring stalls none of them come and the motor stops there by itself
    ahead_slack_mm: int = 100
    min_forward_mm: int = 50  # a capped move still lasts until a sweep can show its abort
    #: motor samples (distinct stamps) showing OFF after a move was sent that make it refused
    #: without the motor's ERROR: up to three can predate the motor taking the command (the
    #: newest before it, the one its loop was making, a SIP sample taken before the command ran)
    off_samples: int = 4
    #: kept free beyond the clearance margin for the pose's drift between sweeps: a capped move
    #: ends this much short of where the body would come within the margin
    clearance_reserve_mm: int = 20
    min_clear_mm: int = 30  # a straight move with less free way than this is not sent at all
    reaction_window: int = 16  # the sweeps and visits over which the reaction time is measured


Send = Callable[..., Any]  # send(target, command, **args)


class Pilot:
    """Executes move sequences; one :meth:`step` per token visit."""

    IDLE, STARTING, MOVING, STOPPING = "idle", "starting", "moving", "stopping"

    def __init__(
        self,
        layout: SonarLayout,
        send: Send,
        settings: PilotSettings | None = None,
        clearance: EchoMemory | None = None,
    ) -> None:
        self.layout = layout
        self.send = send
        self.settings = settings or PilotSettings()
        self.clearance = clearance if clearance is not None else self._make_clearance(layout)
        self._poses_seen = PoseHistory(64)  # where the robot was when (for placing sweeps)
        self._fed_sweep: int | None = None
        self._fed_ms: int | None = None
        self._step_ms: int | None = None
        self._sweep_gaps: deque[int] = deque(maxlen=self.settings.reaction_window)
        self._visit_gaps: deque[int] = deque(maxlen=self.settings.reaction_window)
        self._commanded = 0  # the distance commanded for the move under way (mm or degrees)
        self._capped = False  # ... less than the move asked for: the clearance cut it short
        self._escaping = False  # the move under way is the escape the ALERT lock allows
        self._keep_clear = True  # the sequence under way keeps clear of remembered echoes
        self.state = self.IDLE
        self.alert_lock = STOPPED
        self.moves: list[Move] = []
        self.index = 0
        self.outcome: Outcome | None = None
        self.reached: list[dict[str, int]] = []
        self._seq_before = 0
        self._started_ms = 0
        self._stop_ms: int | None = None
        self._pending_reason: tuple[int, str] | None = None
        self._exempt: set[int] = set()
        self._abort_sweep = 0
        self._abort_counts: dict[int, int] = {}
        self._samples: list[tuple[int, list[int]]] = []
        self._poses: list[tuple[float, float, float] | None] = []
        self._last_sweep: int | None = None
        self._scanning = False
        self._seen_moving = False
        self._idle_at_send = True
        self._visits = 0
        self._sent_code = 0  # the motor command code of the move under way
        self._off_error = False  # the motor refused it with ERROR MOTORS_OFF
        self._off_stamps: set[int] = set()  # motor samples seen OFF since it was sent

    @staticmethod
    def _make_clearance(layout: SonarLayout) -> EchoMemory | None:
        return EchoMemory(mounts=layout.mounts)

    # -- the navigator's side ---------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return self.state != self.IDLE

    def start(self, moves: list[Move], sensors: Sensors, keep_clear: bool = True) -> bool:
        """Take a sequence; False (and an ALERT outcome) if the ALERT lock refuses its first move.
        ``keep_clear``: its straight moves keep clear of remembered echoes (else ALERT alone)."""
        self._keep_clear = keep_clear
        self._observe(sensors)
        self.moves, self.index, self.outcome = list(moves), 0, None
        if not self.moves:
            self.outcome = Outcome(REASON["DONE"])
            return True
        first = self.moves[0]
        if self.alert_lock != STOPPED and first.direction != self.alert_lock:
            self.outcome = Outcome(REASON["ALERT"], first, 0, trigger="locked")
            return False
        self._begin(sensors)
        return True

    def abort(self, reason: str = "USER") -> None:
        """Stop what is going on (the user's STOP_EXPLORE)."""
        if self.state in (self.STARTING, self.MOVING):
            self._stop(REASON[reason], "user")
        elif self.state == self.IDLE:
            self.outcome = Outcome(REASON[reason])

    def note_position_reached(self, status: int, move_seq: int) -> None:
        """motor's POSITION_REACHED, handed over by main's command loop."""
        self.reached.append({"status": status, "move_seq": move_seq})

    def note_error(self, error: int, about: int) -> None:
        """An ERROR reply, handed over by main's command loop: MOTORS_OFF about the move just sent
        ends it at the next step (the motor refused it: its drive is off)."""
        if self.state == self.STARTING and error == ERROR_CODE["MOTORS_OFF"] and about == self._sent_code:
            self._off_error = True

    # -- internals ------------------------------------------------------------------------------
    def _begin(self, sensors: Sensors) -> None:
        move = self.moves[self.index]
        escape = self.alert_lock != STOPPED and move.direction == self.alert_lock
        self._escaping = escape
        self._exempt = self._escape_exempt(move.direction, sensors) if escape else set()
        if escape:
            self.alert_lock = STOPPED  # the navigator commanded the opposite direction
        if self._alert_at_start(move.direction, sensors):
            self._finish(REASON["ALERT"], "alert at start", lock=move.direction)
            return
        amount = self._capped_amount(move, sensors)
        clear = math.inf if escape else self._clear_mm(move.direction, sensors)
        if clear < self.settings.min_clear_mm:
            self._finish(REASON["CLOSE"], "clearance", driven=0)
            return
        self._capped = clear < amount
        amount = int(min(amount, clear))
        self._commanded = amount
        if move.scan and not self._scanning:
            self.send("copro", "START_SCAN")
            self._scanning = True
        name, arg = MOTOR_COMMAND[move.direction]
        self.reached.clear()
        self._seq_before = sensors.move_seq
        self._idle_at_send = sensors.motor_state != MOTOR_STATE["MOVING"]
        self._started_ms = sensors.stamp_ms
        self._samples = []
        self._poses = []
        self._last_sweep = sensors.sweep
        self._abort_sweep = sensors.sweep
        self._abort_counts = {}
        self._visits = 0
        self._seen_moving = False
        self._sent_code = MOTOR_CODES[name]
        self._off_error = False
        self._off_stamps = set()
        self.send("motor", name, **{arg: amount, "speed_pct": int(move.speed_pct)})
        self.state = self.STARTING

    def _capped_amount(self, move: Move, sensors: Sensors) -> int:
        """The distance to command: a forward move whose ``ahead_within`` abort sees a wall ahead
        at its start goes no further than that abort's distance plus ``ahead_slack_mm``. The
        abort needs a sweep to reach main and a STOP to reach the motor; when the ring stalls
        for a few hundred milliseconds (a lost token, a busy machine: 3 simulated seconds at
        speed 20) neither comes, and a 600 mm segment used to drive into the wall it had seen
        (office, ring under load: 11 cm of steps against the wall, the position 15 cm off for
        the rest of the run). Normally the abort stops the move well before the cap."""
        amount = int(move.amount)
        if move.direction != FORWARD:
            return amount
        ahead = sensors.distances[self.layout.front[len(self.layout.front) // 2]]
        if ahead >= NO_CONTACT_CM:
            return amount
        for condition in move.abort:
            if condition.kind == "ahead_within":
                free_mm = (ahead - condition.cm) * 10 + self.settings.ahead_slack_mm
                amount = min(amount, max(free_mm, self.settings.min_forward_mm))
        return amount

    def _escape_exempt(self, direction: int, sensors: Sensors) -> set[int]:
        """The sonars in ALERT when an escape move starts: they do not abort it (what it escapes)."""
        return self._alerting(direction, sensors)

    def _alert_at_start(self, direction: int, sensors: Sensors) -> set[int]:
        """The sonars that keep a move from being sent at all: in ALERT already, not exempt."""
        return self._alerting(direction, sensors) - self._exempt

    def _alerting(self, direction: int, sensors: Sensors) -> set[int]:
        if direction == FORWARD:
            group = self.layout.front
        elif direction == REVERSE:
            group = self.layout.rear
        else:
            group = tuple(range(len(sensors.distances)))
        return {i for i in group if sensors.distances[i] < ALERT_CM}

    def _expected_ms(self, move: Move) -> float:
        s = self.settings
        speed = s.mm_per_s_at_full * max(move.speed_pct, 1) / 100.0
        travel = move.amount if move.direction in (FORWARD, REVERSE) else move.amount * s.turn_mm_per_deg
        return (travel / speed * 1.5 + s.move_margin_s) * 1000.0

    def step(self, sensors: Sensors) -> Outcome | None:
        """Advance; returns the outcome once the sequence ended (DONE or aborted), else None."""
        self._observe(sensors)
        if self.state == self.IDLE:
            out, self.outcome = self.outcome, None
            return out
        self._visits += 1
        move = self.moves[self.index]
        if self.state in (self.STARTING, self.MOVING):
            if sensors.sweep != self._last_sweep:
                self._last_sweep = sensors.sweep
                self._samples.append((sensors.distance_mm, list(sensors.distances)))
                self._poses.append(sensors.pose)
            if self.state == self.STARTING and (
                sensors.move_seq != self._seq_before or sensors.motor_state == MOTOR_STATE["MOVING"]
            ):
                self.state = self.MOVING
            if (
                not self._seen_moving
                and sensors.motor_state == MOTOR_STATE["MOVING"]
                and self._ours(move, sensors)
            ):
                self._seen_moving = True
                self._started_ms = sensors.stamp_ms  # the move's time runs from here (sensor time)
            if self._motors_off(sensors):
                self._finish(REASON["MOTORS_OFF"], MOTORS_OFF_TRIGGER, driven=sensors.distance_mm)
                return self._take()
            alert = self._alerting(move.direction, sensors) - self._exempt
            if alert:
                self._stop(REASON["ALERT"], f"alert on sonar {sorted(alert)}", lock=move.direction)
                return None
            if self._closing(move, sensors):
                self._stop(REASON["CLOSE"], "clearance")
                return None
            new_sweep = sensors.sweep != self._abort_sweep
            self._abort_sweep = sensors.sweep
            for k, condition in enumerate(move.abort):
                if not self._triggered(condition, sensors):
                    self._abort_counts[k] = 0
                    continue
                if new_sweep or not self._abort_counts.get(k):
                    self._abort_counts[k] = self._abort_counts.get(k, 0) + 1
                if self._abort_counts[k] >= condition.sweeps:
                    self._stop(REASON[condition.reason], condition.kind)
                    return None
            if sensors.motor_state in (MOTOR_STATE["STALLED"], MOTOR_STATE["COLLISION"]):
                kind = "STALL" if sensors.motor_state == MOTOR_STATE["STALLED"] else "COLLISION"
                self._stop(REASON[kind], "motor")
                return None
            if self._move_finished(sensors):
                status = self.reached[-1]["status"] if self.reached else MOVE_STATUS["DONE"]
                if status in (MOVE_STATUS["STALLED"], MOVE_STATUS["COLLISION"]):
                    reason = "STALL" if status == MOVE_STATUS["STALLED"] else "COLLISION"
                    self._finish(REASON[reason], "motor", driven=sensors.distance_mm)
                    return self._take()
                if self._capped and self._clear_mm(move.direction, sensors) < self.settings.min_clear_mm:
                    # ended where the clearance cut it short, and the way is still closed there
                    self._finish(REASON["CLOSE"], "clearance", driven=sensors.distance_mm)
                    return self._take()
                self._next(sensors)
                return self._take() if self.state == self.IDLE else None
            if sensors.stamp_ms - self._started_ms > self._expected_ms(move):
                # (from the send until the move is seen running, then from there)
                self._stop(
                    REASON["TIMEOUT"], "move took too long" if self._seen_moving else "move never seen"
                )
            return None
        # STOPPING: wait for the motor to stand still
        if self._stop_ms is None:
            self._stop_ms = sensors.stamp_ms
        stopped = self.reached or (
            self._visits >= self.settings.settle_visits and sensors.motor_state != MOTOR_STATE["MOVING"]
        )
        if stopped or sensors.stamp_ms - self._stop_ms > self.settings.stop_timeout_ms:
            assert self._pending_reason is not None
            reason, trigger = self._pending_reason
            self._finish(reason, trigger, driven=sensors.distance_mm)
            return self._take()
        return None

    def _observe(self, sensors: Sensors) -> None:
        """Every new sweep into the echo memory; the gaps between sweeps and between visits (world
        ms) for the reaction time."""
        stamp = sensors.stamp_ms
        if self._step_ms is not None and stamp > self._step_ms:
            self._visit_gaps.append(stamp - self._step_ms)
        self._step_ms = stamp
        if sensors.pose is not None and sensors.pose_ms is not None:
            self._poses_seen.add(sensors.pose_ms, sensors.pose)
        if sensors.sweep == self._fed_sweep or not sensors.ready:
            return
        if self._fed_ms is not None and stamp > self._fed_ms:
            self._sweep_gaps.append(stamp - self._fed_ms)
        self._fed_sweep, self._fed_ms = sensors.sweep, stamp
        if self.clearance is None or not self._keep_clear or sensors.pose is None:
            return  # (nothing to keep clear of: no numpy work on main's visit)
        pose = sensors.pose
        if sensors.sweep_ms is not None:  # where the robot was at the sweep's middle
            pose = self._poses_seen.at(sensors.sweep_ms + int(SONAR_COUNT * SONAR_SLOT_MS / 2)) or pose
        self.clearance.add(pose, sensors.distances, stamp)

    def reaction_ms(self) -> float:
        """From an echo's sweep to the motor standing: the recent gaps between the sweeps main saw
        (the sweep itself and main's wait for it) and between its visits (the STOP's way to the
        motor), each at its 90th percentile, as measured on this ring (a pause while no
        navigator ran is no ring latency, and a single one does not count)."""
        return _p90(self._sweep_gaps, 240) + _p90(self._visit_gaps, 40)

    def stopping_mm(self, move: Move, sensors: Sensors) -> float:
        """How far a straight move at its speed goes while a STOP is on its way, counted from
        the time of the pose it is judged by (the filter's lags), plus the reserve."""
        speed = self.settings.mm_per_s_at_full * max(move.speed_pct, 1) / 100.0
        lag = max(0, sensors.stamp_ms - sensors.pose_ms) if sensors.pose_ms is not None else 0
        return speed * (self.reaction_ms() + lag) / 1000.0 + self.settings.clearance_reserve_mm

    def _clear_mm(self, direction: int, sensors: Sensors) -> float:
        """The free way for a straight move from here, less the reserve (inf: not straight, no
        pose, no clearance kept)."""
        if (
            self.clearance is None
            or not self._keep_clear
            or sensors.pose is None
            or direction not in (FORWARD, REVERSE)
        ):
            return math.inf
        free = self.clearance.free_mm(sensors.pose, reverse=direction == REVERSE)
        return free - self.settings.clearance_reserve_mm

    def _closing(self, move: Move, sensors: Sensors) -> bool:
        """A running straight move must stop now: the free way left is shorter than what it still
        has to go and no longer than its stopping distance (the next sweep would come too late)."""
        if move.direction not in (FORWARD, REVERSE) or self._escaping or not self._seen_moving:
            return False
        free = self._clear_mm(move.direction, sensors)
        left = self._commanded - max(0, sensors.distance_mm)
        reserve = self.settings.clearance_reserve_mm  # (a capped move's own end is no news)
        return free < left - reserve and free <= self.stopping_mm(move, sensors) - reserve

    def _motors_off(self, sensors: Sensors) -> bool:
        """The move is over because the drive is off: refused (the motor's ERROR, or OFF on
        ``off_samples`` samples since the send: a stale sample cannot say so that often), or
        taken and then ended by MOTORS_OFF (OFF once it was seen running)."""
        if self._off_error:
            return True
        if sensors.motor_state != MOTOR_STATE["OFF"]:
            return False
        if self.state == self.MOVING:
            return True
        self._off_stamps.add(sensors.stamp_ms)
        return len(self._off_stamps) >= self.settings.off_samples

    def _take(self) -> Outcome | None:
        out, self.outcome = self.outcome, None
        return out

    def _move_finished(self, sensors: Sensors) -> bool:
        if any(r["move_seq"] != self._seq_before for r in self.reached):
            return True
        # without POSITION_REACHED: our move was seen running and the motor stands again
        return (
            self._seen_moving
            and (sensors.move_seq != self._seq_before or self._idle_at_send)
            and sensors.motor_state == MOTOR_STATE["IDLE"]
            and self._visits >= self.settings.settle_visits
        )

    def _ours(self, move: Move, sensors: Sensors) -> bool:
        """The motor runs the move we sent: a new move number, or — the motor stood when we sent
        it — a move in our direction. Move numbers are the commanders' command sequence numbers,
        so another commander's last move (a PC's or a test's command; until issue 20 the
        compass's calibration turns) can carry the number ours gets: on the ring main's first turn
        once had the compass's last turn's 144, was never taken for ours and the exploration
        waited 75 s for it (square, seed 2)."""
        if sensors.move_seq != self._seq_before:
            return True
        return self._idle_at_send and sensors.motor_direction == move.direction

    def _next(self, sensors: Sensors) -> None:
        move = self.moves[self.index]
        driven = sensors.distance_mm
        if move.scan and not (self.index + 1 < len(self.moves) and self.moves[self.index + 1].scan):
            self.send("copro", "STOP_SCAN")
            self._scanning = False
        self.index += 1
        if self.index >= len(self.moves):
            self._finish(REASON["DONE"], "", driven=driven)
        else:
            self._begin(sensors)

    def _stop(self, reason: int, trigger: str, lock: int = STOPPED) -> None:
        self.send("motor", "STOP")
        if lock != STOPPED:
            self.alert_lock = OPPOSITE[lock]
        self._pending_reason = (reason, trigger)
        self._stop_ms = None
        self.reached.clear()
        self._visits = 0
        self.state = self.STOPPING

    def _finish(self, reason: int, trigger: str, lock: int = STOPPED, driven: int = 0) -> None:
        if lock != STOPPED:
            self.alert_lock = OPPOSITE[lock]
        if self._scanning:
            self.send("copro", "STOP_SCAN")
            self._scanning = False
        move = self.moves[min(self.index, len(self.moves) - 1)] if self.moves else None
        self.outcome = Outcome(reason, move, self.index, driven, self._samples, trigger, self._poses)
        self.state = self.IDLE

    def _triggered(self, condition: Abort, sensors: Sensors) -> bool:
        d = sensors.distances
        lay = self.layout
        kind, cm = condition.kind, condition.cm
        if kind == "front_within":
            return any(d[i] <= cm for i in lay.front)
        if kind == "ahead_within":  # the straight-ahead sonar only
            return d[lay.front[len(lay.front) // 2]] <= cm
        if kind == "rear_within":
            return any(d[i] <= cm for i in lay.rear)
        if kind == "left_within":
            return d[lay.left_front] <= cm
        if kind == "right_within":
            return d[lay.right_front] <= cm
        if kind == "left_parallel":  # both left sonars on one wall at the same distance
            front, rear = d[lay.left_front], d[lay.left_rear]
            return front <= cm and rear <= cm and abs(front - rear) <= 1
        if kind == "left_beyond":
            return d[lay.left_front] > cm
        if kind == "right_beyond":
            return d[lay.right_front] > cm
        if kind == "corner_left":
            return sensors.left_contact == CONTACT["CORNER"]
        if kind == "corner_right":
            return sensors.right_contact == CONTACT["CORNER"]
        raise ValueError(f"unknown abort condition {kind!r}")


def _p90(values: deque[int], default: float) -> float:
    if not values:
        return default
    ordered = sorted(values)
    return float(ordered[int(0.9 * (len(ordered) - 1))])


class SeedPilot(Pilot):
    """The seed's pilot (seed §4.3.6 ``pilot_1``): "Meldet ein Sensor eine Bereichsunterschreitung
    von 4cm ... so bricht er auf jeden Fall die Fahrt ab" — any of the eight sonars in ALERT aborts
    any move, whatever its direction, escapes included; the move is sent first and the ALERT is
    seen while it runs (the seed checks inside ``while(Position noch nicht erreicht)``). The
    direction lock is the same as ours: only the opposite of the aborted move is accepted next."""

    def _alerting(self, direction: int, sensors: Sensors) -> set[int]:
        return {i for i, cm in enumerate(sensors.distances) if cm < ALERT_CM}

    def _escape_exempt(self, direction: int, sensors: Sensors) -> set[int]:
        return set()  # "auf jeden Fall": no sonar is exempt, not even on the escape

    def _alert_at_start(self, direction: int, sensors: Sensors) -> set[int]:
        return set()  # sent, then stopped at the first check of the running move

    @staticmethod
    def _make_clearance(layout: SonarLayout) -> EchoMemory | None:
        return None  # the seed's robot had only the ALERT rule


def side_slope(
    samples: list[tuple[int, list[int]]], sensor: int, max_cm: int = 120
) -> tuple[float, float] | None:
    """Least-squares (slope, last value in mm) of one sonar's readings over distance driven.

    The slope (mm of reading per mm driven) is the tangent of the angle between the robot's
    course and the wall; None without enough valid readings."""
    pts = [(dist, r[sensor] * 10.0) for dist, r in samples if r[sensor] <= max_cm]
    if len(pts) < 5:
        return None
    xs = [p[0] for p in pts]
    if max(xs) - min(xs) < 150:
        return None
    n = len(pts)
    mx = sum(xs) / n
    my = sum(p[1] for p in pts) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    sxy = sum((x - mx) * (p[1] - my) for x, p in zip(xs, pts, strict=True))
    slope = sxy / sxx
    return slope, my + slope * (xs[-1] - mx)


def angle_of_slope(slope: float) -> float:
    """The course's angle to the wall in degrees (positive: moving away from it)."""
    return math.degrees(math.atan(slope))
