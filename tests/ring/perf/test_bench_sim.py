"""``tokenring bench --sim``: the round trip and the recovery times from the timing model, in
virtual time: exact, within the model's bounds, and the same run after run."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tokenring.contract.ring import ARCNET_RECON_TIMEOUT_S, hop_time

ARCNET = 2_500_000


def bench_sim(*extra: str) -> dict:
    done = subprocess.run(
        [sys.executable, "-m", "tokenring", "bench", "--sim", "--nodes", "8", "--json", "-", *extra],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    return json.loads(done.stdout)


def test_bench_sim_gives_the_model_exactly_and_the_same_figures_twice():
    first = bench_sim()
    (run,) = first["runs"]
    hop_ms = hop_time(ARCNET) * 1e3
    # every round exactly eight emulated hops: the model is the round trip
    assert run["round_median_ms"] == pytest.approx(8 * hop_ms, abs=1e-6)
    assert run["round_p99_ms"] == pytest.approx(8 * hop_ms, abs=1e-6)
    assert run["round_samples"] >= 1000
    assert first["arcnet"]["lost_token_timer_ms"] == pytest.approx(ARCNET_RECON_TIMEOUT_S * 1e3)
    # a lost token: the highest ID regenerates it one lost-token timer (840 ms at 8 nodes, more
    # than ten rounds) after it last saw it, then it goes round
    low, high = run["model"]["lost_token_ms"]
    assert low == pytest.approx(840 - 8 * hop_ms) and high == pytest.approx(840 + 16 * hop_ms)
    assert low <= run["lost_token_ms"] <= high
    assert run["lost_token_regenerations"] == 1
    # a crashed node is passed over at once; a frozen one costs a regeneration and three passes
    assert run["crash_ms"] <= run["model"]["crash_ms"][1] and run["crash_regenerations"] == 0
    low, high = run["model"]["freeze_ms"]
    assert low <= run["freeze_ms"] <= high and run["freeze_regenerations"] == 1
    # host-independent: the same figures, and the same frame stream, the second time
    again = bench_sim("--quiet")
    strip = lambda report: [{k: v for k, v in r.items() if k != "real_s"} for r in report["runs"]]  # noqa: E731
    assert strip(again) == strip(first)
