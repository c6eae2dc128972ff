"""RESULTS.md's "What watching costs" section (``bench.observers.section_md``): each run's ratios
with the window pairs they held in, so a median that moved in some pairs and not in others reads
as noise and a p99 higher in every pair as a cost."""

from __future__ import annotations

from bench.observers import section_md, summarize


def windows(pairs: list[tuple[float, float, float, float]]) -> list[dict]:
    """(baseline median, baseline p99, watched median, watched p99) per pair, as a run writes them."""
    out = []
    for none_median, none_p99, all_median, all_p99 in pairs:
        out.append({"condition": "none", "median_ms": none_median, "p99_ms": none_p99, "n": 1000})
        out.append(
            {
                "condition": "all",
                "median_ms": all_median,
                "p99_ms": all_p99,
                "n": 1000,
                "observer_cpu_pct": 19.0,
            }
        )
    return out


def test_a_median_that_moved_in_some_pairs_is_noise_and_a_p99_higher_in_all_is_a_cost():
    run = summarize(
        windows([(23.0, 29.0, 22.9, 30.0), (23.0, 29.0, 23.5, 31.0), (23.1, 29.5, 23.0, 30.5)]),
        repeat=3,
        rounds=1000,
        speed="1",
        which=("metrics", "pcap"),
    )
    text = section_md([("observers-metrics-pcap-X.json", run)])
    row = next(
        line
        for line in text.splitlines()
        if line.startswith("| metrics + scrapes every 1 s, pcapng capture |")
    )
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1] == "one `tokenring watch` (as `up` starts it)" and cells[2] == "3 × 1000"
    assert cells[5] == f"×{run['ratio_median']:.3f}, higher in 1 of 3 pairs: within the noise"
    assert cells[6] == f"×{run['ratio_p99']:.3f}, higher in all 3 pairs"
    assert cells[8] == "[observers-metrics-pcap-X.json](results/observers-metrics-pcap-X.json)"
    # at Prometheus's usual interval the row says so
    slower = summarize(run["windows"], 3, 1000, "1", ("metrics", "pcap"), scrape_s=15.0)
    assert "| metrics + scrapes every 15 s, pcapng capture |" in section_md([("observers-15.json", slower)])


def test_a_file_of_named_runs_gives_a_row_each_and_no_runs_no_section():
    run = summarize(
        windows([(21.0, 25.0, 22.0, 29.0)]), 1, 1000, "1", ("web", "record", "foxglove"), separate=True
    )
    text = section_md([("observers-old.json", {"one_watcher": [run, run], "separate": [run]})])
    assert text.count("| web view + browser, MCAP recording, Foxglove bridge + client |") == 3
    assert section_md([]) == "" and section_md([("observers-x.json", {"note": "none"})]) == ""
