"""Sonar physics: what one transmitter/receiver pair's envelope ADC records after a ping.

The beam (30° at half sensitivity) is sampled by rays; every ray that meets a surface returns an
echo starting at the round-trip time of that surface. An echo's amplitude falls with distance,
with the ray's angle off the beam axis and steeply with the incidence angle on the surface (a
wall hit at a grazing angle reflects the sound away: no echo). Its envelope rises like a driven
resonator, ``A (1 - exp(-t / tau))``, with ``tau`` growing with distance — so the rising edge gets
flatter the farther and the more oblique the surface, and a plain threshold reads late (the seed's
25 cm echo crosses its threshold at about 28 cm). The receiver adds a little low-pass noise.
Samples are 8-bit, 510 of them, every 20 µs.
"""

from __future__ import annotations

import math

import numpy as np

from modules.description.robot import SONAR_BEAM_RAD, SONAR_SAMPLE_US, SONAR_SAMPLES, SPEED_OF_SOUND_M_S
from modules.description.room import World
from modules.world.physics import cast_rays

MM_PER_SAMPLE = SPEED_OF_SOUND_M_S * 1000.0 * SONAR_SAMPLE_US * 1e-6 / 2  # one-way: 3.3 mm
BEAM_SIGMA = SONAR_BEAM_RAD / 2 / math.sqrt(2 * math.log(2))  # Gaussian with half sensitivity at ±15°
RAY_SPREAD = math.radians(25)  # rays out to ±25° (the beam's skirt)
RAY_COUNT = 51
AMPLITUDE_25CM = 200.0  # a head-on wall at 25 cm, counts
AMPLITUDE_EXPONENT = 0.9  # amplitude ~ distance^-0.9: a head-on wall fades into the threshold near 1.5 m
TAU_25CM = 130.0  # rise time constant at 25 cm, samples
INCIDENCE_POWER = 4.0  # echo strength ~ cos(incidence)^4
DECAY = 30.0  # decay time constant after the ping ends, samples
DEFAULT_PING_SAMPLES = 60  # 1.2 ms burst
BASELINE = 3.0  # counts
NOISE = 1.0  # counts, standard deviation of the (low-pass) receiver noise
NOISE_CORRELATION = 0.95  # first-order low-pass of the receiver noise
RANGE_JITTER_MM = 10.0  # σ 1 cm of the echo's start (air, surface texture)


def echo_shapes(
    distances_mm: np.ndarray, gains: np.ndarray, ping_samples: int, onset_jitter: float = 0.0
) -> np.ndarray:
    """Noise-free envelopes of echoes from surfaces at ``distances_mm`` with relative ``gains``:
    one row of 510 float counts per echo."""
    distance = np.maximum(np.asarray(distances_mm, dtype=float), 10.0)[:, None]
    gain = np.asarray(gains, dtype=float)[:, None]
    t = np.arange(SONAR_SAMPLES, dtype=float)[None, :] - (distance / MM_PER_SAMPLE + onset_jitter)
    peak = AMPLITUDE_25CM * (250.0 / distance) ** AMPLITUDE_EXPONENT * gain
    tau = TAU_25CM * np.sqrt(distance / 250.0)
    rising = peak * (1.0 - np.exp(-np.clip(t, 0.0, ping_samples) / tau)) / (1.0 - np.exp(-ping_samples / tau))
    decaying = peak * np.exp(-np.clip(t - ping_samples, 0.0, None) / DECAY)
    return np.where(t < 0, 0.0, np.where(t < ping_samples, rising, decaying))


def echo_shape(distance_mm: float, gain: float, ping_samples: int, onset_jitter: float = 0.0) -> np.ndarray:
    """The noise-free envelope of one echo (float counts over the 510 samples)."""
    return echo_shapes(np.array([distance_mm]), np.array([gain]), ping_samples, onset_jitter)[0]


_NOISE_KERNEL = NOISE_CORRELATION ** np.arange(100)
_NOISE_GAIN = 1.0 / math.sqrt(float(np.sum(_NOISE_KERNEL**2)))


def receiver_noise(rng: np.random.Generator, sigma: float = NOISE) -> np.ndarray:
    """Low-pass Gaussian noise (first-order, ``NOISE_CORRELATION``) with standard deviation ``sigma``."""
    white = rng.normal(0.0, sigma * _NOISE_GAIN, SONAR_SAMPLES + len(_NOISE_KERNEL) - 1)
    return np.convolve(white, _NOISE_KERNEL, mode="valid")


def to_adc(envelope: np.ndarray) -> np.ndarray:
    """Float counts -> the 8-bit envelope ADC's samples."""
    return np.clip(np.rint(envelope), 0, 255).astype(np.uint8)


def envelope(
    world: World,
    x: float,
    y: float,
    direction: float,
    rng: np.random.Generator | None,
    ping_samples: int = DEFAULT_PING_SAMPLES,
    jitter_mm: float = RANGE_JITTER_MM,
    noise: float = NOISE,
) -> np.ndarray:
    """The 510 uint8 samples a pair at (x, y) looking along ``direction`` records in ``world``."""
    offsets = np.linspace(-RAY_SPREAD, RAY_SPREAD, RAY_COUNT)
    hits = cast_rays(world, x, y, direction + offsets, max_range=SONAR_SAMPLES * MM_PER_SAMPLE)
    gain = np.exp(-0.5 * (offsets / BEAM_SIGMA) ** 2) * np.cos(hits.incidence) ** INCIDENCE_POWER
    onset_jitter = (rng.normal(0.0, jitter_mm) if rng is not None and jitter_mm else 0.0) / MM_PER_SAMPLE
    audible = np.isfinite(hits.distance) & (gain > 0.02)
    signal = np.zeros(SONAR_SAMPLES)
    if audible.any():
        signal = echo_shapes(hits.distance[audible], gain[audible], ping_samples, onset_jitter).max(axis=0)
    base = BASELINE + (receiver_noise(rng, noise) if rng is not None and noise else 0.0)
    return to_adc(signal + base)
