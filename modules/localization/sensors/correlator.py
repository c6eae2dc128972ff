"""The floor correlator (seed §3.3, table 3.1; Darmstadt): ``correlator.data``'s running sum of
the translation increments along the robot's axis.

Synchronised as table 3.1's sum of the increments since the last sync, from the difference of
the running sum (an i32 of µm that wraps) between two sync times (:class:`CorrelatorSync`).
Logged as ``C``: ``C R`` the increment and the sum, ``C C`` the distance of the period and its
count (table B.6 names no format; B.8 no column). No position of its own. Its correction (the
distance of the step, not while turning) is the core's, off by default: the seed's never ran.
"""

from __future__ import annotations

import math
from typing import Any

from modules.localization.records import fields, integer, num, number
from modules.localization.sensors.base import Sensor, SyncContext, register, sensor_settings
from modules.localization.sync import Sample, SummedSync, wrap_i32


class CorrelatorSync(SummedSync):
    """Table 3.1's sum of the floor correlator's translation increments: ``distance`` (mm) and
    ``speed`` (mm/s), from the correlator module's running sum (``forward_um``)."""

    sensor = "correlator"
    field, scale = "forward_um", 0.001
    running_state = 1  # correlator_state RUNNING
    amount_key, rate_key = "distance", "speed"

    def track_change(self, older: tuple[float, float, float], newer: tuple[float, float, float]) -> float:
        mid = (older[2] + newer[2]) / 2.0  # the displacement along the mean heading: forward > 0
        return (newer[0] - older[0]) * math.cos(mid) + (newer[1] - older[1]) * math.sin(mid)

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any] | None:
        # forward_um wraps as an i32: unwrap against the previous sample before summing
        unwrapped = []
        for sample in samples:
            raw = int(sample.values.get(self.field, 0))
            if self.recent:
                last = round(self.recent[-1][1] / self.scale)
                raw = last + wrap_i32(raw - last)
            unwrapped.append(
                Sample(sample.sensor, sample.stamp_ms, {**sample.values, self.field: raw}, sample.seq)
            )
        return super().synchronise(unwrapped, sync_ms)


def _text(kind: str, v: dict[str, Any]) -> str:
    if kind == "R":
        return f"{num(float(v['increment_um']) / 1000.0, 8, 3)} {num(float(v['forward_um']) / 1000.0, 10, 3)}"
    return f"{num(v['distance'], 8, 3)} {v['count']}"


def _seed_text(kind: str, v: dict[str, Any], context: Any) -> str:
    """The increment (mm): table B.6 names no format; ... the sum of the increments (table 3.1)."""
    if kind == "R":
        return f"{float(v['increment_um']) / 1000.0:8.3f}"
    return f"{float(v['distance']):8.3f} {v['count']}"


def _synchroniser(context: SyncContext) -> CorrelatorSync:
    return CorrelatorSync(context.track)


CORRELATOR = register(
    Sensor(
        name="correlator",
        letter="C",
        title="correlator",
        rank=30,
        synchroniser=_synchroniser,
        channel="correlator.data",
        value_fields=("forward_um", "increment_um", "state"),
        settings=sensor_settings(),
        sets=("darmstadt",),
        raw=fields(forward_um=number, increment_um=number),
        synchronised=fields(distance=number, speed=number, count=integer),
        text=_text,
        seed_text=_seed_text,
    )
)
