"""The compass module's arithmetic (seed §3.3.3): two KMZ51 bridges at 90°, flip and compensation.

A measurement takes each bridge's ADC samples with the flip coil set and again with it reset: half
the difference is the field the bridge sees (its own electrical offset cancels), half the sum is
that offset. Averaging 20 samples at 1 kHz spans one 50 Hz period, so mains fields cancel too.
The compensation coil cancels the motors' static field in the sensor (learned by calibration:
a circle fit through readings taken at rest at eight headings); it lowers the bridge's gain a
little, which is a known factor. The seed's loop (§3.3.3) also cancels the offset with the coil:
flip, measure, compensate, measure again until the pair is symmetric round zero
(:func:`compensate_until_symmetric`). Of the two bridges, the one within ±45° of its zero crossing
(the steep part of its sine) gives the angle by arccos; the other only says which side.
Heading: navigation convention, radians from north, clockwise.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from modules.description.robot import MOTOR_TICK_MS
from modules.sensors.odometry import step_rate_hz
from tokenring import default_protocol

ADC_MID = 2048
COUNTS_PER_UT = 20.0  # bridge + amplifier: the module's datasheet value
COMPENSATION_SENSITIVITY_LOSS = 0.002  # relative gain lost per µT of compensation field
SIN45 = math.sqrt(0.5)


def bridge_gain(compensation_ut: float) -> float:
    """ADC counts per µT of a bridge carrying ``compensation_ut`` in its compensation coil."""
    return COUNTS_PER_UT * (1.0 - COMPENSATION_SENSITIVITY_LOSS * abs(compensation_ut))


def flip_measurement(
    plus: np.ndarray,
    minus: np.ndarray,
    compensation_ut: Sequence[float],
    minus_compensation_ut: Sequence[float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Samples (2 bridges x n) taken flipped and reset -> (field each bridge sees after the
    static compensation in µT, the midpoint of the two readings in counts: the bridge's offset
    less what the coil's flip-synchronous part cancels). ``minus_compensation_ut``: the coils'
    field in the reset phase when it differs (:func:`phase_compensation`)."""
    vp, vm = np.asarray(plus, float).mean(axis=1), np.asarray(minus, float).mean(axis=1)
    midpoint = (vp + vm) / 2 - ADC_MID
    if minus_compensation_ut is None:
        gains = np.array([bridge_gain(c) for c in compensation_ut])
        return (vp - vm) / (2 * gains), midpoint
    # (V+ - mid)/g+ = H + s + k + o/g+ and (V- - mid)/g- = -(H + s) + k + o/g-: k drops out
    gp = np.array([bridge_gain(c) for c in compensation_ut])
    gm = np.array([bridge_gain(c) for c in minus_compensation_ut])
    return ((vp - ADC_MID) / gp - (vm - ADC_MID) / gm) / 2, midpoint


# -- the flip -> compensation coil -> re-measure loop (seed §3.3.3) -----------------------------
SYMMETRY_TOLERANCE_UT = 0.25  # a flip pair's midpoint scatters by ~0.08 µT (20 samples each)
MAX_COMPENSATION_ROUNDS = 8
COIL_LIMIT_UT = 50.0  # the most field a compensation coil's driver makes (gain then -10 %)
Vector = np.ndarray | Sequence[float]  # one value per bridge


def phase_compensation(
    static_ut: Vector, offset_ut: Vector
) -> tuple[tuple[float, float], tuple[float, float]]:
    """The coils' field with the flip coil set and reset: the static part (cancelling the motors'
    field) stays, the offset part turns with the flip. A coil field that stays is inverted with
    the bridge's response like the Earth's and cannot move the readings' midpoint; one reversed
    with the flip adds to the bridge's offset, which is what the seed's coil cancels."""
    s, k = np.asarray(static_ut, float), np.asarray(offset_ut, float)
    plus, minus = s + k, s - k
    return (float(plus[0]), float(plus[1])), (float(minus[0]), float(minus[1]))


