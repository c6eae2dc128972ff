"""The charger module's arithmetic (seed §3.3.7): battery voltages from the ADC, state of charge,
remaining driving time, and the deep-discharge cut.

Batteries: one 12 V / 24 Wh lead-gel block for the electronics, three in series (36 V / 72 Wh) for
the motors. The state of charge is read off the lead-gel rest-voltage curve after adding back the
sag of the measured load current through the blocks' internal resistance. Deep discharge starts
below 10.5 V per 12 V block: then everything is switched off.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

ADC_COUNTS = 1023
ELECTRONICS_FULL_SCALE_V = 15.0  # the dividers in front of the charger's ADC
MOTORS_FULL_SCALE_V = 45.0
CURRENT_FULL_SCALE_A = 5.0
SOC_POINTS = np.array([0.0, 0.05, 0.10, 0.20, 0.50, 0.80, 1.00])
BLOCK_REST_V = np.array([10.2, 11.0, 11.5, 11.8, 12.2, 12.5, 12.8])  # lead-gel datasheet, per block
BLOCK_RESISTANCE_OHM = 0.08
DEEP_DISCHARGE_V = 10.5  # per 12 V block
ELECTRONICS_CURRENT_A = 0.4
ELECTRONICS_MINUTES_FULL = 24.0 / (12.0 * ELECTRONICS_CURRENT_A) * 60  # 5 h
DRIVING_MINUTES_FULL = 45.0  # the motor pack at 1 A motor current (seed §3.3.1)
LOW_PERCENT = 20


def counts_to_value(counts: int, full_scale: float) -> float:
    """An ADC reading -> volts (or amperes) through its divider."""
    return counts / ADC_COUNTS * full_scale


def state_of_charge(volts: float, blocks: int, current_a: float = 0.0) -> float:
    """State of charge 0..1 from the terminal voltage of ``blocks`` 12 V blocks under ``current_a``."""
    rest_per_block = volts / blocks + current_a * BLOCK_RESISTANCE_OHM
    return float(np.interp(rest_per_block, BLOCK_REST_V, SOC_POINTS))


def remaining_minutes(motors_soc: float, electronics_soc: float) -> float:
    """Estimated driving time left: the motor pack at 1 A, unless the electronics give out first."""
    return min(motors_soc * DRIVING_MINUTES_FULL, electronics_soc * ELECTRONICS_MINUTES_FULL)


@dataclass
class DischargeGuard:
    """Trips when any 12 V block reads below 10.5 V in ``confirm`` consecutive samples."""

    confirm: int = 3
    low_samples: int = 0

    def check(self, electronics_v: float, motors_v: float) -> bool:
        low = electronics_v < DEEP_DISCHARGE_V or motors_v / 3 < DEEP_DISCHARGE_V
        self.low_samples = self.low_samples + 1 if low else 0
        return self.low_samples >= self.confirm


@dataclass
class Smoother:
    """Running mean over the last ``length`` values."""

    length: int = 8
    values: deque = field(default_factory=deque)

    def add(self, value: float) -> float:
        self.values.append(value)
        while len(self.values) > self.length:
            self.values.popleft()
        return sum(self.values) / len(self.values)
