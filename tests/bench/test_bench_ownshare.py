"""The own share per hop's interval, and the hop-cost profiler on real rings."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from bench.ownshare import own_share
from tests.support.processes import REPO
from tokenring.perf.hop_overhead import interval


def test_the_interval_is_students_t_over_the_pairs():
    # 1..5: mean 3, sd sqrt(2.5) = 1.5811; t(0.975, 4) = 2.7764 from a printed t table
    got = interval([1.0, 2.0, 3.0, 4.0, 5.0])
    half = 2.7764 * 1.5811 / 5**0.5
    assert got["mean"] == pytest.approx(3.0)
    assert got["lo"] == pytest.approx(3.0 - half, abs=1e-3) and got["hi"] == pytest.approx(
        3.0 + half, abs=1e-3
    )
    assert got["n"] == 5


def test_one_pair_gives_a_share_but_no_interval_and_never_meets_the_aim():
    share = own_share([(0.808, 0.800)], 8)  # 8 µs over 8 hops: 1 µs per hop
    assert share["mean"] == pytest.approx(1.0) and share["pairs_us"] == [1.0]
    assert share["n"] == 1 and share["met"] is False


def test_the_aim_is_judged_on_the_top_of_the_interval():
    close = own_share([(0.80 + d, 0.80) for d in (0.008, 0.010, 0.012, 0.009)], 8)  # ~1.2 µs/hop
    wide = own_share([(0.80 + d, 0.80) for d in (0.0, 0.4, -0.2, 0.1)], 8)  # mean 9 µs, sd ~25
    assert close["met"] is True and close["hi"] < 10
    assert wide["mean"] < 10 and wide["hi"] > 10 and wide["met"] is False


@pytest.mark.slow
def test_hopcost_counts_each_rings_visits_and_leaves_no_process(tmp_path):
    out = tmp_path / "hopcost.json"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "bench.hopcost",
            "--nodes",
            "3",
            "--pairs",
            "1",
            "--window",
            "1.5",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )
    assert result.returncode == 0, result.stderr
    data = json.loads(out.read_text())
    ((ring, bare),) = data["pairs"]
    for run in (ring, bare):
        # every hop runs on some thread: the round's CPU is more than nothing, the visits were counted
        assert run["visits"] >= 10 and run["per_visit_us"]["total"] > 0
        assert run["round_ms"] == pytest.approx(1.5e3 / run["visits"], rel=0.5)
        # CPU read from /proc: all processes together cannot have used more than the cores give
        cpu_s = run["per_visit_us"]["total"] * 1e-6 * run["visits"] * 3
        assert 0 < cpu_s <= 1.5 * (os.cpu_count() or 1) * 1.2
        for pid in run["pids"]:
            assert not os.path.exists(f"/proc/{pid}") or "zombie" in Path(f"/proc/{pid}/status").read_text()
    # the node's own Python threads (watchdog, token thread) exist only in the ring
    assert any(row["part"].startswith("Python threads") for row in data["threads"])
    assert "CPU per visit per node" in result.stdout


def test_hopcost_refuses_an_existing_output_file(tmp_path):
    out = tmp_path / "kept.json"
    out.write_text("{}")
    result = subprocess.run(
        [sys.executable, "-m", "bench.hopcost", "--json", str(out)], capture_output=True, text=True, cwd=REPO
    )
    assert result.returncode == 2 and "exists" in result.stderr and out.read_text() == "{}"


@pytest.mark.parametrize("count", ["0", "8"])
def test_hopcost_refuses_to_record_nodes_the_ring_does_not_have(count):
    result = subprocess.run(
        [sys.executable, "-m", "bench.hopcost", "--nodes", "8", "--perf", "--perf-nodes", count],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
    )
    assert result.returncode == 2 and "--perf-nodes 1..7" in result.stderr
    assert "Traceback" not in result.stderr


def test_steal_time_is_the_hosts_share_of_the_cpus_between_two_readings():
    from tokenring.perf.hop_overhead import cpu_jiffies, steal_pct

    assert steal_pct((100, 10_000), (250, 11_000)) == 15.0  # 150 of 1000 ticks went to the host
    assert steal_pct((5, 50), (5, 50)) == 0.0  # no time passed: nothing stolen, no division by 0
    steal, total = cpu_jiffies()
    fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()  # read after: the counters only grow
    assert fields[0] == "cpu" and 0 <= steal <= int(fields[8]) and steal <= total


def test_the_intervals_of_a_result_file_are_printed_with_the_pairs_the_host_spoiled(tmp_path, capsys):
    from bench.ownshare import main

    record = {
        "topology": "router",
        "nodes": 64,
        "load_before": [2.2],
        "own_share_us": own_share([(21.0, 20.936), (22.0, 22.0)], 64),  # 1.0 and 0.0 µs per hop
        "own_share_all_us": own_share([(21.0, 20.936), (40.0, 21.8), (22.0, 22.0)], 64),
        "pair_steal_pct": [[1.0, 2.0], [25.0, 3.0], [0.5, 9.9]],
        "steal_limit_pct": 10.0,
    }
    result = tmp_path / "run.json"
    result.write_text(json.dumps({"sections": {"scaling": {"runs": [record]}}}))
    assert main([str(result)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("router  64 nodes: 0.5 µs per hop (95 % CI")
    assert (
        "2 pairs), load 2.2; 2 of 3 pairs within 10 % steal, every pair: 95.1 µs per hop" in line
    )  # (1 + 284.4 + 0) / 3
    assert main([str(tmp_path / "missing.json")]) == 2


def test_the_retake_rule_stops_at_enough_calm_pairs_or_twice_the_pairs_asked():
    from bench.ownshare import more_pairs_needed

    calm, spoiled = (1.0, 2.0), (1.0, 10.5)  # 10.5 %: over the 10 % limit
    assert more_pairs_needed(1, 2, [calm])  # the pairs asked for come first
    assert not more_pairs_needed(2, 2, [calm, calm])
    assert more_pairs_needed(2, 2, [calm, spoiled])  # one retake
    assert not more_pairs_needed(3, 2, [calm, spoiled, calm])
    assert not more_pairs_needed(4, 2, [spoiled, spoiled, spoiled, spoiled])  # capped at 2 x 2
    assert more_pairs_needed(3, 2, [calm, spoiled])  # a failed pair recorded no steal: spoiled


def test_the_aim_is_judged_on_the_interleaved_windows_where_a_size_has_them():
    from bench.report import own_share_aims

    separate = own_share([(21.0, 20.0), (23.0, 20.5), (20.0, 20.9)], 64)  # wide: missed
    record = {
        "topology": "router",
        "nodes": 64,
        "load_before": [1.0],
        "own_share_us": separate,
        "interleaved": {
            "window_s": 0.6,
            "pairs": 100,
            "steal_limit_pct": 10.0,
            "own_share_us": {"mean": 1.0, "lo": -3.0, "hi": 5.0, "sd": 14.0, "n": 52},
            "own_share_all_us": {"mean": -11.5, "lo": -30.1, "hi": 7.1, "sd": 90.0, "n": 100},
        },
    }
    (row,) = own_share_aims([record])
    assert row[3] == "**met**" and separate["met"] is False
    assert row[2].startswith("1.0 µs per hop (95 % CI -3.0 to 5.0, 52 pairs), both rings up at once")
    assert "52 of 100 pairs within 10 % steal" in row[2] and "separate runs: " in row[2]
    record["interleaved"]["own_share_us"] = {"mean": 1.0, "lo": -9.0, "hi": 11.0, "sd": 14.0, "n": 52}
    assert own_share_aims([record])[0][3] == "**missed**"


def test_the_steal_note_gives_every_pairs_share_only_where_some_were_spoiled():
    from bench.report import steal_note

    shares = [(21.0, 20.936), (22.0, 22.0)]  # 1.0 and 0.0 µs per hop
    record = {
        "own_share_us": own_share(shares, 64),
        "own_share_all_us": own_share(shares, 64),
        "pair_steal_pct": [[1.0, 2.0], [0.5, 9.9]],
        "steal_limit_pct": 10.0,
    }
    assert steal_note(record) == "; all 2 pairs within 10 % steal time (worst 9.9 %)"
    record["pair_steal_pct"] = [[1.0, 2.0], [25.0, 9.9]]
    assert steal_note(record).startswith(
        "; 1 of 2 pairs within 10 % steal time (worst 25.0 %), over all 2: 0.5 µs"
    )


def test_the_big_rings_tail_in_calm_windows_stands_beside_the_runs_p99():
    from bench.report import calm_tail_note

    record = {"interleaved": {"steal_limit_pct": 10.0, "calm_p99_ms": {"ring": 78.25, "bare": 80.04}}}
    assert calm_tail_note(record) == "; in the interleaved windows within 10 % steal: 78.2 / 80.0 ms"
    assert calm_tail_note({"interleaved": {"calm_p99_ms": {"ring": None, "bare": 80.0}}}) == ""
    assert calm_tail_note({}) == ""  # a run from before the windows


def test_a_result_files_interleaved_windows_are_printed_too(tmp_path, capsys):
    from bench.ownshare import main

    record = {
        "topology": "links",
        "nodes": 255,
        "interleaved": {
            "topology": "links",
            "nodes": 255,
            "pairs": 100,
            "pairs_usable": 96,
            "steal_limit_pct": 10.0,
            "own_share_us": {"mean": -16.5, "lo": -23.0, "hi": -10.0, "sd": 26.0, "n": 67},
            "own_share_all_us": {"mean": -21.7, "lo": -30.9, "hi": -12.5, "sd": 46.0, "n": 96},
        },
    }
    result = tmp_path / "run.json"
    result.write_text(json.dumps({"sections": {"scaling": {"runs": [record]}}}))
    assert main([str(result)]) == 0
    assert capsys.readouterr().out.strip() == (
        "interleaved windows, links 255: -16.5 µs per hop (95 % CI -23.0 to -10.0, 67 pairs) within 10 % steal; "
        "-21.7 µs per hop (95 % CI -30.9 to -12.5, 96 pairs) over 96 of 100 pairs"
    )