def coil_limited(static_ut: Vector, offset_ut: np.ndarray) -> np.ndarray:
    """``offset_ut`` cut so that neither phase's coil field exceeds :data:`COIL_LIMIT_UT`."""
    reach = np.maximum(COIL_LIMIT_UT - np.abs(np.asarray(static_ut, float)), 0.0)
    return np.clip(offset_ut, -reach, reach)


def compensation_step(static_ut: Vector, offset_ut: Vector, midpoint_counts: Vector) -> np.ndarray:
    """The coils' next offset field: the last one less the midpoint the flip pair showed, in µT
    at the two phases' mean gain (the coil's field lowers the gain: seed §3.3.3, so one step
    leaves a little and the loop measures again)."""
    plus, minus = phase_compensation(static_ut, offset_ut)
    gains = np.array([(bridge_gain(p) + bridge_gain(m)) / 2 for p, m in zip(plus, minus, strict=True)])
    step = np.asarray(offset_ut, float) - np.asarray(midpoint_counts, float) / gains
    return coil_limited(static_ut, step)


def symmetric(
    static_ut: Vector,
    offset_ut: Vector,
    midpoint_counts: Vector,
    tolerance_ut: float = SYMMETRY_TOLERANCE_UT,
) -> bool:
    """Both bridges' flip readings lie symmetric round zero: their midpoint within ``tolerance_ut``."""
    plus, minus = phase_compensation(static_ut, offset_ut)
    gains = np.array([(bridge_gain(p) + bridge_gain(m)) / 2 for p, m in zip(plus, minus, strict=True)])
    return bool(np.all(np.abs(np.asarray(midpoint_counts, float)) / gains <= tolerance_ut))


@dataclass
class Compensation:
    """The loop's outcome: symmetric or not, after how many flip measurements, the coils' offset
    field it left (µT per bridge) and the last midpoint (counts per bridge)."""

    converged: bool
    measurements: int
    offset_ut: np.ndarray
    midpoint_counts: np.ndarray


#: (coil field flipped, coil field reset) -> the mean ADC counts of both bridges in each phase
FlipPair = Callable[[tuple[float, float], tuple[float, float]], tuple[np.ndarray, np.ndarray]]


def compensate_until_symmetric(
    measure: FlipPair,
    static_ut: Vector,
    offset_ut: Vector = (0.0, 0.0),
    tolerance_ut: float = SYMMETRY_TOLERANCE_UT,
    max_measurements: int = MAX_COMPENSATION_ROUNDS,
) -> Compensation:
    """Seed §3.3.3: measure, flip, measure; if the two readings are not symmetric round zero,
    drive the compensation coil to cancel the offset and measure again, until they are — at most
    ``max_measurements`` flip pairs (an offset beyond the coil's reach, or readings scattering
    more than the tolerance, never get there: reported, not looped on)."""
    if max_measurements < 1:
        raise ValueError("the loop needs at least one flip measurement")
    offset = coil_limited(static_ut, np.asarray(offset_ut, float))
    midpoint = np.zeros(2)
    for n in range(1, max_measurements + 1):
        plus, minus = measure(*phase_compensation(static_ut, offset))
        midpoint = (np.asarray(plus, float) + np.asarray(minus, float)) / 2 - ADC_MID
        if symmetric(static_ut, offset, midpoint, tolerance_ut):
            return Compensation(True, n, offset, midpoint)
        if n < max_measurements:
            offset = compensation_step(static_ut, offset, midpoint)
    return Compensation(False, max_measurements, offset, midpoint)


def heading_from_bridges(h0: float, h1: float) -> tuple[float, int]:
    """Heading (radians from north, clockwise, [0, 2 pi)) from bridge 0 (forward axis, sees
    H cos psi) and bridge 1 (left axis, sees H sin psi), and which bridge gave the angle."""
    magnitude = math.hypot(h0, h1)
    if magnitude == 0:
        return 0.0, 0
    c0, c1 = h0 / magnitude, h1 / magnitude
    if abs(c0) <= SIN45:  # bridge 0 is on the steep part of its sine
        angle = math.acos(max(-1.0, min(1.0, c0)))
        heading = angle if c1 >= 0 else 2 * math.pi - angle
        return heading % (2 * math.pi), 0
    angle = math.acos(max(-1.0, min(1.0, c1)))  # angle between the field and bridge 1's axis
    heading = math.pi / 2 + angle if c0 <= 0 else math.pi / 2 - angle
    return heading % (2 * math.pi), 1


