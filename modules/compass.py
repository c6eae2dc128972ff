"""The compass module (seed §3.3.3): heading from two KMZ51 bridges, navigation convention.

Every 100 simulated ms: one flip measurement (20 samples with the flip coil set, 20 reset, so
mains fields and the bridges' offsets cancel), the bridge within ±45° of its zero crossing gives
the angle by arccos, a short circular mean filters it (not while the robot turns). The motors'
static field is cancelled in the sensor by the compensation coils once CALIBRATE has learned it;
their running field (while motor.data says the robot moves) is subtracted in software; motor.data
arrives a token round after a start or stop, so the short mean starts again when it changes.

Seed §3.3.3's loop: the two readings of a flip pair should lie symmetric round zero; if their
midpoint is off (the bridge's offset), the compensation coils cancel it and the pair is measured
again, until symmetric — at start and after calibration up to eight pairs in a row (not getting
there is logged and reported, not looped on), then one step on each sample as the offsets drift.
The coils' offset part is driven with the flip (reversed in the reset phase): a field that stays
is inverted with the bridge's response and cannot move the midpoint. The field itself is still
taken from the pair's difference, which the coils' offset part does not enter.

Calibration (seed 001 §4.3: the turn goes through main's pilot): CALIBRATE asks main for the
turn (main's CALIBRATE_COMPASS); main tells the compass to listen (CALIBRATE_LISTEN, eight stops)
and its pilot turns the robot once round in eight 45° turns on the spot, waiting at each stop
for the compass's samples. The compass never commands the motor: it watches motor.data, takes
its readings at rest at each stop and those taken while turning
(:class:`~modules.sensors.compass.CalibrationListener`); a circle fit through the eight stops'
readings gives the static field (centre) and the Earth's field (radius); the readings taken
while turning lie on a circle round static + running field, which gives the running field;
every straight move afterwards measures it again (the field driving minus the field at rest
before and after: :class:`~modules.sensors.compass.RunningFieldLearner`). State:
UNCALIBRATED, CALIBRATING, OK, DISTURBED (the field strength, averaged like the heading, is off
by more than 0.8 % from the calibrated one: an anomaly, iron nearby; a flip measurement's strength
scatters by about 0.5 %, the mean of three by 0.3 %, and an anomaly across the Earth's field bends
the heading long before it changes the strength much — the office pillar's by ~0.7° at 1 %, ~0.55°
at 0.8 %).
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from modules.sensors.compass import (
    FLIP_SAMPLES,
    MAX_COMPENSATION_ROUNDS,
    STOPPED,
    TURN_LEFT,
    TURN_RIGHT,
    CalibrationListener,
    RunningFieldLearner,
    circular_mean,
    compensate_until_symmetric,
    compensation_step,
    fit_circle,
    fit_circle_robust,
    flip_measurement,
    heading_from_bridges,
    phase_compensation,
    symmetric,
)
from modules.units import heading_to_cdeg
from tokenring import UserProgram

log = logging.getLogger("tokenring.compass")

UNCALIBRATED, OK, DISTURBED, CALIBRATING = range(4)  # enum compass_state
SAMPLE_PERIOD_SIM_S = 0.1
MIN_PERIOD_REAL_S = 0.005
SAMPLES = FLIP_SAMPLES  # one 50 Hz period at 1 kHz
FILTER_LENGTH = 3
DISTURBED_RATIO = 0.008
REQUEST_TIMEOUT_S = 5.0  # real seconds main's inbox may take to accept CALIBRATE_COMPASS


class Program(UserProgram):
    module = "compass"

    def setup(self) -> None:
        self.out = self.os.publish()
        self.os.set_own_input_id()
        self.motor = self.os.subscribe("motor.data")
        self.clock = self.hw.clock
        self.compensation = (0.0, 0.0)
        self.offset_compensation = np.zeros(2)  # the coils' flip-synchronous part (seed §3.3.3)
        self.asymmetric_rounds = 0  # flip measurements in a row not symmetric round zero
        self.symmetry: dict = {}
        self.running_field = np.zeros(2)
        self.reference_ut: float | None = None
        self.state = UNCALIBRATED
        self.recent: list[float] = []
        self.strengths: list[float] = []
        self.last_direction = STOPPED
        self.heading = 0.0
        self.bridge = 0
        self.magnitude = 0.0
        self.samples = 0
        self.stamp_ms = 0.0
        self.calibration: dict = {}
        self.learner = RunningFieldLearner(self.running_field)
        self.listener: CalibrationListener | None = None  # listening to a calibration turn
        self._before: tuple[int, tuple[float, float]] = (self.state, self.compensation)
        self.period_real = max(MIN_PERIOD_REAL_S, self.clock.to_real(SAMPLE_PERIOD_SIM_S))

    # -- measuring ------------------------------------------------------------------------------
    def motors_moving(self) -> int:
        """The motor's current direction (0 = standing) as the ring last carried it."""
        return int(self.motor["direction"]) if self.motor.visits else STOPPED

    def read_field(self, compensation: tuple[float, float] | None = None) -> tuple[np.ndarray, float]:
        """One flip measurement: the field both bridges see after compensation (µT), and its time.
        It is also a round of the seed's compensation loop: not symmetric, the coils move."""
        comp = self.compensation if compensation is None else compensation
        plus, minus = phase_compensation(comp, self.offset_compensation)
        adc, stamp = self.hw.measure([(1, plus), (-1, minus)], SAMPLES)
        field, midpoint = flip_measurement(adc[0], adc[1], plus, minus)
        self._follow_offsets(comp, midpoint)
        return field, stamp

    def _follow_offsets(self, static: tuple[float, float], midpoint: np.ndarray) -> None:
        """Seed §3.3.3 on every sample: flip readings not symmetric round zero -> the coils cancel
        the offset they show for the next one (the bridges' offsets drift with temperature)."""
        if symmetric(static, self.offset_compensation, midpoint):
            if self.asymmetric_rounds >= MAX_COMPENSATION_ROUNDS:
                log.info("compass: flip readings symmetric again")
            self.asymmetric_rounds = 0
            return
        self.asymmetric_rounds += 1
        self.offset_compensation = compensation_step(static, self.offset_compensation, midpoint)
        if self.asymmetric_rounds == MAX_COMPENSATION_ROUNDS:
            log.warning(
                "compass: flip readings not symmetric after %d compensations (midpoint %s counts)",
                MAX_COMPENSATION_ROUNDS,
                np.round(midpoint, 1).tolist(),
            )

    def settle_offsets(self) -> bool:
        """The seed's loop before a heading is trusted: flip, compensate, measure again until
        symmetric (at most :data:`MAX_COMPENSATION_ROUNDS` flip pairs); True if it got there."""

        def pair(plus: tuple[float, float], minus: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
            adc, _stamp = self.hw.measure([(1, plus), (-1, minus)], SAMPLES)
            return adc[0].mean(axis=1), adc[1].mean(axis=1)

        result = compensate_until_symmetric(pair, self.compensation, self.offset_compensation)
        self.offset_compensation = result.offset_ut
        self.asymmetric_rounds = 0
        self.symmetry = {
            "converged": result.converged,
            "measurements": result.measurements,
            "offset_ut": result.offset_ut.tolist(),
            "midpoint_counts": result.midpoint_counts.tolist(),
        }
        if result.converged:
            log.info(
                "compass: flip readings symmetric after %d measurements, coils' offset field %s µT",
                result.measurements,
                np.round(result.offset_ut, 2).tolist(),
            )
        else:
            log.warning(
                "compass: flip readings not symmetric after %d measurements (midpoint %s counts)",
                result.measurements,
                np.round(result.midpoint_counts, 1).tolist(),
            )
        return result.converged

    def sample(self) -> None:
        field, stamp = self.read_field()
        if self.listener is not None:
            self._listen(stamp, field)
            if self.listener is None:  # done and published (this reading was uncompensated)
                return
        direction = self.motors_moving()
        learning = self.state in (OK, DISTURBED) and self.motor.visits
        if learning and self.learner.add(stamp, field, self.motor.read()):
            self.running_field = self.learner.estimate.copy()
            log.info(
                "compass: running field %s µT after %d straight moves",
                np.round(self.running_field, 3).tolist(),
                self.learner.moves,
            )
        if direction != STOPPED and self.state != CALIBRATING:
            field = field - self.running_field
        heading, bridge = heading_from_bridges(float(field[0]), float(field[1]))
        started_or_stopped = (direction == STOPPED) != (self.last_direction == STOPPED)
        self.last_direction = direction
        strength = float(np.hypot(*field))
        if direction in (TURN_LEFT, TURN_RIGHT) or started_or_stopped:
            # the mean starts again: the samples before it heard of a start or stop (a token
            # round late) had the running field wrongly subtracted or kept
            self.recent, self.strengths = [heading], [strength]
        else:
            self.recent = [*self.recent[-(FILTER_LENGTH - 1) :], heading]
            self.strengths = [*self.strengths[-(FILTER_LENGTH - 1) :], strength]
        self.heading = circular_mean(self.recent)
        self.bridge = bridge
        self.magnitude = float(np.mean(self.strengths))  # over the heading's samples: 0.3 % scatter
        if self.reference_ut and self.state in (OK, DISTURBED):
            off = abs(self.magnitude - self.reference_ut) / self.reference_ut
            self.state = DISTURBED if off > DISTURBED_RATIO else OK
        self.samples = (self.samples + 1) & 0xFFFF
        self.stamp_ms = stamp
        self.publish()

    def publish(self) -> None:
        self.out.write(
            heading_cdeg=heading_to_cdeg(self.heading),
            state=self.state,
            bridge=self.bridge,
            field_nt=min(0xFFFF, round(self.magnitude * 10)),
            sample=self.samples,
            stamp_ms=int(self.stamp_ms) & 0xFFFFFFFF,
        )

    # -- the loop -------------------------------------------------------------------------------
    def run(self) -> None:
        self.settle_offsets()
        next_ms = self.clock.now_ms()
        while self.running:
            self.sample()
            next_ms = max(next_ms + SAMPLE_PERIOD_SIM_S * 1000, self.clock.now_ms())
            while self.running:
                remaining = max(
                    self.period_real / 2, self.clock.to_real((next_ms - self.clock.now_ms()) / 1000)
                )
                command = self.os.receive_command(timeout=remaining)
                if command is None:
                    break
                self.handle_command(command.name, command.args, command.sender)

    def handle_command(self, name: str, args: dict[str, Any], sender: int) -> None:
        """CALIBRATE: ask main for the turn; CALIBRATE_LISTEN: listen to it (0 stops: stop)."""
        if name == "CALIBRATE":
            self.request_calibration(sender)
        elif name == "CALIBRATE_LISTEN":
            stops = int(args["stops"])
            if stops:
                self.listen(stops)
            elif self.listener is not None:
                self._calibration_failed(f"node {sender} stopped the calibration turn")
        else:
            log.info("compass: ignoring %s from node %d", name, sender)

    # -- calibration ----------------------------------------------------------------------------
    def request_calibration(self, sender: int) -> None:
        """The compass's calibration turn is main's to drive (seed 001 §4.3): ask main for it."""
        if self.listener is not None:
            log.info("compass: already listening to a calibration turn (CALIBRATE from node %d)", sender)
            return
        if not self.os.deliver("main", "CALIBRATE_COMPASS", timeout=REQUEST_TIMEOUT_S):
            log.warning("compass: main did not take CALIBRATE_COMPASS: no calibration turn")

    def listen(self, stops: int) -> None:
        """Learn the motors' fields while someone else turns the robot: compensation off, a
        reading at rest at each of ``stops`` stops seen on motor.data, then the fits."""
        if self.listener is None:
            self._before = (self.state, self.compensation)
        self.state = CALIBRATING
        self.compensation = (0.0, 0.0)
        motor = self.motor.read() if self.motor.visits else None
        self.listener = CalibrationListener(stops, motor, self.clock.now_ms())
        self.recent, self.strengths = [], []
        log.info("compass: listening to a calibration turn of %d stops", stops)
        self.publish()

    def _listen(self, stamp: float, field: np.ndarray) -> None:
        listener = self.listener
        assert listener is not None
        listener.add(stamp, field, self.motor.read() if self.motor.visits else None)
        if listener.error:
            self._calibration_failed(listener.error)
        elif listener.done:
            self._calibrated(listener.stops, listener.turning)

    def _calibrated(self, stops: list[np.ndarray], turning: list[np.ndarray]) -> None:
        """The fits: the stops' circle gives the static field (centre) and the Earth's (radius);
        the readings while turning lie on a circle round static + running field."""
        self.listener = None
        cx, cy, radius = fit_circle(np.array(stops))
        static = np.array([cx, cy])
        if len(turning) >= 8:
            rx, ry, _ = fit_circle_robust(np.array(turning))
            running = np.array([rx, ry]) - static
        else:
            running = np.mean(turning, axis=0) - static if turning else np.zeros(2)
        self.compensation = (-cx, -cy)
        self.settle_offsets()  # the new static field changes the coils' gains: symmetric again
        self.running_field = running
        self.learner.reset(running)
        self.reference_ut = radius
        self.state = OK
        self.recent, self.strengths = [], []
        self.calibration = {
            "static_ut": static.tolist(),
            "running_ut": running.tolist(),
            "earth_ut": radius,
            "stops": len(stops),
            "turning_samples": len(turning),
        }
        log.info(
            "compass calibrated: static field %s µT, running field %s µT, |H| %.1f µT",
            np.round(static, 2).tolist(),
            np.round(running, 2).tolist(),
            radius,
        )
        self.publish()

    def _calibration_failed(self, why: str) -> None:
        log.warning("compass calibration failed: %s", why)
        self.listener = None
        self.state, self.compensation = self._before
        self.recent, self.strengths = [], []
        self.publish()

    def report(self) -> dict:
        return {
            "heading_deg": math.degrees(self.heading),
            "state": self.state,
            "bridge": self.bridge,
            "field_ut": self.magnitude,
            "samples": self.samples,
            "calibration": dict(self.calibration),
            "running_ut": self.running_field.tolist(),
            "running_moves": {"learned": self.learner.moves, "rejected": self.learner.rejected},
            "compensation_ut": list(self.compensation),
            "offset_compensation_ut": self.offset_compensation.tolist(),
            "asymmetric_rounds": self.asymmetric_rounds,
            "symmetry": dict(self.symmetry),
        }
