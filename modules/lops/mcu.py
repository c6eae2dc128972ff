"""LOPS's hardware, as the world makes it: the MCU, the robot's transmitter, three receivers.

Each trigger (§3.5) the MCU times the robot transmitter's 40 kHz ultrasound from its radio
trigger to each receiver. A time holds the flight and the fixed delays the seed's negative
Offset stands for: ``time = (distance − Offset) / Steigung`` (the inverse of lopscpp's
``Entfernung = Laufzeit · Signalgeschwindigkeit + Offset``). A receiver behind a wall or obstacle
(the room's geometry, :func:`modules.world.physics.cast_rays`) hears no direct sound: nothing, or
a reflection's longer path. Otherwise a random disturbance (people, other sound, the seed's 404 of
2024) loses the signal or lets a late echo in; the rest carry ~4 mm of noise and the MCU's
1 µs timer tick. The seed gives none of these numbers; they are ours, fitted to chapter 10.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from modules.description.room import World
from modules.lops.config import LopsConfig
from modules.world.physics import cast_rays

#: what became of one receiver's measurement
OK, SHADOW, LOST, ECHO = "ok", "shadow", "lost", "echo"


@dataclass(frozen=True)
class Hardware:
    """The physics of the ultrasound and the MCU (ours: the seed gives no numbers)."""

    speed_mm_per_us: float = 0.330  # the true speed of sound (the house's 330 m/s)
    range_noise_mm: float = 4.0  # σ of one distance: the position scatters by about ±1 cm
    tick_us: float = 1.0  # the MCU's timer resolution
    window_us: float = 90_000.0  # the MCU listens this long after its trigger (within 98 ms)
    disturbance: float = 0.072  # per receiver and trigger: 1 − (1 − p)³ ≈ 20 % of triggers
    late_share: float = 0.5  # of the disturbances: a late echo (else the signal is lost)
    late_mm: tuple[float, float] = (30.0, 1500.0)  # a late echo's extra path, uniform
    shadow_echo: float = 0.5  # a shadowed receiver hears a reflection (else nothing)
    shadow_late_mm: tuple[float, float] = (300.0, 2000.0)  # a reflection's extra path, uniform


@dataclass(frozen=True)
class Reading:
    """One trigger's times of flight (µs, None: nothing heard) and what happened at each receiver."""

    t_ms: float
    times_us: tuple[float | None, float | None, float | None]
    kinds: tuple[str, str, str]
    true_mm: tuple[float, float, float]  # the true distances (for tests and plots, never sent)


class Mcu:
    """The MCU and its receivers in ``world``, placed and calibrated as ``config`` says."""

    def __init__(
        self, world: World, config: LopsConfig, hardware: Hardware | None = None, seed: int = 1
    ) -> None:
        self.world = world
        self.config = config
        self.hw = hardware or Hardware()
        self.rng = np.random.default_rng([seed, 0x1095])  # LOPS's own stream of the seed
        self.receivers = np.asarray(config.receivers, dtype=float)

    def true_distances(self, x: float, y: float) -> np.ndarray:
        """The straight-line distances from the transmitter at (x, y) to the receivers, mm."""
        return np.hypot(self.receivers[:, 0] - x, self.receivers[:, 1] - y)

    def shadowed(self, x: float, y: float) -> tuple[bool, bool, bool]:
        """Per receiver: does a wall or obstacle stand between (x, y) and it?"""
        dist = self.true_distances(x, y)
        angles = np.arctan2(self.receivers[:, 1] - y, self.receivers[:, 0] - x)
        hits = cast_rays(self.world, x, y, angles, max_range=float(dist.max()) + 1.0)
        blocked = hits.distance < dist - 1e-6
        return (bool(blocked[0]), bool(blocked[1]), bool(blocked[2]))

    def measure(self, t_ms: float, x: float, y: float) -> Reading:
        """One trigger with the transmitter at (x, y) (the robot's reference point)."""
        hw, rng = self.hw, self.rng
        true = self.true_distances(x, y)
        shadow = self.shadowed(x, y)
        times: list[float | None] = []
        kinds: list[str] = []
        for i in range(3):
            path: float | None = float(true[i]) + float(rng.normal(0.0, hw.range_noise_mm))
            kind = OK
            if shadow[i]:
                kind = SHADOW
                path = float(true[i]) + float(rng.uniform(*hw.shadow_late_mm))
                if rng.random() >= hw.shadow_echo:
                    path = None
            elif rng.random() < hw.disturbance:
                if rng.random() < hw.late_share:
                    kind = ECHO
                    path = float(true[i]) + float(rng.uniform(*hw.late_mm))
                else:
                    kind, path = LOST, None
            time_us = self._time(i, path)
            if time_us is None and kind == OK:
                kind = LOST  # beyond the MCU's window
            times.append(time_us)
            kinds.append(kind)
        return Reading(
            t_ms,
            (times[0], times[1], times[2]),
            (kinds[0], kinds[1], kinds[2]),
            (float(true[0]), float(true[1]), float(true[2])),
        )

    def _time(self, i: int, path: float | None) -> float | None:
        """The MCU's count for a sound path of ``path`` mm: flight plus the fixed delays, in ticks."""
        if path is None:
            return None
        t = (path - self.config.offsets[i]) / self.hw.speed_mm_per_us
        if not 0 < t <= self.hw.window_us or not math.isfinite(t):
            return None
        return round(t / self.hw.tick_us) * self.hw.tick_us
