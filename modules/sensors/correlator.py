"""The correlator module's arithmetic (Darmstadt seed 000 §3.3, table 3.1): the sum of the
floor correlator's translation increments, as the seed synchronised it ("Summe der
Translationsinkremente"), kept as a wrapping 32-bit count of µm so a reader takes differences.

The sensor cannot tell a turn's excess, a bogus reading on the spot or a wrong direction from a
good reading (§3.3: only another sensor can): the sum takes every increment as it came.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

#: the sum wraps at ±2^31 µm (±2147 m), as the i32 on the wire does
WRAP = 2**32


def wire_i32(value: int) -> int:
    """``value`` as a signed 32-bit integer, wrapped (two's complement)."""
    return (value + 2**31) % WRAP - 2**31


def translation_between(newer_um: int, older_um: int) -> int:
    """The translation (µm) between two values of a wrapping sum: what a reader of the data
    channel adds up between two visits (correct while less than 2147 m lies between them)."""
    return wire_i32(newer_um - older_um)


@dataclass
class TranslationSum:
    """The running sum of the increments, the newest one and its stamp, samples counted."""

    total_um: int = 0  # wrapped to i32
    newest_um: int = 0
    stamp_ms: float = 0.0
    samples: int = 0  # since start, not wrapped
    backward: int = 0  # samples that read backwards (a reverse drive, a flip or a bogus reading)
    backward_um: int = 0  # their size, summed (not wrapped)
    lost: int = 0

    def add(self, increments_um: Iterable[int], stamps_ms: Iterable[float], lost: int = 0) -> None:
        """Take one read's increments (µm) with their stamps (ms), oldest first."""
        self.lost += lost
        for increment, stamp in zip(increments_um, stamps_ms, strict=True):
            self.total_um = wire_i32(self.total_um + int(increment))
            self.newest_um = int(increment)
            self.stamp_ms = float(stamp)
            self.samples += 1
            if increment < 0:
                self.backward += 1
                self.backward_um -= int(increment)

    def reset(self) -> None:
        """Start the sum from 0 again; the counters run on."""
        self.total_um = 0
