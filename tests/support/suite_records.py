"""A made-up full suite run of the benchmarks, the size and shape of a real one: what the
report's and the suite's tests render and summarise without measuring anything."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from bench.suite import FULL_SIZES, pairs_for, ring_record, rounds_for
from tokenring.perf.roundtrip import summarize


def round_trips(rng: np.random.Generator, median_ms: float, rounds: int) -> list[float]:
    """Round trips (s) as the suite stores them: rounded to 0.1 µs, a long tail."""
    return [round(x, 7) for x in median_ms / 1e3 * (0.8 + rng.gamma(2.0, 0.12, rounds))]


def measured(rng: np.random.Generator, n: int, median_ms: float, rounds: int) -> dict:
    """``ring_record`` of a made-up ring run of ``n`` nodes."""
    run = SimpleNamespace(
        rounds_s=round_trips(rng, median_ms, rounds),
        rss_mb=[55.0 + i % 3 for i in range(n)],
        cpu_s=[1.0 + 0.01 * i for i in range(n)],
        wall_s=10.0,
        handler_us={"median": 6.0, "p99": 9.0},
        stats={"send_us": {"median": 3.0}},
        launcher_cpu_s=0.5,
        form_s=1.5,
    )
    return ring_record(run, n)


def suite_run(seed: int = 1) -> dict:
    """A full suite run's raw record, the size of a real one: every ring size of ``FULL_SIZES``
    with its bare ring and as many rounds as the suite measures, two profile runs, the commands'
    per-command samples."""
    rng = np.random.default_rng(seed)
    scaling = []
    for topology, sizes in FULL_SIZES.items():
        for n in sizes:
            rounds, pairs = rounds_for(n, False)[0], pairs_for(n, False)  # small rings: pairs pooled
            bare = round_trips(rng, 0.09 * n, rounds * pairs)
            record = {
                "topology": topology,
                "nodes": n,
                "rounds": rounds,
                "pairs": pairs,
                "load_before": [1.0],
            }
            record |= {
                "bare_rtt_ms": summarize(bare),
                "bare_rounds_s": bare,
                **measured(rng, n, 0.1 * n, rounds * pairs),
            }
            record["ratio_median"] = record["rtt_ms"]["median"] / record["bare_rtt_ms"]["median"]
            record["ratio_p99"] = record["rtt_ms"]["p99"] / record["bare_rtt_ms"]["p99"]
            record["pair_ratios"] = [record["ratio_median"]]
            record["load_after"] = [1.2, 1.0, 0.9]
            scaling.append(record)
    profile = {
        "profile": "arcnet",
        "nodes": ["main", "motor", "sonar", "compass", "copro", "map", "lcd"],
        "bitrate": "2.5M",
        "seed_ms": [30.0, 40.0],
        "model": {
            "wire_ms_per_hop": 2.286,
            "visit_ms": 0.375,
            "byte_us": 12.0,
            "sonar_lock_ms": [15.0, 10.2],
            "no_copy_ms": 22.1,
            "sonar_mean_hold_ms": 3.5,
        },
        "runs": [
            {"label": "idle (no programs)", **measured(rng, 7, 23.0, 600), "load": [1.0]},
            {"label": "the seven programs running", **measured(rng, 7, 31.0, 600), "load": [1.0]},
        ],
    }
    samples = [
        {"ms": float(ms), "visits": 3, "waited": 0, "acked": True, "sender": "main"}
        for ms in rng.uniform(2.0, 4.0, 280)
    ]
    commands = {
        "nodes": 8,
        "bitrate": "max",
        "seed_worst_rounds": 6,
        "scenarios": [
            {
                "label": "free inbox",
                "senders": {"main": ["motor.command"]},
                "commands": 280,
                "lost": 0,
                "acknowledged": 280,
                "ms": {"median": 2.6, "p99": 3.2, "max": 4.0},
                "rounds": {"median": 3.0, "max": 4.0},
                "waited_rounds": {"median": 0.0, "max": 0.0},
                "round_ms": {"median": 0.8},
                "samples": samples,
            }
        ],
    }
    return {
        "date": f"2026-11-2{seed}T10:00:00",
        "command": "python -m bench",
        "quick": False,
        "machine": {
            "cpus": 2,
            "memory_gib": 23.5,
            "python": "3.11.7",
            "zenoh": "1.10.2",
            "pyzmq": "26",
            "kernel": "6.18",
            "token_path": "C",
        },
        "load_start": [1.0, 1.0, 1.0],
        "sections": {
            "scaling": {"runs": scaling, "seconds": 600.0},
            "commands": commands,
            "profile": profile,
        },
        "errors": {},
        "load_end": [2.0, 1.5, 1.0],
        "seconds": 1800.0,
    }
