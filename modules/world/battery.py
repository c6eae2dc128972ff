"""The two lead-gel batteries: 12 V / 24 Wh for the electronics, 3 x 12 V / 72 Wh for the motors.

Open-circuit voltage per 12 V block follows a lead-gel discharge curve over the state of charge;
under load it sags by the internal resistance. The electronics draw a steady current; the motor
pack draws while steps are issued (about 45 minutes of driving at 1 A motor current, SPEC §5).
Deep discharge starts below 10.5 V per block (seed §3.3.7).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SOC_POINTS = np.array([0.0, 0.05, 0.10, 0.20, 0.50, 0.80, 1.00])
BLOCK_VOLTS = np.array([10.2, 11.0, 11.5, 11.8, 12.2, 12.5, 12.8])  # open circuit, per 12 V block
BLOCK_RESISTANCE_OHM = 0.08
DEEP_DISCHARGE_V = 10.5  # per block
ELECTRONICS_CURRENT_A = 0.4  # eight computers, sonar, display
MOTOR_PACK_A_PER_MOTOR_A = 2.67  # pack current at 1 A phase current: 2 Ah in 45 min


@dataclass
class Battery:
    """A series string of ``blocks`` 12 V lead-gel blocks."""

    name: str
    blocks: int
    capacity_wh: float
    soc: float = 1.0
    current_a: float = 0.0

    @property
    def capacity_ah(self) -> float:
        return self.capacity_wh / (12.0 * self.blocks)

    def open_circuit_v(self) -> float:
        return float(np.interp(self.soc, SOC_POINTS, BLOCK_VOLTS)) * self.blocks

    def voltage(self) -> float:
        """Terminal voltage under the present load."""
        return self.open_circuit_v() - self.current_a * BLOCK_RESISTANCE_OHM * self.blocks

    def drain(self, current_a: float, seconds: float) -> None:
        """Take ``current_a`` for ``seconds`` of simulated time."""
        if seconds > 0:
            self.soc = max(0.0, self.soc - current_a * seconds / 3600.0 / self.capacity_ah)

    def deep_discharged(self) -> bool:
        return self.voltage() < DEEP_DISCHARGE_V * self.blocks

    def as_dict(self) -> dict[str, float]:
        return {"v": round(self.voltage(), 4), "soc": round(self.soc, 6), "a": round(self.current_a, 4)}
