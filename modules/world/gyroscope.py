"""The piezo rate gyroscope (Darmstadt seed 000 §3.2, Siegel 2001) and its hardware request.

Every 20.48 ms the gyro gives one raw value: its zero point plus the true rotation rate over the
sample's interval divided by the scale factor, with white noise, rounded to whole ADC counts
(12 bits, mid-scale 2048). The zero point depends on the sensor's temperature, which warms up
after power-on, and walks slowly (drift); the true scale factor differs from the nominal one by
a fixed error drawn at power-on. The nominal scale factor is the seed's: its figure 10.2 shows
one bit as 1.7436e-5 rad in a 20.48 ms sample, 8.5136e-4 rad/s (0.0488 °/s, ±100 °/s over
±2048 counts). Deterministic from the world's seed (a random stream of its own).

The world serves it at ``hw/gyro/read`` (:class:`GyroDevice`, :data:`modules.world.devices`):
``{}`` → ``{raw: [counts...], stamps_ms: [...], temperature_c, lost, period_ms, power}``, every
sample taken since the previous read (at most :data:`MAX_SAMPLES`, the oldest dropped and counted
in ``lost``). The module reaches it through :class:`~modules.world.gyroclient.GyroHardware` only; the true zero point and
scale are the model's, for tests and scoring.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from modules.world.sim import HardwareRequestError

SAMPLE_MS = 20.48  # one raw value (seed §3.2)
ADC_MID = 2048
ADC_MAX = 4095
#: the nominal scale factor, rad/s per count: one bit = 1.7436e-5 rad per 20.48 ms (seed fig. 10.2)
SCALE_RAD_S = (0.000013599955 + 0.000003835885) / (SAMPLE_MS / 1000.0)
ZERO_SPREAD_COUNTS = 20.0  # the zero point at 20 °C is drawn within mid-scale ± this
NOISE_COUNTS = 0.3  # white noise per sample: at rest mostly one value, now and then the next bit
SCALE_ERROR = 0.01  # the true scale factor is the nominal one × (1 + e), |e| ≤ this
TEMP_COEFF_COUNTS_PER_K = 0.3  # zero-point shift per kelvin
AMBIENT_C = 20.0
WARM_UP_K = 2.0  # the sensor warms by this much after power-on ...
WARM_UP_S = 600.0  # ... with this time constant
DRIFT_COUNTS_PER_SQRT_S = 0.01  # random walk of the zero point
MAX_SAMPLES = 256  # samples a read returns at most (5.2 s): older ones are lost
#: the stream of the world's seed the gyro draws from (the simulator's own are 0..3)
SEED_STREAM = 16


class RateGyro:
    """The sensor alone: raw values from true rates at given times (ms since power-on)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.zero_20c = ADC_MID + float(rng.uniform(-ZERO_SPREAD_COUNTS, ZERO_SPREAD_COUNTS))
        self.scale_error = float(rng.uniform(-SCALE_ERROR, SCALE_ERROR))
        self.walk = 0.0
        self.last_ms = 0.0

    @property
    def true_scale(self) -> float:
        """rad/s per count as the sensor really has it."""
        return SCALE_RAD_S * (1.0 + self.scale_error)

    def temperature_c(self, t_ms: float) -> float:
        """The sensor's temperature: it warms up after power-on."""
        return AMBIENT_C + WARM_UP_K * (1.0 - math.exp(-max(0.0, t_ms) / 1000.0 / WARM_UP_S))

    def zero_point(self, t_ms: float) -> float:
        """The true zero point now (counts, not whole): temperature plus the drift walked so far."""
        return self.zero_20c + TEMP_COEFF_COUNTS_PER_K * (self.temperature_c(t_ms) - AMBIENT_C) + self.walk

    def sample(self, t_ms: float, rate_rad_s: float) -> int:
        """One raw value at ``t_ms`` for the mean true rate (CCW) over the sample's interval."""
        dt = max(0.0, t_ms - self.last_ms) / 1000.0
        self.last_ms = max(self.last_ms, t_ms)
        self.walk += float(self.rng.normal(0.0, DRIFT_COUNTS_PER_SQRT_S * math.sqrt(dt) + 1e-12))
        analog = self.zero_point(t_ms) + rate_rad_s / self.true_scale + self.rng.normal(0.0, NOISE_COUNTS)
        return int(min(ADC_MAX, max(0, round(analog))))


def gyro_rng(seed: int) -> np.random.Generator:
    """The gyro's own random stream of the world's ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(SEED_STREAM,)))


class GyroDevice:
    """The gyro on the simulated robot: samples on a 20.48 ms grid from the world's rotation.

    The world's heading is known where it is asked (``pose_at`` now); between two reads it is
    taken to turn evenly, so each sample's rate is the angle turned over its interval and the
    rates of all samples sum to the angle the robot really turned (read to read)."""

    def __init__(self, sim: Any, gyro: RateGyro | None = None) -> None:
        self.sim = sim
        self.clock = sim.clock
        self.gyro = gyro or RateGyro(gyro_rng(int(sim.seed)))
        now = self.clock.now_ms()
        self.seen = (now, float(sim.pose_at(now).theta))  # (time, heading) of the last read
        self.next_tick = math.floor(now / SAMPLE_MS) + 1  # index of the next sample on the grid
        self.tick_theta = self.seen[1]  # heading at the last sample taken

    def read(self, _: dict[str, Any] | None = None) -> dict[str, Any]:
        """``hw/gyro/read``: every sample since the previous read (the newest last)."""
        with self.sim.lock:
            now = self.sim.advance()
            theta = float(self.sim.pose_at(now).theta)
            powered = bool(self.sim.powered)
        since, before = self.seen
        turned = math.remainder(theta - before, 2 * math.pi)
        span = max(now - since, 1e-9)
        last = math.floor(now / SAMPLE_MS)
        first = max(self.next_tick, last - MAX_SAMPLES + 1)
        lost = max(0, first - self.next_tick)
        raw: list[int] = []
        stamps: list[float] = []
        previous_t = (first - 1) * SAMPLE_MS
        previous = before + turned * min(1.0, max(0.0, (previous_t - since) / span))
        if lost == 0:
            previous = self.tick_theta
        for k in range(first, last + 1):
            t = k * SAMPLE_MS
            heading = before + turned * min(1.0, max(0.0, (t - since) / span))
            rate = (heading - previous) / (SAMPLE_MS / 1000.0)
            previous = heading
            sample = self.gyro.sample(t, rate)
            if powered:
                raw.append(sample)
                stamps.append(t)
        if last >= first:
            self.tick_theta = previous
            self.next_tick = last + 1
        self.seen = (now, theta)
        return {
            "raw": raw,
            "stamps_ms": stamps,
            "temperature_c": self.gyro.temperature_c(now),
            "lost": lost,
            "period_ms": SAMPLE_MS,
            "power": powered,
        }

    def handle(self, what: str, request: dict[str, Any]) -> Any:
        """Answer a request below ``hw/`` (``gyro/read``)."""
        if what == "gyro/read":
            return self.read(request)
        raise HardwareRequestError(f"no hardware at hw/{what} (have: gyro/read)")
