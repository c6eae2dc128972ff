"""``tokenring bench``'s library: the ring's round trip beside a bare Zenoh ring, rings that run
until stopped, interleaved pairs, and the "own share per hop" statistics."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring.perf.defaults import ROUTER_FROM
    from tokenring.perf.hop_overhead import (
        STEAL_LIMIT_PCT,
        cpu_jiffies,
        describe,
        describe_interleaved,
        interval,
        pair_share_us,
        steal_pct,
        within_steal_limit,
    )
    from tokenring.perf.interleaved_pairs import interleave
    from tokenring.perf.roundtrip import RingRun, run_bare, run_ring, summarize
    from tokenring.perf.running_rings import BareRing, LiveRing
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "BareRing": "tokenring.perf.running_rings",
            "cpu_jiffies": "tokenring.perf.hop_overhead",
            "describe": "tokenring.perf.hop_overhead",
            "describe_interleaved": "tokenring.perf.hop_overhead",
            "interleave": "tokenring.perf.interleaved_pairs",
            "interval": "tokenring.perf.hop_overhead",
            "LiveRing": "tokenring.perf.running_rings",
            "pair_share_us": "tokenring.perf.hop_overhead",
            "RingRun": "tokenring.perf.roundtrip",
            "ROUTER_FROM": "tokenring.perf.defaults",
            "run_bare": "tokenring.perf.roundtrip",
            "run_ring": "tokenring.perf.roundtrip",
            "STEAL_LIMIT_PCT": "tokenring.perf.hop_overhead",
            "steal_pct": "tokenring.perf.hop_overhead",
            "summarize": "tokenring.perf.roundtrip",
            "within_steal_limit": "tokenring.perf.hop_overhead",
        },
    )

__all__ = [
    "ROUTER_FROM",
    "STEAL_LIMIT_PCT",
    "BareRing",
    "LiveRing",
    "RingRun",
    "cpu_jiffies",
    "describe",
    "describe_interleaved",
    "interleave",
    "interval",
    "pair_share_us",
    "run_bare",
    "run_ring",
    "steal_pct",
    "summarize",
    "within_steal_limit",
]
