"""The generated report: the Zenoh runtime comparison and the aims it qualifies; its tables from a
run's summary alone, its plots from the raw record, nothing kept of the file it replaces."""

from __future__ import annotations

import datetime as dt
import json

import numpy as np
import pytest

from bench.report import aims, nemesis_md, runtime_md, write_report
from bench.sections import summary_of
from bench.suite import (
    parse_sizes,
    result_path,
    write_results,
)
from tests.support.suite_records import suite_run
from tokenring.errors import UsageError


def ring(nodes: int, topology: str, bare_ms: float, ring_ms: float, p99_ms: float) -> dict:
    return {
        "nodes": nodes,
        "topology": topology,
        "rtt_ms": {"median": ring_ms, "p99": p99_ms},
        "bare_rtt_ms": {"median": bare_ms, "p99": bare_ms * 1.2},
        "ratio_median": ring_ms / bare_ms,
        "per_hop_us": ring_ms * 1e3 / nodes,
        "pair_ratios": [ring_ms / bare_ms] * 3,
    }


def runtime_run(nodes: int, topology: str, runtime: str, bare_ms: float, ring_ms: float) -> dict:
    return {
        "nodes": nodes,
        "topology": topology,
        "runtime": runtime,
        "rtt_ms": {"median": ring_ms, "p99": ring_ms * 1.3},
        "bare_rtt_ms": {"median": bare_ms},
        "ratio": ring_ms / bare_ms,
        "per_hop_us": {"ring": ring_ms * 1e3 / nodes, "baseline": bare_ms * 1e3 / nodes},
        "handler_us": {"median": 15.0},
        "cpu_per_node_pct": 13.0,
    }


RUNTIME = {
    "node_runtime": "(rx:(worker_threads:1))",
    "runs": [
        runtime_run(8, "peer", "tokenring", 0.665, 0.839),
        runtime_run(8, "peer", "zenoh defaults", 0.840, 0.995),
        runtime_run(8, "peer", "callback on a Python thread", 0.650, 0.870),
        runtime_run(64, "router", "tokenring", 11.4, 15.4),
        {"nodes": 64, "topology": "router", "runtime": "zenoh defaults", "error": "ring of 64 did not form"},
    ],
}


def test_the_runtime_table_shows_both_runtimes_and_what_one_thread_gains():
    text = runtime_md(RUNTIME)
    assert "`ZENOH_RUNTIME=(rx:(worker_threads:1))`" in text
    assert "| 8 | peer | tokenring | 0.665 | 0.839 |" in text
    assert "| 8 | peer | zenoh defaults | 0.840 | 0.995 |" in text
    assert "| 64 | router | zenoh defaults | failed: ring of 64 did not form |" in text
    # per hop over the bare ring: (0.839 - 0.665) ms / 8 = 22 µs
    assert "1.26× | 22 |" in text
    assert (
        "against Zenoh's defaults: 8 nodes (peers): tokenring 0.995 → 0.839 ms (0.84×), the bare ring 0.840 → 0.665 ms"
        in text
    )
    assert "64 nodes (routers): tokenring" not in text  # no pair to compare
    assert "| 8 | peer | callback on a Python thread | 0.650 | 0.870 |" in text
    assert (
        "against a Python thread: 8 nodes (peers): tokenring 0.870 → 0.839 ms (0.96×), the bare ring 0.650 → 0.665 ms"
        in text
    )


def test_the_8_node_aim_is_judged_on_the_shared_runtime_and_names_the_defaults_beside_it():
    scaling = {"runs": [ring(8, "peer", 0.658, 0.824, 1.0), ring(255, "router", 47.6, 65.5, 74.4)]}
    text = aims({"scaling": scaling, "runtime": RUNTIME})
    row = next(line for line in text.splitlines() if line.startswith("| 8-node"))
    assert "1.25× (0.824 vs 0.658 ms" in row and row.endswith("**missed** |")
    assert "both rings on Zenoh's default runtime: 1.18× (0.995 vs 0.840 ms" in row
    big = next(line for line in text.splitlines() if line.startswith("| 255 nodes"))
    assert "74.4 ms" in big and big.endswith("**met** |")
    # without the runtime section the row carries no such note
    assert "default runtime" not in aims({"scaling": scaling})


