"""The WLAN between the LOPS PC and the robot: each packet's delay, seeded and deterministic.

Chapter 10: the cycle of the LOPS packets seen on the robot was at least 11 ms, at most 270 ms,
more than 85 % within 90–110 ms, because "die Daten werden auf einem externen Rechner erfasst und
anschließend mittels WLAN zum Onboardrechner übertragen". The model (ours): every packet takes
a base delay plus a jitter drawn within ``[0, 2·jitter_mean]``; now and then the radio stalls
(retries, another station) and a packet waits up to ``stall_max_ms`` more. The seed's link was
TCP, so packets arrive in order: one queued behind a stalled one follows it no sooner than
``min_gap_ms`` (the robot's socket thread taking one packet), which makes the seed's 11 ms.
With the trigger's 98 ms the cycle is bounded by ``min_gap_ms`` and
``period + 2·jitter_mean + stall_max_ms`` = 98 + 12 + 160 = 270 ms.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class WlanModel:
    """The link's numbers (ours, fitted to chapter 10's cycle times)."""

    base_ms: float = 3.0
    jitter_mean_ms: float = 6.0
    jitter_sigma_ms: float = 2.5
    stall_probability: float = 0.045
    stall_max_ms: float = 160.0
    min_gap_ms: float = 11.0


class WlanLink:
    """Delivers packets sent at given times, in order, each after its drawn delay."""

    def __init__(self, seed: int = 1, model: WlanModel | None = None) -> None:
        self.model = model or WlanModel()
        self.rng = np.random.default_rng([seed, 0x3A11])  # the link's own stream of the seed
        self.last_arrival = -np.inf

    def delay_ms(self) -> float:
        """One packet's own delay, before any queueing behind the one ahead of it."""
        m, rng = self.model, self.rng
        jitter = float(np.clip(rng.normal(m.jitter_mean_ms, m.jitter_sigma_ms), 0.0, 2 * m.jitter_mean_ms))
        stall = float(rng.uniform(0.0, m.stall_max_ms)) if rng.random() < m.stall_probability else 0.0
        return m.base_ms + jitter + stall

    def deliver(self, sent_ms: float) -> float:
        """When the packet sent at ``sent_ms`` arrives (sent times must not go back)."""
        arrival = max(sent_ms + self.delay_ms(), self.last_arrival + self.model.min_gap_ms)
        self.last_arrival = arrival
        return arrival


def cycles(arrivals: Iterable[float]) -> np.ndarray:
    """The times between consecutive arrivals, ms (what the seed's time module plotted)."""
    a = np.fromiter(arrivals, dtype=float)
    return np.diff(a)


def cycle_summary(cycle_ms: np.ndarray) -> dict[str, float]:
    """min, max, and the share within 90–110 ms: chapter 10's three numbers."""
    return {
        "min_ms": float(cycle_ms.min()),
        "max_ms": float(cycle_ms.max()),
        "within_90_110": float(np.mean((cycle_ms >= 90.0) & (cycle_ms <= 110.0))),
        "count": float(len(cycle_ms)),
    }
