"""The suite's runs of `tokenring bench` in their own processes: a failed or overlong one is
recorded as an error, and a killed benchmark leaves no ring process behind."""

from __future__ import annotations

import time
from pathlib import Path

from bench.suite import bench_cli
from tokenring.zconfig import NODE_RUNTIME


def bare_ring_pids() -> set[int]:
    """PIDs of bare-ring processes (read only, to see what a killed benchmark left)."""
    pids = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cmdline = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if b"tokenring.bench_bare" in cmdline:
                pids.add(int(entry.name))
    return pids


def test_a_bench_run_that_fails_is_recorded_not_raised():
    result = bench_cli(["--nodes", "2", "--rounds", "5"], NODE_RUNTIME, timeout=60)
    assert result == {"error": "tokenring bench: error: --rounds must be 10..16000"}


def test_a_bench_run_gets_its_environment_and_the_python_token_path_circulates():
    result = bench_cli(
        ["--nodes", "3", "--rounds", "50", "--warmup", "10"], NODE_RUNTIME, 120, {"TOKENRING_NATIVE": "0"}
    )
    assert "error" not in result, result
    assert result["token_path"] == "Python"
    assert result["rounds"] >= 50 and result["rtt_ms"]["median"] > 0


def test_an_overlong_bench_run_is_stopped_with_its_bare_ring():
    before = bare_ring_pids()
    # 16000 rounds of 8 processes take ~10 s: the budget ends inside the bare ring's run
    started = time.monotonic()
    result = bench_cli(["--nodes", "8", "--rounds", "16000"], NODE_RUNTIME, timeout=6)
    assert result == {"error": "no result in 6 s"}
    assert time.monotonic() - started < 15
    deadline = time.monotonic() + 5
    while (left := bare_ring_pids() - before) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not left, f"bare ring processes outlived the killed benchmark: {sorted(left)}"
