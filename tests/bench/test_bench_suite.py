"""The suite's runs of `tokenring bench` in their own processes: a failed or overlong one is
recorded as an error, and a killed benchmark leaves no ring process behind; what a run writes:
its samples to the ignored raw/, its summary (kilobytes) beside them."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading

import pytest

from bench import suite
from bench.suite import bench_cli
from tests.support.processes import REPO, wait_gone
from tests.support.ringutil import processes, wait_until
from tests.support.suite_records import suite_run
from tokenring.transport import zenoh_config as zconfig


@pytest.mark.slow
def test_a_suite_run_writes_its_samples_to_raw_and_a_summary_of_kilobytes(tmp_path, monkeypatch, capsys):
    """``python -m bench``'s own path, its sections replaced by made-up records of a real run's size."""
    made_up = suite_run()
    for name in ("scaling", "profile"):
        monkeypatch.setitem(
            suite.SECTION_FUNCTIONS,
            name,
            lambda ctx, name=name: json.loads(json.dumps(made_up["sections"][name])),
        )
    monkeypatch.setattr(zconfig, "use_host_runtime", lambda: None)
    out = tmp_path / "results"
    assert suite.main(["--sections", "scaling,profile", "--out", str(out)]) == 0
    (summary,) = out.glob("*.json")
    raw = out / "raw" / summary.name
    assert raw.stat().st_size > 1_000_000 and summary.stat().st_size < 100_000
    assert (
        json.loads(raw.read_text())["sections"]["profile"]["runs"][0]["rounds_s"]
        == made_up["sections"]["profile"]["runs"][0]["rounds_s"]
    )
    assert "rounds_s" not in summary.read_text()
    assert f"written {summary}, its samples in {raw}" in capsys.readouterr().err
    assert (out / "plots" / "profile.png").exists()  # drawn from the samples in memory
    report = (tmp_path / "RESULTS.md").read_text()
    assert "| router | 255 |" in report and "![profile arcnet](results/plots/profile.png)" in report


def test_pairs_set_for_every_size_reach_the_scaling_section_and_a_bad_count_is_refused(tmp_path, monkeypatch):
    asked: list[tuple[int, int]] = []

    def scaling(ctx):
        asked.extend((n, ctx.pairs_for(n)) for sizes in ctx.sizes.values() for n in sizes)
        return {"runs": []}

    monkeypatch.setitem(suite.SECTION_FUNCTIONS, "scaling", scaling)
    monkeypatch.setattr(zconfig, "use_host_runtime", lambda: None)
    args = ["--sections", "scaling", "--sizes", "peer:8/links:255", "--out", str(tmp_path), "--no-report"]
    assert suite.main([*args, "--pairs", "16"]) == 0
    assert asked == [(8, 16), (255, 16)]
    asked.clear()
    assert suite.main([*args, "--pairs", "255:12"]) == 0
    assert asked == [(8, 8), (255, 12)]  # a size not named keeps its default
    asked.clear()
    assert suite.main(args) == 0
    assert asked == [(8, 8), (255, 10)]  # the defaults
    assert suite_refuses(tmp_path, "--pairs", "0") == "python -m bench: --pairs '0': expected 1 to 1000 pairs"


def test_a_pair_the_host_stole_from_is_retaken_and_the_own_share_judged_without_it(monkeypatch):
    """Pairs of made-up runs: (bare, ring) medians in ms and the steal each run saw. The second
    pair lost 30 % to the host, so a third is taken; the own share counts pairs 1 and 3 only."""
    from tokenring.perf import roundtrip

    script = [  # (bare median ms, ring median ms, bare steal %, ring steal %)
        (20.0, 20.64, 1.0, 2.0),
        (20.0, 40.00, 30.0, 4.0),
        (21.0, 21.32, 0.0, 9.5),
    ]
    medians = iter(x for bare, ring, _, _ in script for x in (bare, ring))
    steals = iter(x for _, _, bare, ring in script for x in (bare, ring))
    ticks = {"steal": 0, "total": 0}

    def reading():
        return ticks["steal"], ticks["total"]

    def run(median_ms):
        stolen = next(steals)  # what the host takes while this run goes on: 1000 ticks of CPU
        ticks["steal"] += round(stolen * 10)
        ticks["total"] += 1000
        return [median_ms / 1e3] * 5

    def fake_bare(n, rounds, warmup, timeout, *, router, chain):
        return run(next(medians))

    def fake_ring(n, rounds, warmup, *, timeout, router, links, tap):
        rounds_s = run(next(medians))
        return roundtrip.RingRun(rounds_s, [30.0] * n, [1.0] * n, {"median": 5.0}, 10.0)

    monkeypatch.setattr(roundtrip, "run_bare", fake_bare)
    monkeypatch.setattr(roundtrip, "run_ring", fake_ring)
    monkeypatch.setattr(suite, "cpu_jiffies", reading)
    ctx = suite.Context(False, {"router": [64]}, suite.Progress(4), pairs={64: 2}, windows={0: 0})
    (record,) = suite.section_scaling(ctx)["runs"]
    assert record["pairs_taken"] == 3 and "interleaved" not in record
    assert [tuple(pair) for pair in record["pair_steal_pct"]] == [(2.0, 1.0), (4.0, 30.0), (9.5, 0.0)]
    # pairs 1 and 3: 0.64 and 0.32 ms over 64 nodes = 10 and 5 µs per hop
    assert record["own_share_us"]["pairs_us"] == [10.0, 5.0]
    assert record["own_share_us"]["mean"] == pytest.approx(7.5)
    assert record["own_share_all_us"]["pairs_us"] == [10.0, 312.5, 5.0]


def test_interleaved_windows_run_at_the_aims_sizes_unless_told_otherwise(monkeypatch):
    import tokenring.perf
    from tokenring.perf import interleaved_pairs as interleave_module
    from tokenring.perf import roundtrip

    assert [suite.windows_of(n, False, None) for n in (8, 16, 64, 128, 255)] == [100, 0, 100, 0, 100]
    assert suite.windows_of(8, True, None) == 6  # quick
    assert suite.windows_of(64, False, {0: 0}) == 0  # --interleaved 0: none anywhere
    assert [suite.windows_of(n, False, {16: 30}) for n in (16, 64)] == [30, 100]
    asked = []

    def fake_interleave(n, topology, pairs, say):
        asked.append((n, topology, pairs))
        return {"own_share_us": {"n": 0}, "pids": {"ring": [1], "bare": [2]}, "pairs": pairs}

    monkeypatch.setattr(interleave_module, "interleave", fake_interleave)
    monkeypatch.setattr(tokenring.perf, "interleave", fake_interleave)  # the face's cached name
    monkeypatch.setattr(suite, "describe_interleaved", lambda record: "made up")
    monkeypatch.setattr(roundtrip, "run_bare", lambda *a, **k: [0.02] * 5)
    monkeypatch.setattr(
        roundtrip,
        "run_ring",
        lambda *a, **k: roundtrip.RingRun([0.021] * 5, [30.0] * 4, [1.0] * 4, {"median": 5.0}, 1.0),
    )
    ctx = suite.Context(
        False, {"peer": [4], "router": [64]}, suite.Progress(8), pairs={0: 1}, windows={64: 12}
    )
    runs = suite.section_scaling(ctx)["runs"]
    assert asked == [(64, "router", 12)]  # 4 nodes: not an aim's size, nothing asked for it
    assert "interleaved" not in runs[0]
    assert runs[1]["interleaved"] == {"own_share_us": {"n": 0}, "pairs": 12}  # its PIDs dropped


def suite_refuses(tmp_path, *args: str) -> str:
    """What ``python -m bench --sections scaling ARGS`` says on stderr as it refuses them (exit
    code 2, no output directory made)."""
    refused = subprocess.run(
        [sys.executable, "-m", "bench", "--sections", "scaling", *args, "--out", str(tmp_path / "x")],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert refused.returncode == 2 and not (tmp_path / "x").exists()
    return refused.stderr.strip()


def test_a_bad_interleaved_count_is_refused_in_one_line(tmp_path):
    said = suite_refuses(tmp_path, "--interleaved", "64:x")
    assert said == "python -m bench: --interleaved '64:x': expected K or N:K,N:K (whole numbers)"


def test_the_raw_records_are_ignored_and_no_committed_result_file_is_over_100_kb():
    results = REPO / "bench" / "results"
    ignored = subprocess.run(
        ["git", "check-ignore", "-q", str(results / "raw" / "2026-11-21.json")], cwd=REPO, check=False
    )
    assert ignored.returncode == 0, "bench/results/raw/ is not ignored"
    big = [
        f"{p.relative_to(REPO)}: {p.stat().st_size} bytes"
        for p in results.rglob("*")
        if p.is_file() and "raw" not in p.relative_to(results).parts[:1] and p.stat().st_size > 100 * 1024
    ]
    assert not big, big


def test_a_bench_run_that_fails_is_recorded_not_raised():
    result = bench_cli(["--nodes", "2", "--rounds", "5"], timeout=60)
    assert result == {"error": "tokenring bench: error: --rounds must be 10..16000"}


@pytest.mark.slow
def test_a_bench_run_gets_its_environment_and_the_python_token_path_circulates():
    result = bench_cli(["--nodes", "3", "--rounds", "50", "--warmup", "10"], 120, {"TOKENRING_NATIVE": "0"})
    assert "error" not in result, result
    assert result["token_path"] == "Python"
    assert result["rounds"] >= 50 and result["rtt_ms"]["median"] > 0


#: a run that never ends on any machine: 10 measured rounds after a hundred million warm-up
#: rounds (--rounds is limited, --warmup is not); it is inside its bare ring for as long as
#: anybody waits, so no budget has to be guessed against how fast this machine is today
ENDLESS = ["--nodes", "8", "--rounds", "10", "--warmup", "100000000"]
HANG_GUARD_S = 60.0
BARE = b"tokenring.perf.bare_ring"


def bare_ring_of(benchmarks: set[int]) -> set[int]:
    """PIDs of the bare-ring processes whose parent is one of ``benchmarks``."""
    return {pid for pid, (ppid, cmdline) in processes().items() if ppid in benchmarks and BARE in cmdline}


def gone_or_killed(pids: set[int]) -> list[int]:
    """Wait for ``pids`` to end; kill (by PID, if still a bare-ring process) and return those that do not."""
    left = wait_gone(sorted(pids), HANG_GUARD_S)  # they would run for days if nothing ended them
    for pid in left:
        if BARE in processes().get(pid, (0, b""))[1]:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    return left


@pytest.mark.slow
def test_an_overlong_bench_run_is_recorded_as_an_error():
    budget = 6
    me = os.getpid()
    seen: set[int] = set()  # this run's bare ring processes, while its benchmark lives
    done = threading.Event()
    result: dict = {}

    def watch() -> None:
        while not done.is_set():
            benchmarks = {pid for pid, (ppid, _) in processes().items() if ppid == me}
            seen.update(bare_ring_of(benchmarks))
            done.wait(0.05)

    def run() -> None:
        try:
            result.update(bench_cli(ENDLESS, timeout=budget))
        finally:
            done.set()

    threading.Thread(target=watch, daemon=True).start()
    threading.Thread(target=run, daemon=True).start()
    # the run never ends by itself: bench_cli returns only if its budget stopped it
    returned = done.wait(budget + HANG_GUARD_S)
    left = gone_or_killed(seen)
    assert returned, f"bench_cli did not return after its {budget} s budget"
    assert result == {"error": f"no result in {budget} s"}
    assert not left, f"bare ring processes outlived the killed benchmark: {left}"


def test_a_killed_benchmark_takes_its_bare_ring_with_it(procs):
    # what the suite's budget does to an overlong run (subprocess.run kills it: SIGKILL), done
    # at a moment the bare ring is known to be running rather than after a guessed time
    bench = procs.tokenring("bench", *ENDLESS, "--quiet", stdout=subprocess.DEVNULL)
    ring = wait_until(lambda: len(r := bare_ring_of({bench.pid})) == 8 and r, HANG_GUARD_S, "the bare ring")
    bench.kill()
    bench.wait(HANG_GUARD_S)
    left = gone_or_killed(ring)
    assert not left, f"bare ring processes outlived the killed benchmark: {left}"


def test_recovery_progress_prints_medians_to_a_tenth_of_a_ms_and_names_a_missing_one():
    assert suite._ms(12.993187494430458) == "13.0 ms"
    assert suite._ms(None) == "none (no trial recovered)"
