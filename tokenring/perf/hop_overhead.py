"""tokenring's own share of a hop, with its error: what a node adds per hop on top of a bare
Zenoh forwarder, and how much of the CPUs the host took meanwhile.

A pair (a ring measured against a bare Zenoh ring of the same size and topology) gives
``(ring median - bare median) / N``; on two shared cores one pair says little, so pairs are
repeated and given as their mean with a Student-t 95 % interval. On a virtual machine the slow
seconds are the hypervisor's (``/proc/stat``'s steal time rises exactly while a bare ring slows),
so every measure records its steal and a pair that lost more than :data:`STEAL_LIMIT_PCT` is set
apart. ``tokenring bench`` and the suite (``bench/``) share
these figures.
"""

from __future__ import annotations

import math
import statistics
from typing import Any

#: a run that lost more of the machine's CPU time than this to the hypervisor (steal) is
#: disturbed from outside
STEAL_LIMIT_PCT = 10.0


def cpu_jiffies() -> tuple[int, int]:
    """(steal, total) clock ticks of all CPUs since boot, from ``/proc/stat``'s ``cpu`` line;
    (0, 0) where the kernel does not say."""
    try:
        with open("/proc/stat") as stat:
            fields = stat.readline().split()
    except OSError:
        return 0, 0
    if len(fields) < 9 or fields[0] != "cpu":
        return 0, 0
    ticks = [int(x) for x in fields[1:9]]  # user nice system idle iowait irq softirq steal
    return ticks[7], sum(ticks)


def steal_pct(before: tuple[int, int], after: tuple[int, int]) -> float:
    """The share (%) of the CPUs' time between two :func:`cpu_jiffies` readings that the
    hypervisor gave to someone else."""
    total = after[1] - before[1]
    return 100.0 * (after[0] - before[0]) / total if total > 0 else 0.0


def within_steal_limit(pair_steal: tuple[float, float] | list[float], limit: float = STEAL_LIMIT_PCT) -> bool:
    """A pair whose ring and bare run each lost at most ``limit`` % of the CPUs to the host."""
    return max(pair_steal) <= limit


def pair_share_us(ring_median_ms: float, bare_median_ms: float, nodes: int) -> float:
    """One pair's own share per hop in µs: the ring's median round trip above the bare ring's, per node."""
    return (ring_median_ms - bare_median_ms) * 1e3 / nodes


def interval(values: list[float], confidence: float = 0.95) -> dict[str, Any]:
    """Mean of ``values`` with its two-sided Student-t confidence interval (NaN bounds for fewer
    than two values: one pair gives no spread)."""
    n = len(values)
    if n == 0:
        return {"mean": math.nan, "lo": math.nan, "hi": math.nan, "sd": math.nan, "n": 0}
    mean = statistics.fmean(values)
    if n == 1:
        return {"mean": mean, "lo": math.nan, "hi": math.nan, "sd": math.nan, "n": 1}
    from scipy.stats import t  # the t quantile; imported here, as only a measure needs it

    sd = statistics.stdev(values)
    half = float(t.ppf(0.5 + confidence / 2, n - 1)) * sd / math.sqrt(n)
    return {"mean": mean, "lo": mean - half, "hi": mean + half, "sd": sd, "n": n}


def describe(share: dict[str, Any]) -> str:
    """``12.3 µs per hop (95 % CI 8.1 to 16.5, 6 pairs)``; one pair: no interval; none: no share."""
    if share["n"] == 0:
        return "no pair to give it"
    if share["n"] < 2:
        return f"{share['mean']:.1f} µs per hop (1 pair: no interval)"
    return (
        f"{share['mean']:.1f} µs per hop (95 % CI {share['lo']:.1f} to {share['hi']:.1f}, {share['n']} pairs)"
    )


def describe_interleaved(record: dict[str, Any]) -> str:
    """An interleaved record (:mod:`tokenring.perf.interleaved_pairs`) in a line: the own share over the pairs
    within the steal limit and over every usable pair."""
    calm, every = record["own_share_us"], record["own_share_all_us"]
    return (
        f"{record['topology']} {record['nodes']}: {describe(calm)} within {record['steal_limit_pct']:.0f} % steal; "
        f"{describe(every)} over {record['pairs_usable']} of {record['pairs']} pairs"
    )