def fit_circle(points: np.ndarray) -> tuple[float, float, float]:
    """Least-squares circle (Kasa) through 2-D points: (centre x, centre y, radius)."""
    pts = np.asarray(points, dtype=float)
    if len(pts) < 3:
        raise ValueError("a circle needs at least three points")
    a = np.column_stack([pts[:, 0], pts[:, 1], np.ones(len(pts))])
    b = -(pts[:, 0] ** 2 + pts[:, 1] ** 2)
    (d, e, f), *_ = np.linalg.lstsq(a, b, rcond=None)
    cx, cy = -d / 2, -e / 2
    return float(cx), float(cy), float(math.sqrt(max(cx * cx + cy * cy - f, 0.0)))


def fit_circle_robust(points: np.ndarray, rounds: int = 2) -> tuple[float, float, float]:
    """:func:`fit_circle` again without the points far off the first fit (more than 3 robust σ,
    at least 0.3 µT): readings of another circle (taken at rest among those while turning) pull
    a least-squares fit toward their centre."""
    pts = np.asarray(points, dtype=float)
    cx, cy, radius = fit_circle(pts)
    for _ in range(rounds):
        residual = np.abs(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) - radius)
        sigma = 1.4826 * float(np.median(residual))
        keep = pts[residual <= max(3.0 * sigma, 0.3)]
        if len(keep) < 3 or len(keep) == len(pts):
            break
        pts = keep
        cx, cy, radius = fit_circle(pts)
    return cx, cy, radius


def circular_mean(angles: Sequence[float]) -> float:
    """Mean direction of angles (radians), in [0, 2 pi)."""
    s = sum(math.sin(a) for a in angles)
    c = sum(math.cos(a) for a in angles)
    return math.atan2(s, c) % (2 * math.pi)


def angle_difference(a: float, b: float) -> float:
    """a - b folded into (-pi, pi]."""
    d = math.remainder(a - b, 2 * math.pi)
    return math.pi if d == -math.pi else d


_DIRECTION = default_protocol().enums["direction"]  # motor.data's direction field
STOPPED, FORWARD, REVERSE = _DIRECTION["STOPPED"], _DIRECTION["FORWARD"], _DIRECTION["REVERSE"]
TURN_LEFT, TURN_RIGHT = _DIRECTION["TURN_LEFT"], _DIRECTION["TURN_RIGHT"]
FLIP_SAMPLES = 20  # one 50 Hz period at 1 kHz, with the flip coil set and again reset
MEASUREMENT_MS = 2 * FLIP_SAMPLES  # a flip measurement takes this long from its stamp


