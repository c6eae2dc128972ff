"""The magnetic field at the compass and the two KMZ51 bridges that measure it.

Field at the robot (horizontal, µT): the Earth's field pointing north, local anomalies (Gaussian
bumps), the motors' static field (fixed in the robot frame, large) and, while the motors are
energised, their running field (smaller). A bridge sees the component along its axis plus its
compensation coil's field; the flip coil inverts its response; its own electrical offset drifts
slowly (temperature) and is what the flip measurement removes. The compensation field lowers the
sensitivity a little (seed: it "influences the amplitude", so it must be known as a factor).
Output: 12-bit ADC counts around mid-scale, sampled every millisecond with white noise and a
50 Hz AC field on top.
"""

from __future__ import annotations

import math

import numpy as np

from modules.description.robot import COMPASS_AXES
from modules.description.room import World

ADC_MID = 2048
ADC_MAX = 4095
COUNTS_PER_UT = 20.0  # bridge + amplifier sensitivity: ±100 µT full scale
COMPENSATION_SENSITIVITY_LOSS = 0.002  # relative sensitivity lost per µT of compensation field
MOTOR_STATIC_UT = (6.0, -4.0)  # the stepper magnets' field, robot frame
MOTOR_RUNNING_UT = (2.0, 1.5)  # added while the coils carry current, robot frame
NOISE_UT = 0.5  # white noise per sample
AC_UT = 0.4  # 50 Hz field amplitude
AC_HZ = 50.0
SAMPLE_MS = 1.0
OFFSET_COUNTS = 60.0  # bridge offsets are drawn within ±this
OFFSET_DRIFT_COUNTS_PER_S = 0.5  # random-walk drift of the bridge offsets


class CompassBridges:
    """Two KMZ51 bridges on the robot, with flip and compensation coils."""

    def __init__(self, world: World, rng: np.random.Generator) -> None:
        self.world = world
        self.rng = rng
        self.offsets = rng.uniform(-OFFSET_COUNTS, OFFSET_COUNTS, 2)
        self.last_ms = 0.0

    def field(self, x: float, y: float, theta: float, motors_running: bool) -> np.ndarray:
        """Horizontal field in the robot frame (forward, left), µT."""
        w = self.world
        bx, by = w.earth_field_ut * math.cos(w.north), w.earth_field_ut * math.sin(w.north)
        for a in w.anomalies:
            fade = math.exp(-((x - a.x) ** 2 + (y - a.y) ** 2) / (2 * a.radius**2))
            bx += a.bx * fade
            by += a.by * fade
        c, s = math.cos(theta), math.sin(theta)
        robot = np.array([c * bx + s * by, -s * bx + c * by])
        robot += MOTOR_STATIC_UT
        if motors_running:
            robot += MOTOR_RUNNING_UT
        return robot

    def measure(
        self,
        x: float,
        y: float,
        theta: float,
        motors_running: bool,
        flip: int,
        compensation_ut: tuple[float, float],
        samples: int,
        now_ms: float,
    ) -> np.ndarray:
        """ADC counts of both bridges, shape (2, samples), one sample per millisecond from ``now_ms``."""
        dt = max(0.0, now_ms - self.last_ms) / 1000.0
        self.last_ms = max(self.last_ms, now_ms)
        self.offsets += self.rng.normal(0.0, OFFSET_DRIFT_COUNTS_PER_S * math.sqrt(dt) + 1e-9, 2)
        field = self.field(x, y, theta, motors_running)
        t = (now_ms + np.arange(samples) * SAMPLE_MS) / 1000.0
        ac_phase = self.rng.uniform(0, 2 * math.pi)
        out = np.empty((2, samples))
        sign = 1.0 if flip >= 0 else -1.0
        for k, axis in enumerate(COMPASS_AXES):
            comp = float(compensation_ut[k])
            along = field[0] * math.cos(axis) + field[1] * math.sin(axis)
            ac = AC_UT * np.sin(2 * math.pi * AC_HZ * t + ac_phase + k)
            noise = self.rng.normal(0.0, NOISE_UT, samples)
            gain = COUNTS_PER_UT * (1.0 - COMPENSATION_SENSITIVITY_LOSS * abs(comp))
            out[k] = ADC_MID + sign * gain * (along + comp + ac + noise) + self.offsets[k]
        return np.clip(np.rint(out), 0, ADC_MAX).astype(np.int32)
