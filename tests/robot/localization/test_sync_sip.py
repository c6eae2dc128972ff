"""The seed's count trigger (count 1 on odometry, no minimum period) on the motor's two streams
(issue 53): on the SIP stream (a sample every 100 ms of the motor's clock, stamped with its grid
time) it synchronises exactly every 100 ms of sensor time whatever the token's visits do, as the
Darmstadt robot did on its Pioneer's SIPs (seed 000, §10: 95-105 ms, over 85 % in 98-102 ms); on a
sample every motor tick it synchronises at every token visit that brought a new one.

Token visits come at jittery times; each sees only the newest sample on the token and feeds it
if its stamp is new, as the Localizer does with motor.data.
"""

from __future__ import annotations

import itertools
import math
import random

from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.sync import Sample

SEED_COUNT = {"mode": "count", "sensor": "odometry", "count": 1, "min_period_ms": 0}
CONFIG = {
    "sensors": {name: {"use": False} for name in ("compass", "sonar", "battery", "truth")},
    "walls": {"mode": "off"},
    "filter": {"initial_pose": {"x_mm": 0, "y_mm": 0, "heading_deg": 0}},
    "sync": {"trigger": SEED_COUNT},
}
RATE = 0.0923  # half-steps per ms (50 %)
END_MS = 30_000


def counters(stamp: float) -> tuple[int, int]:
    steps = math.floor(RATE * stamp)
    return steps, steps


def sip_stream() -> list[tuple[float, int]]:
    """(publication time, stamp): a SIP every 100 ms, written up to 3 ms after its grid time."""
    rng = random.Random(1)
    return [(stamp + rng.uniform(0.5, 3.0), stamp) for stamp in range(0, END_MS, 100)]


def tick_stream() -> list[tuple[float, int]]:
    """(publication time, stamp): a sample every motor tick (20 ms, woken up to 8 ms late)."""
    rng = random.Random(2)
    out, t = [], 0.0
    while t < END_MS:
        out.append((t, int(t)))
        t += 20.0 + rng.uniform(0.0, 8.0)
    return out


def synchronise(
    stream: list[tuple[float, int]], pause: tuple[float, float] | None = None
) -> list[tuple[int, int]]:
    """(stamp, dl) of every synchronisation, the token visiting every 10-60 ms (none in ``pause``)."""
    core = LocalizationCore(load_config(CONFIG))
    rng = random.Random(3)
    syncs: list[tuple[int, int]] = []
    seen: int | None = None
    t, i = 0.0, -1
    while t < END_MS + 200:
        t += rng.uniform(10.0, 60.0)
        if pause and pause[0] <= t < pause[1]:
            continue
        while i + 1 < len(stream) and stream[i + 1][0] <= t:
            i += 1
        if i < 0 or stream[i][1] == seen:
            continue
        seen = stream[i][1]
        left, right = counters(seen)
        core.feed(Sample("odometry", seen, {"steps_left": left, "steps_right": right}))
        result = core.maybe_sync()
        if result is not None and (not syncs or result.stamp_ms != syncs[-1][0]):
            syncs.append((result.stamp_ms, result.data["odometry"]["dl"]))
    return syncs


def periods(syncs: list[tuple[int, int]]) -> list[int]:
    return [b[0] - a[0] for a, b in itertools.pairwise(syncs)]


def test_the_count_trigger_on_the_sip_stream_synchronises_every_100_ms() -> None:
    stream = sip_stream()
    syncs = synchronise(stream)
    assert set(periods(syncs)) == {100}
    assert len(syncs) == len(stream)
    # every half-step counted once: the sums add up to the counters' total
    assert sum(dl for _, dl in syncs) == counters(stream[-1][1])[0]


def test_a_late_token_costs_sips_but_never_the_grid() -> None:
    stream = sip_stream()
    syncs = synchronise(stream, pause=(10_020.0, 10_270.0))
    gaps = periods(syncs)
    assert all(p % 100 == 0 for p in gaps) and max(gaps) in (300, 400)
    assert sum(1 for p in gaps if p == 100) == len(gaps) - 1
    assert sum(dl for _, dl in syncs) == counters(stream[-1][1])[0]


def test_the_count_trigger_on_a_sample_every_tick_follows_the_token() -> None:
    stream = tick_stream()
    syncs = synchronise(stream)
    gaps = periods(syncs)
    within = sum(1 for p in gaps if 98 <= p <= 102) / len(gaps)
    assert within < 0.1  # the seed's figure, over 85 %, is out of reach
    assert sum(dl for _, dl in syncs) == counters(stream[-1][1])[0]