class RunningFieldLearner:
    """The motors' running field, learned again on every straight move.

    Calibration finds it from readings taken while turning, told apart from those at rest by
    motor.data, which arrives a token round late and says "moving" before the first batch of
    steps: on a busy ring readings at rest counted as turning pulled the estimate toward the
    static circle (bench.mapping's rings: 3-15 % short; the heading on the move then ±0.3-1.3°
    off, with a sign that turns with the heading). On a straight move the robot does not turn,
    so the field the sensor sees while driving minus the field at rest before and after the
    move is the running field alone. A reading counts only where motor.data proves the state:
    at rest when the snapshot read before it said stopped and one read after it still did
    (stamped at or after the reading's end); moving when a snapshot read before it showed the
    step counters moved and one read after it still said moving at or after its end. A move
    whose field at rest before and after differs (an anomaly, iron nearby) or whose readings
    scatter is not used. The calibration's estimate weighs as ``prior_moves`` moves.
    """

    REST_KEEP = 3
    MIN_MOVING = 5
    REST_AGREE_UT = 0.25  # a reading scatters by ~0.08 µT; more than this: the field changed
    MAX_SPREAD_UT = 0.5
    MAX_STEP_UT = 1.0

    def __init__(self, running: np.ndarray | Sequence[float], prior_moves: float = 1.0) -> None:
        self.prior_moves = prior_moves
        self.reset(running)

    def reset(self, running: np.ndarray | Sequence[float]) -> None:
        """Start again from a calibration's estimate."""
        self.prior = np.asarray(running, dtype=float).copy()
        self.estimate = self.prior.copy()
        self.total = np.zeros(2)
        self.moves = 0
        self.rejected = 0
        self.previous_direction: int | None = None  # of the snapshot read before this reading
        self.last_steps: tuple[int, int] | None = None
        self.unconfirmed: list[tuple[float, np.ndarray]] = []  # at rest if a later snapshot says so
        self.rest: list[np.ndarray] = []  # proven at rest since the last move
        self.move: dict | None = None
        self.pending: tuple[list[np.ndarray], list[np.ndarray]] | None = None
        self.after: list[np.ndarray] = []

    def add(self, stamp_ms: float, field: np.ndarray, motor: dict) -> bool:
        """One reading (after compensation, running field not subtracted) and motor.data as read
        just after it; True when a move was learned from (``estimate`` changed)."""
        field = np.asarray(field, dtype=float)
        direction = int(motor.get("direction", STOPPED))
        steps = (int(motor.get("steps_left", 0)), int(motor.get("steps_right", 0)))
        motor_ms = float(motor.get("stamp_ms", 0.0))
        previous, self.previous_direction = self.previous_direction, direction
        learned = False
        if direction == STOPPED:
            if self.move is not None:
                self._end_move()
            if previous == STOPPED:
                self.unconfirmed.append((stamp_ms, field))
            proven = [f for s, f in self.unconfirmed if s + MEASUREMENT_MS <= motor_ms]
            self.unconfirmed = [(s, f) for s, f in self.unconfirmed if s + MEASUREMENT_MS > motor_ms]
            self.rest = [*self.rest, *proven][-self.REST_KEEP :]
            if self.pending is not None and proven:
                self.after.extend(proven)
                if len(self.after) >= self.REST_KEEP:
                    learned = self._learn()
            self.last_steps = steps
            return learned
        seq = motor.get("move_seq")
        if self.move is not None and (self.move["direction"], self.move["seq"]) != (direction, seq):
            self.move = None  # one move followed another without a stop heard: no clean rest
        if self.move is None:
            # readings taken before the move began were at rest: it began when motor.data's stamp
            # says, less the time its counters took to get where they are now
            began = self._move_began(motor, steps, motor_ms)
            proven = [f for s, f in self.unconfirmed if s + MEASUREMENT_MS <= began]
            self.rest = [*self.rest, *proven][-self.REST_KEEP :]
            if self.pending is not None:
                self.after.extend(proven)
                learned = self._learn() if self.after else self._drop()
        self.unconfirmed = []  # the motor may have started before they were taken
        if self.move is None:
            self.move = {
                "direction": direction,
                "seq": seq,
                "steps0": self.last_steps,
                "stepped": False,
                "last_ms": -math.inf,
                "before": self.rest,
                "moving": [],
            }
            self.rest = []
        move = self.move
        if move["stepped"] and previous == direction:
            move["moving"].append((stamp_ms, field))
        move["stepped"] = move["stepped"] or (move["steps0"] is not None and steps != move["steps0"])
        move["last_ms"] = max(move["last_ms"], motor_ms)
        return learned

    def _move_began(self, motor: dict, steps: tuple[int, int], motor_ms: float) -> float:
        """The latest time the move heard now can have energised the motors (sim ms)."""
        if self.last_steps is None:
            return -math.inf
        made = max(abs(steps[0] - self.last_steps[0]), abs(steps[1] - self.last_steps[1]))
        if made == 0:
            return motor_ms  # no batch of steps yet when motor.data was stamped
        rate = step_rate_hz(float(motor.get("speed_pct", 0)))
        if rate <= 0:
            return -math.inf
        return motor_ms - 1000.0 * made / rate - MOTOR_TICK_MS

    def _end_move(self) -> None:
        move, self.move = self.move, None
        self.rest, self.after, self.pending = [], [], None
        if move is None or move["direction"] not in (FORWARD, REVERSE):
            return
        moving = [f for s, f in move["moving"] if s + MEASUREMENT_MS <= move["last_ms"]]
        if len(moving) >= self.MIN_MOVING and move["before"]:
            self.pending = (move["before"], moving)

    def _drop(self) -> bool:
        self.pending, self.after = None, []
        return False

    def _learn(self) -> bool:
        assert self.pending is not None
        before, moving = self.pending
        after = self.after
        self.pending, self.after = None, []
        rest_before, rest_after = np.mean(before, axis=0), np.mean(after, axis=0)
        middle = np.median(np.asarray(moving), axis=0)
        spread = float(np.max(np.hypot(*(np.asarray(moving) - middle).T)))
        observed = middle - (rest_before + rest_after) / 2
        if (
            float(np.hypot(*(rest_before - rest_after))) > self.REST_AGREE_UT
            or spread > self.MAX_SPREAD_UT
            or float(np.hypot(*(observed - self.estimate))) > self.MAX_STEP_UT
        ):
            self.rejected += 1
            return False
        self.moves += 1
        self.total += observed
        self.estimate = (self.prior_moves * self.prior + self.total) / (self.prior_moves + self.moves)
        return True