def test_every_topology_of_the_biggest_size_gets_its_own_p99_row_and_links_are_named():
    """A suite run with ``--sizes router:255/links:255`` judges the p99 aim on each topology."""
    scaling = {"runs": [ring(255, "router", 83.0, 84.0, 110.0), ring(255, "links", 56.0, 57.0, 78.3)]}
    rows = [line for line in aims({"scaling": scaling}).splitlines() if line.startswith("| 255 nodes")]
    assert len(rows) == 2
    router_row, links_row = sorted(rows, key=lambda line: "direct links" in line)
    assert "(routers)" in router_row and "110.0 ms" in router_row and router_row.endswith("**missed** |")
    assert "(direct links)" in links_row and "78.3 ms" in links_row and links_row.endswith("**met** |")


def test_the_suites_sizes_take_direct_links_and_refuse_an_unknown_topology():
    assert parse_sizes("router:8,64/links:255") == {"router": [8, 64], "links": [255]}
    with pytest.raises(UsageError, match="mesh:8"):
        parse_sizes("mesh:8")


def test_a_later_run_on_the_same_day_never_overwrites_an_earlier_result_file(tmp_path):
    morning, evening = dt.datetime(2026, 11, 21, 9, 0, 0), dt.datetime(2026, 11, 21, 19, 30, 5)
    full = result_path(tmp_path, morning, False, None)
    assert full.name == "2026-11-21.json"
    full.write_text("{}")
    assert result_path(tmp_path, evening, False, ["runtime"]).name == "2026-11-21-runtime.json"
    assert result_path(tmp_path, evening, True, None).name == "2026-11-21-quick.json"
    assert result_path(tmp_path, evening, False, None).name == "2026-11-21-193005.json"


def test_the_router_flatness_aim_names_the_growth_on_zenohs_default_runtime():
    scaling = {"runs": [ring(8, "router", 0.8, 1.03, 1.3), ring(64, "router", 10.25, 14.71, 19.1)]}
    runtime = {
        "node_runtime": "x",
        "runs": [
            runtime_run(8, "router", "zenoh defaults", 1.434, 1.714),
            runtime_run(64, "router", "zenoh defaults", 15.9, 19.84),
        ],
    }
    row = next(
        line for line in aims({"scaling": scaling, "runtime": runtime}).splitlines() if "(routers)" in line
    )
    # 129 -> 230 µs per hop under tokenring's runtime; 214 -> 310 µs under Zenoh's defaults
    assert row.startswith(
        "| per-hop cost flat from 8 to 64 nodes (routers) | within 1.5× | 1.79× (129 → 230 µs)"
    )
    assert "both rings on Zenoh's default runtime: 1.45× (214 → 310 µs; bare 1.39×)" in row
    assert row.endswith("**missed** |")


def test_a_bench_runs_default_time_budget_covers_a_255_node_ring_and_the_wire():
    """`tokenring bench --nodes 255` failed with the old fixed 120 s: 2300 rounds of ~80 ms."""
    from tokenring.contract.ring import hop_time, parse_bitrate
    from tokenring.perf.roundtrip import run_budget

    measured_round_s = 0.080  # 255 nodes, routers, bench/RESULTS.md
    assert run_budget(255, 2300, None) > 60 + 2300 * measured_round_s * 1.5
    assert run_budget(8, 2300, None) < 150  # a hung small ring still fails within minutes
    slow = parse_bitrate("2.5M")
    assert run_budget(7, 2300, slow) > 120 + 2300 * 7 * hop_time(slow)


# ---------------------------------------------------------------------------------------------
# a run's summary and raw record


