"""The generated report: the Zenoh runtime comparison and the aims it qualifies."""

from __future__ import annotations

from bench.report import aims, runtime_md


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
    assert "8 nodes (peers): tokenring 0.995 → 0.839 ms (0.84×), the bare ring 0.840 → 0.665 ms" in text
    assert "64 nodes (routers): tokenring" not in text  # no pair to compare


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
