"""The gyro module (Darmstadt seed 000 §3.2, §6.2.3): the piezo gyroscope's rate on the ring.

At start it calibrates: the mean of :data:`CALIBRATION_SAMPLES` raw values taken while the robot
stands (motor.data says STOPPED; a move seen restarts the mean) is the zero point NP. Then every
raw value becomes a rate, ω = (raw − NP) · SF with the constant nominal scale factor, and the
orientation is the sum of ω·T since calibration. The data channel always holds the newest
sample, so every token visit carries it. CALIBRATE takes the zero point again (the seed's only
cure for drift: the zero point moves with the sensor's temperature).
"""

from __future__ import annotations

import logging
import math
from typing import Any

from modules.sensors.gyro import CALIBRATION_SAMPLES, SAMPLE_S, SCALE_RAD_S, ZeroPointCalibration, rate
from tokenring import UserProgram

log = logging.getLogger("tokenring.gyro")

UNCALIBRATED, CALIBRATING, RUNNING, NO_DATA = range(4)  # enum gyro_state
STOPPED = 0  # enum direction
READ_PERIOD_SIM_S = 0.1  # the serial line is read this often; each read brings ~5 samples
MIN_PERIOD_REAL_S = 0.005
NO_DATA_READS = 10  # reads in a row without a sample (1 simulated s): state NO_DATA


class Program(UserProgram):
    module = "gyro"

    def setup(self) -> None:
        self.out = self.os.publish()
        self.os.set_own_input_id()
        self.motor = self.os.subscribe("motor.data")
        self.clock = self.hw.clock
        self.state = UNCALIBRATED
        self.calibration = ZeroPointCalibration()
        self.zero_point = 0.0
        self.raw = 0
        self.rate = 0.0
        self.angle = 0.0
        self.samples = 0
        self.lost = 0
        self.stamp_ms = 0.0
        self.restarts = 0
        self.empty_reads = 0
        self.calibrated: dict[str, Any] = {}
        self.period_real = max(MIN_PERIOD_REAL_S, self.clock.to_real(READ_PERIOD_SIM_S))

    def standing(self) -> bool:
        """The robot stands as the ring last carried motor.data (no motor: taken as standing)."""
        return not self.motor.visits or int(self.motor.read()["direction"]) == STOPPED

    def calibrate(self, wanted: int = CALIBRATION_SAMPLES) -> None:
        """Start averaging the zero point over ``wanted`` raw values at rest."""
        self.calibration = ZeroPointCalibration(wanted)
        self.state = CALIBRATING
        log.info("gyro: calibrating the zero point over %d samples at rest", wanted)
        self.publish()

    def take(self, raw: list[int], stamps: list[float], lost: int) -> None:
        """The raw values of one read, oldest first."""
        self.lost += lost
        if lost and self.state == RUNNING:
            log.warning("gyro: %d samples lost (the serial line was not read in time)", lost)
        standing = self.standing()
        for value, stamp in zip(raw, stamps, strict=True):
            self.raw, self.stamp_ms = value, stamp
            self.samples = (self.samples + 1) & 0xFFFF
            if self.state == CALIBRATING:
                if not standing:
                    if self.calibration.values:
                        self.restarts += 1
                    self.calibration.restart()
                elif self.calibration.add(value):
                    self._calibrated()
                continue
            if self.state == RUNNING:
                self.rate = rate(value, self.zero_point)
                self.angle += self.rate * SAMPLE_S

    def _calibrated(self) -> None:
        cal = self.calibration
        self.zero_point = cal.zero_point
        self.state = RUNNING
        self.angle = 0.0
        self.rate = 0.0
        self.calibrated = {"zero_point": cal.zero_point, "spread": cal.spread, "samples": len(cal.values)}
        log.info(
            "gyro calibrated: zero point %.3f counts (spread %.2f counts over %d samples)",
            cal.zero_point,
            cal.spread,
            len(cal.values),
        )

    def publish(self) -> None:
        self.out.write(
            rate_urad_s=max(-(2**31), min(2**31 - 1, round(self.rate * 1e6))),
            raw=self.raw,
            zero_mcounts=round(self.zero_point * 1000),
            angle_mrad=max(-(2**31), min(2**31 - 1, round(self.angle * 1000))),
            sample=self.samples,
            state=self.state,
            stamp_ms=int(self.stamp_ms) & 0xFFFFFFFF,
        )

    def run(self) -> None:
        self.calibrate()
        while self.running:
            raw, stamps, lost = self.hw.read()
            if raw:
                if self.state == NO_DATA:  # back: run on the zero point, or take one first
                    if self.calibrated:
                        self.state = RUNNING
                    else:
                        self.calibrate()
                self.take(raw, stamps, lost)
                self.empty_reads = 0
            else:
                self.empty_reads += 1
                if self.empty_reads == NO_DATA_READS:  # the sensor is silent (no power)
                    log.warning("gyro: no samples in %d reads", NO_DATA_READS)
                    self.state = NO_DATA
            self.publish()
            command = self.os.receive_command(timeout=self.period_real)
            if command is None:
                continue
            if command.name == "CALIBRATE":
                self.calibrate(int(command.args.get("samples") or CALIBRATION_SAMPLES))
            else:
                log.info("gyro: ignoring %s from node %d", command.name, command.sender)

    def report(self) -> dict:
        return {
            "state": self.state,
            "zero_point": self.zero_point,
            "rate_rad_s": self.rate,
            "angle_deg": math.degrees(self.angle),
            "samples": self.samples,
            "lost": self.lost,
            "calibration": dict(self.calibrated),
            "calibration_restarts": self.restarts,
            "scale_rad_s": SCALE_RAD_S,
        }