def turned_on_the_spot(start: tuple[int, int], end: tuple[int, int]) -> bool:
    """The step counters moved as a turn on the spot moves them: the two tracks in opposite senses."""
    left, right = end[0] - start[0], end[1] - start[1]
    return left * right < 0


class CalibrationListener:
    """The compass's calibration while someone else turns the robot (main's pilot, seed 001 §4.3).

    Fed every flip measurement (after the static compensation, which is off while calibrating)
    with motor.data as read just after it, it finds the stops on motor.data alone: the motor
    stands again after its step counters moved as a turn on the spot moves them. At each stop it
    keeps the first :attr:`REST_READINGS` readings proven at rest — the snapshot read before the
    reading said "stopped" at the stop's counters and a later one still did, stamped at or after
    the reading's end — and their mean is the stop's field. While the robot turns it keeps the
    readings taken while the motors surely ran, for the running field: from the first one after
    motor.data showed the counters moved (it says "turning" before the first batch of steps,
    which on a busy ring comes 100 ms or more later) until the last stamp it said "turning" (it
    tells of the stop a token round late). A snapshot older than one already heard (a token
    regenerated from an old copy carries an old motor.data) tells nothing and its reading is left
    out. A straight move, or a stop without a reading at rest before the robot moved again, ends
    the listening with ``error``; so does no stop for ``timeout_ms``. ``done`` once ``stops``
    stops have their readings."""

    REST_READINGS = 3

    def __init__(
        self, stops: int, motor: Mapping[str, Any] | None, now_ms: float, timeout_ms: float = 300_000.0
    ) -> None:
        self.wanted = stops
        self.timeout_ms = timeout_ms
        self.progress_ms = now_ms
        self.stops: list[np.ndarray] = []  # the mean field at rest at each stop
        self.turning: list[np.ndarray] = []  # readings taken while the motors surely turned
        self.error = ""
        self.previous: Mapping[str, Any] | None = motor  # the snapshot read before the next reading
        self.newest_ms = float(motor.get("stamp_ms", 0.0)) if motor is not None else -math.inf
        self.stop_steps = _steps(motor) if motor is not None else None  # the counters standing
        self.collecting = False  # standing at a stop that still wants its readings
        self.rest: list[np.ndarray] = []
        self.unconfirmed: list[tuple[float, np.ndarray]] = []
        self.turn: dict[str, Any] | None = None

    @property
    def done(self) -> bool:
        return len(self.stops) >= self.wanted

    def add(self, stamp_ms: float, field: np.ndarray, motor: Mapping[str, Any] | None) -> None:
        """One reading and motor.data as read just after it (None: the motor has not spoken)."""
        if self.done or self.error or motor is None:
            return
        field = np.asarray(field, dtype=float)
        steps, motor_ms = _steps(motor), float(motor.get("stamp_ms", 0.0))
        if motor_ms < self.newest_ms:
            return  # an old copy of motor.data: it cannot tell what the robot did during the reading
        self.newest_ms = motor_ms
        before, self.previous = self.previous, motor
        if self.stop_steps is None:
            self.stop_steps = steps
        if int(motor.get("direction", STOPPED)) == STOPPED:
            if self.turn is not None or steps != self.stop_steps:  # a move ended (seen or not)
                self._end_move(steps, motor_ms)
            elif self.collecting:
                self._at_rest(stamp_ms, field, before, steps, motor_ms)
        else:
            self._moving(stamp_ms, field, steps, motor_ms)
        if not self.done and not self.error and stamp_ms - self.progress_ms > self.timeout_ms:
            self.error = f"no stop seen for {self.timeout_ms / 1000:.0f} s"

    def _at_rest(
        self,
        stamp_ms: float,
        field: np.ndarray,
        before: Mapping[str, Any] | None,
        steps: tuple[int, int],
        motor_ms: float,
    ) -> None:
        if (
            before is not None
            and int(before.get("direction", STOPPED)) == STOPPED
            and _steps(before) == steps
        ):
            self.unconfirmed.append((stamp_ms, field))
        self.rest += [f for s, f in self.unconfirmed if s + MEASUREMENT_MS <= motor_ms]
        self.unconfirmed = [(s, f) for s, f in self.unconfirmed if s + MEASUREMENT_MS > motor_ms]
        if len(self.rest) >= self.REST_READINGS:
            self._take_stop(motor_ms)

    def _take_stop(self, now_ms: float) -> None:
        self.stops.append(np.mean(self.rest[: self.REST_READINGS], axis=0))
        self.collecting, self.rest, self.unconfirmed = False, [], []
        self.progress_ms = now_ms

    def _leave_stop(self, now_ms: float) -> bool:
        """The robot moves on: a stop still collecting keeps the readings it has (False: none)."""
        if not self.collecting:
            return True
        if not self.rest:
            self.error = f"no reading at rest at stop {len(self.stops) + 1} before the robot moved on"
            return False
        self._take_stop(now_ms)
        return True

    def _moving(self, stamp_ms: float, field: np.ndarray, steps: tuple[int, int], motor_ms: float) -> None:
        if not self._leave_stop(motor_ms):
            return
        self.unconfirmed = []
        if self.turn is None:
            self.turn = {"steps0": self.stop_steps, "stepped": False, "readings": [], "last_ms": -math.inf}
        turn = self.turn
        if turn["stepped"]:
            turn["readings"].append((stamp_ms, field))
        turn["stepped"] = turn["stepped"] or steps != turn["steps0"]
        turn["last_ms"] = max(turn["last_ms"], motor_ms)

    def _end_move(self, steps: tuple[int, int], motor_ms: float) -> None:
        turn, self.turn = self.turn, None
        start = self.stop_steps if turn is None else turn["steps0"]
        assert start is not None
        self.stop_steps = steps
        if steps == start:
            return  # the motor said it moved but made no step: still where it was
        if not self._leave_stop(motor_ms) or self.done:  # (a whole turn between two readings)
            return
        if not turned_on_the_spot(start, steps):
            self.error = (
                f"the robot did not turn on the spot (step counters {start} -> {steps}): "
                "not a calibration turn"
            )
            return
        if turn is not None:
            end = turn["last_ms"] - MEASUREMENT_MS
            self.turning += [f for s, f in turn["readings"] if s <= end]
        self.collecting, self.rest, self.unconfirmed = True, [], []
        self.progress_ms = motor_ms


def _steps(motor: Mapping[str, Any]) -> tuple[int, int]:
    return int(motor.get("steps_left", 0)), int(motor.get("steps_right", 0))