@pytest.mark.slow
def test_a_runs_summary_is_kilobytes_keeps_every_figure_and_drops_every_sample(tmp_path):
    results = suite_run()
    path, raw = write_results(results, tmp_path / "2026-11-21.json")
    assert raw == tmp_path / "raw" / "2026-11-21.json"
    assert json.loads(raw.read_text()) == results  # the raw record: everything, samples and all
    assert raw.stat().st_size > 1_000_000  # as a real run's: megabytes
    assert path.stat().st_size < 100_000, path.stat().st_size
    summary = json.loads(path.read_text())
    assert summary["raw"] == "raw/2026-11-21.json"
    text = path.read_text()
    assert "rounds_s" not in text and '"samples"' not in text
    for full, slim in zip(
        results["sections"]["scaling"]["runs"], summary["sections"]["scaling"]["runs"], strict=True
    ):
        assert slim["rtt_ms"] == full["rtt_ms"] and slim["bare_rtt_ms"] == full["bare_rtt_ms"]
        assert slim["ratio_median"] == full["ratio_median"] and slim["rss_mb"] == full["rss_mb"]
        values = np.array(full["rounds_s"]) * 1e3
        assert slim["rounds_ms"]["p10"] == np.percentile(values, 10) and slim["rounds_ms"]["n"] == len(values)
    assert summary["machine"] == results["machine"] and summary["load_end"] == results["load_end"]
    assert summary_of(summary) == summary  # a summary is its own summary


@pytest.mark.slow
def test_the_tables_from_the_summary_alone_are_those_from_the_raw_record(tmp_path, capsys):
    results = suite_run()
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    from_raw = write_report(results, tmp_path / "a" / "results", current=None).read_text()
    from_summary = write_report(summary_of(results), tmp_path / "b" / "results").read_text()
    assert from_summary == from_raw
    # the profile's quantiles as the report once computed them from the samples
    busy = np.array(results["sections"]["profile"]["runs"][1]["rounds_s"]) * 1e3
    row = f"| {np.median(busy):.1f} | {np.percentile(busy, 10):.1f}-{np.percentile(busy, 90):.1f} | {busy.max():.1f} |"
    assert row in from_summary
    assert f"(p10-p90 {np.percentile(busy, 10):.1f}-" in from_summary
    assert "| peer | 8 |" in from_summary and "| router | 255 |" in from_summary
    # without a raw record the profile's histogram could not be drawn, and that is said
    assert not (tmp_path / "b" / "results" / "plots" / "profile.png").exists()
    assert "profile.png: not drawn" in capsys.readouterr().err


@pytest.mark.slow
def test_plots_are_drawn_from_the_raw_record_and_kept_without_it(tmp_path, capsys):
    out = tmp_path / "results"
    out.mkdir()
    path, raw = write_results(suite_run(), out / "2026-11-21.json")
    write_report(json.loads(path.read_text()), out, current=path)
    plots = out / "plots"
    for name in ("scaling", "resources", "profile"):
        assert (plots / f"{name}.png").read_bytes().startswith(b"\x89PNG")
        assert (plots / f"{name}.png").stat().st_size < 100_000
    assert "profile.png" not in capsys.readouterr().err
    md = (tmp_path / "RESULTS.md").read_text()
    # a fresh clone: the summaries only; the histogram stays as committed, the tables are the same
    raw.unlink()
    (plots / "profile.png").write_bytes(b"the committed plot")
    write_report(json.loads(path.read_text()), out, current=path)
    assert (plots / "profile.png").read_bytes() == b"the committed plot"
    assert (
        f"profile.png: kept as it is: the profile's round trips are in no raw record ({raw})"
        in capsys.readouterr().err
    )
    assert (tmp_path / "RESULTS.md").read_text() == md
    # a later run without the profile takes it, and its samples, from the earlier run
    later = suite_run(2)
    del later["sections"]["profile"]
    write_results(suite_run(3), out / "2026-11-23.json")  # the latest profile, with its raw record
    (plots / "profile.png").unlink()
    write_report(summary_of(later), out, current=out / "2026-11-22.json", raw=later)
    assert (plots / "profile.png").exists()
    assert "profile from 2026-11-23T10:00:00 (2026-11-23.json)" in (tmp_path / "RESULTS.md").read_text()


@pytest.mark.slow
def test_a_rewrite_keeps_nothing_of_the_file_it_replaces_and_names_its_own_command(tmp_path):
    out = tmp_path / "results"
    out.mkdir()
    md = tmp_path / "RESULTS.md"
    path, _ = write_results(suite_run(), out / "2026-11-21.json")
    fresh = write_report(json.loads(path.read_text()), out, current=path).read_text()
    md.write_text(
        "# old\n\n## Nemesis: seeded random faults\n\nHand-written: what seed 5 found.\n\n"
        "<!-- keep:notes -->\nA note by hand.\n<!-- /keep:notes -->\n"
    )
    write_report(json.loads(path.read_text()), out, current=path)
    text = md.read_text()
    assert text == fresh  # the report is its result files' alone
    assert "by hand" not in text and "keep:" not in text and "## Nemesis" not in text
    # its top names the command that writes it again from that file, and the one that measures
    assert f".venv/bin/python -m bench.report --out {out} {path}" in text.split("## ")[0]
    assert ".venv/bin/python -m bench " in text.split("## ")[0]


@pytest.mark.slow
def test_the_nemesis_section_is_rendered_from_its_results(tmp_path):
    out = tmp_path / "results"
    out.mkdir()
    run = {
        "duration_s": 60,
        "faults": 100,
        "regenerated": 150,
        "sent": 1000,
        "acked": 900,
        "lost": 0,
        "duplicated": 0,
        "one_token_at_end": True,
        "ok": True,
        "load_1min_at_start": 30.0,
    }
    runs = [
        run | {"seed": 1},
        run | {"seed": 2, "ok": False, "one_token_at_end": False, "load_1min_at_start": 50.0},
        run | {"seed": 3, "lost": 1},
        {"seed": 4, "duration_s": 60, "error": "no verdict within 480 s"},
    ]
    (out / "nemesis-20x60.json").write_text(json.dumps({"runs": runs}))
    row = "| [nemesis-20x60.json](results/nemesis-20x60.json) | 4 | 1-4 | 240 | 300 | 450 | 3000 | 2700 | 1 | 0 | 2/4 | 2/4 | 30 / 50 |"
    assert row in nemesis_md(out)
    write_report(summary_of(suite_run()), out)
    md = tmp_path / "RESULTS.md"
    assert row in md.read_text()
    (out / "nemesis-reruns.json").write_text(json.dumps({"runs": [run | {"seed": 5}, run | {"seed": 10}]}))
    write_report(summary_of(suite_run()), out)  # the new file shows
    text = md.read_text()
    assert (
        text.count("## Nemesis") == 1
        and "| [nemesis-reruns.json](results/nemesis-reruns.json) | 2 | 5, 10 |" in text
    )
    assert text.index("## Nemesis") < text.index("## The robot's own benchmarks")
    assert nemesis_md(tmp_path / "none") == ""


def recovery_run(topology: str, crash_ms: float) -> dict:
    summary = {
        kind: {
            "trials": 10, "not_recovered": 0, "median_ms": median, "p90_ms": median * 1.1,
            "max_ms": median * 1.3, "aim_ms": aim, "tokens_regenerated": 3, "duplicates_eliminated": 0,
        }
        for kind, median, aim in (("crash", crash_ms, 50.0), ("heal", 300.0, None))
    }  # fmt: skip
    return {
        "benchmark": "recovery",
        "topology": topology,
        "nodes": 8,
        "machine": {"load_1min": 1.0},
        "summary": summary,
    }


def test_recovery_on_direct_links_gets_its_own_table_and_aims_beside_the_meshs():
    from bench.report import recovery_md

    section = recovery_run("peers", 13.3) | {"links": recovery_run("links", 14.1)}
    text = recovery_md(section)
    assert text.count("| crash |") == 2
    assert "13.3" in text and "14.1" in text
    assert "tcpdump" in text  # the links table says where its wire was seen
    rows = aims({"recovery": section})
    assert "recovery after crash (median, 8 nodes) | < 50 ms | 13.3 ms" in rows
    assert "recovery after crash (median, 8 nodes, direct links) | < 50 ms | 14.1 ms" in rows
    assert "heal" not in rows  # no aim, no row


def test_the_scaling_text_says_how_many_pairs_each_size_had():
    from bench.report import pairs_text

    default = [{"nodes": 8, "topology": "peer", "pairs": 8}, {"nodes": 255, "topology": "links", "pairs": 10}]
    assert pairs_text(default) == "8 up to 64 nodes, 10 beyond"
    every = [{"nodes": 8, "topology": "peer", "pairs": 16}, {"nodes": 255, "topology": "links", "pairs": 16}]
    assert pairs_text(every) == "16 for every size"
    mixed = [
        {"nodes": 64, "topology": "router", "pairs": 30},
        {"nodes": 255, "topology": "links", "pairs": 12},
    ]
    assert pairs_text(mixed) == "30 at 64 routers, 12 at 255 direct links"
