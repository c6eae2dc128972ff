"""``tokenring up --metrics`` and ``watch --metrics``: the ring's figures for Prometheus
(tokenring/observe/metrics.py, docs/metrics.md). Every exposition is read back with
``prometheus_client``'s own parsers, as Prometheus would read it; the live test scrapes a real
ring over HTTP and waits on values that move, never on a clock."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import urllib.request
from collections.abc import Iterable

import msgpack
import pytest
import zenoh
from prometheus_client import generate_latest
from prometheus_client.openmetrics.parser import text_string_to_metric_families as openmetrics_families
from prometheus_client.parser import text_string_to_metric_families

from tests.support.processes import REPO, run_tokenring
from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until
from tokenring.contract import keys
from tokenring.observe.feed import Message
from tokenring.observe.metrics import (
    NODE_COUNTERS,
    ROUND_TRIP_BUCKETS,
    SCRAPE_ASK_MIN_S,
    STALE_S,
    SYSTEM_COUNTERS,
    RingMetrics,
)
from tokenring.transport import make_config
from tokenring.transport.session import free_port

#: what a node's ``stats`` answer holds of what the metrics read (tokenring/node/program_host.py)
STATS = {
    "id": 20,
    "name": "motor",
    "host": "box",
    "program": "Program",
    "active": [10, 20],
    "excluded": [],
    "stats": {"visits": 7, "rejected_crc": 2, "rejected_length": 0, "pass_retries": 1, "inbox_full": 3},
    "round_ms": {"median": 4.0, "p99": 9.0, "n": 12},
    "handler_us": {"median": 8.0, "p99": 70.0, "n": 12},
    "send_us": {"median": 20.0, "p99": 140.0},
    "regenerations": {"fault": 1, "membership": 0, "network": 0, "spurious": 2, "regenerated": 3},
    "uptime_s": 12.5,
}

Samples = dict[tuple[str, frozenset[tuple[str, str]]], float]


def samples(families: Iterable) -> tuple[Samples, dict[str, str]]:
    """Every sample by (name, labels), and every family's type by name."""
    values: Samples = {}
    types: dict[str, str] = {}
    for family in families:
        types[family.name] = family.type
        for sample in family.samples:
            values[sample.name, frozenset(sample.labels.items())] = sample.value
    return values, types


def value(found: Samples, metric: str, /, **labels: str) -> float | None:
    """The one sample of ``metric`` whose labels include ``labels`` (None if there is none)."""
    hits = [v for (n, ls), v in found.items() if n == metric and set(labels.items()) <= ls]
    assert len(hits) <= 1, (metric, labels, hits)
    return hits[0] if hits else None


def total(found: Samples, metric: str, /, **labels: str) -> float:
    """The sum of the samples of ``metric`` whose labels include ``labels``."""
    return sum(v for (n, ls), v in found.items() if n == metric and set(labels.items()) <= ls)


def test_a_poll_a_round_trip_and_an_event_become_prometheus_families():
    clock = [100.0]
    metrics = RingMetrics("lab", clock=lambda: clock[0])
    metrics.on_message(Message("/ring/nodes", 0, {"nodes": {"20": STATS}, "faults": {"20": {"delay": {}}}}))
    metrics.on_message(Message("/ring/roundtrip", 0, {"ms": 4.2, "node": 10}))
    metrics.on_message(Message("/ring/roundtrip", 0, {"ms": 2000.0, "node": 10}))
    metrics.on_message(Message("/ring/event", 0, {"kind": "regenerated", "node": 10, "by": 20}))
    metrics.on_message(Message("/ring/frame", 0, {"did": 20, "crc_ok": True}))
    metrics.on_system({
        20: {"stats": {"bytes_received": 900, "chunks_received": 3}, "state": "RUNNING"},
        30: {"stats": {}, "state": "NONE", "download": {"chunks": 8, "received": 2}},
    })  # fmt: skip

    found, types = samples(text_string_to_metric_families(generate_latest(metrics.registry).decode()))
    motor = {"ring": "lab", "node": "20", "name": "motor"}
    assert value(found, "tokenring_visits_total", **motor) == 7 and types["tokenring_visits"] == "counter"
    assert value(found, "tokenring_frames_rejected_total", reason="crc", **motor) == 2
    assert value(found, "tokenring_pass_retries_total", **motor) == 1
    assert value(found, "tokenring_inbox_full_total", **motor) == 3
    assert value(found, "tokenring_regenerations_by_cause", cause="spurious", **motor) == 2
    assert types["tokenring_regenerations_by_cause"] == "gauge"  # reclassified later: it may go down
    assert value(found, "tokenring_node_round_trip_p99_seconds", **motor) == pytest.approx(0.009)
    assert value(found, "tokenring_node_members", **motor) == 2
    assert value(found, "tokenring_faults_active", kind="delay", **motor) == 1
    assert value(found, "tokenring_faults_active", kind="drop", **motor) == 0
    assert value(found, "tokenring_download_received_bytes_total", **motor) == 900
    assert value(found, "tokenring_program_state", state="RUNNING", **motor) == 1
    sonar = {"ring": "lab", "node": "30", "name": "30"}
    assert value(found, "tokenring_download_progress_ratio", **sonar) == 0.25  # 2 of 8 chunks
    assert value(found, "tokenring_download_progress_ratio", **motor) is None  # none under way
    assert value(found, "tokenring_ring_events_total", ring="lab", kind="regenerated") == 1
    assert value(found, "tokenring_watch_frames_total", ring="lab") == 1
    assert value(found, "tokenring_nodes_answering", ring="lab") == 1
    assert types["tokenring_round_trip_seconds"] == "histogram"
    assert value(found, "tokenring_round_trip_seconds_count", ring="lab") == 2
    assert value(found, "tokenring_round_trip_seconds_bucket", ring="lab", le="0.005") == 1
    assert value(found, "tokenring_round_trip_seconds_bucket", ring="lab", le="1.0") == 1
    assert value(found, "tokenring_round_trip_seconds_bucket", ring="lab", le="+Inf") == 2
    assert ROUND_TRIP_BUCKETS[0] <= 0.001 and 1.0 in ROUND_TRIP_BUCKETS  # 1 ms ... 1 s rings

    # the OpenMetrics exposition (what Prometheus asks for first) parses as strictly
    from prometheus_client.openmetrics.exposition import generate_latest as openmetrics

    om, om_types = samples(openmetrics_families(openmetrics(metrics.registry).decode()))
    assert value(om, "tokenring_visits_total", **motor) == 7 and om_types["tokenring_visits"] == "counter"

    # a node that stopped answering keeps its series for a while, then they end with it
    clock[0] += STALE_S / 2
    metrics.on_message(Message("/ring/nodes", 0, {"nodes": {}, "faults": {}}))
    found, _ = samples(text_string_to_metric_families(generate_latest(metrics.registry).decode()))
    assert value(found, "tokenring_visits_total", **motor) == 7
    clock[0] += STALE_S
    found, _ = samples(text_string_to_metric_families(generate_latest(metrics.registry).decode()))
    assert value(found, "tokenring_visits_total", **motor) is None
    assert value(found, "tokenring_faults_active", kind="delay", **motor) is None
    assert value(found, "tokenring_nodes_answering", ring="lab") == 0
    assert value(found, "tokenring_round_trip_seconds_count", ring="lab") == 2  # the watcher's own


def test_a_watcher_serving_only_metrics_asks_the_nodes_when_scraped_at_most_once_a_second(ring_name):
    clock = [100.0]
    metrics = RingMetrics(ring_name, clock=lambda: clock[0])
    asked: list[dict] = []

    def motor_answers(query) -> None:  # a node's ``stats`` queryable: one more visit per question
        request = msgpack.unpackb(query.payload.to_bytes()) if query.payload is not None else {}
        asked.append(request)
        stats = dict(STATS, stats={"visits": 7 + len(asked)}, faults={"delay": {}})
        stats["system"] = {"stats": {"bytes_received": 900}, "state": "RUNNING"}
        query.reply(query.key_expr, msgpack.packb({"ok": True, "result": stats}))

    with zenoh.open(make_config()) as session:
        node = session.declare_queryable(keys.control(ring_name, 20, "stats"), motor_answers)
        metrics.ask_on_scrape(session)
        motor = {"ring": ring_name, "node": "20", "name": "motor"}

        def scrape() -> Samples:
            return samples(text_string_to_metric_families(generate_latest(metrics.registry).decode()))[0]

        assert asked == []  # nobody scraped: nobody was asked
        found = scrape()
        assert asked == [{"with": ["faults", "system"]}]  # one question a node, not three
        assert value(found, "tokenring_visits_total", **motor) == 8
        assert value(found, "tokenring_faults_active", kind="delay", **motor) == 1
        assert value(found, "tokenring_download_received_bytes_total", **motor) == 900
        assert value(found, "tokenring_program_state", state="RUNNING", **motor) == 1
        clock[0] += SCRAPE_ASK_MIN_S / 2  # a scraper faster than that gets the same answers again
        assert value(scrape(), "tokenring_visits_total", **motor) == 8 and len(asked) == 1
        clock[0] += SCRAPE_ASK_MIN_S
        assert value(scrape(), "tokenring_visits_total", **motor) == 9 and len(asked) == 2
        node.undeclare()  # the node went away: the scrape serves what is held, for a while
        clock[0] += SCRAPE_ASK_MIN_S
        assert value(scrape(), "tokenring_visits_total", **motor) == 9
        clock[0] += STALE_S
        assert value(scrape(), "tokenring_visits_total", **motor) is None


def test_the_dashboard_and_the_docs_name_only_metrics_that_are_served():
    """docs/grafana-tokenring.json's queries and docs/metrics.md's names are all served (a
    metric renamed here would leave a panel empty without a word)."""
    metrics = RingMetrics("lab")
    node = {**STATS, "stats": {**dict.fromkeys(NODE_COUNTERS, 1), "rejected_crc": 0}}
    metrics.on_message(Message("/ring/nodes", 0, {"nodes": {"20": node}, "faults": {"20": {}}}))
    metrics.on_message(Message("/ring/roundtrip", 0, {"ms": 4.2, "node": 10}))
    metrics.on_message(Message("/ring/event", 0, {"kind": "regenerated", "node": 10, "by": 20}))
    download = {"chunks": 4, "received": 1}  # (the progress gauge is served while one runs)
    metrics.on_system(
        {20: {"stats": dict.fromkeys(SYSTEM_COUNTERS, 1), "state": "RUNNING", "download": download}}
    )
    found, types = samples(text_string_to_metric_families(generate_latest(metrics.registry).decode()))
    served = {name for name, _ in found} | set(types)

    dashboard = json.loads((REPO / "docs" / "grafana-tokenring.json").read_text(encoding="utf-8"))
    queries = [target["expr"] for panel in dashboard["panels"] for target in panel["targets"]]
    queries += [v["definition"] for v in dashboard["templating"]["list"] if "definition" in v]
    asked = {name for query in queries for name in re.findall(r"tokenring_\w+", query)}
    assert len(asked) >= 10 and asked <= served, sorted(asked - served)

    doc = (REPO / "docs" / "metrics.md").read_text(encoding="utf-8")
    # whole names (not the shorthands `…_total` and `tokenring_node_put_{median,p99}_seconds`)
    named = {n for n in re.findall(r"`(tokenring_[a-z_]+)", doc) if not n.endswith("_")}
    assert len(named) >= 30 and named <= served, sorted(named - served)


def one_line_refusal(out: subprocess.CompletedProcess, *needles: str) -> None:
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr
    for needle in needles:
        assert needle in out.stderr, out.stderr


@pytest.mark.slow
def test_a_metrics_port_in_use_is_one_line_and_exit_2_before_anything_starts(ring_name):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        watch = run_tokenring("watch", "--metrics", str(port), "-e", endpoint, timeout=60)
        one_line_refusal(watch, f"--metrics {port}", f"127.0.0.1:{port}")
        up = run_tokenring(
            "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main", "--no-world",
            "--no-programs", "--metrics", str(port), timeout=60,
        )  # fmt: skip
        one_line_refusal(up, f"--metrics {port}", f"127.0.0.1:{port}")
        assert "starting" not in up.stdout, up.stdout  # refused before any node started


IDLE_PROGRAM = """
from tokenring import UserProgram


class Program(UserProgram):
    pass
"""


def scrape(url: str, openmetrics: bool = False) -> Samples:
    """One scrape, parsed as Prometheus would (empty while the server is not up yet)."""
    accept = "application/openmetrics-text; version=1.0.0" if openmetrics else "text/plain"
    request = urllib.request.Request(url, headers={"Accept": accept})
    try:
        with urllib.request.urlopen(request, timeout=10) as answer:
            text = answer.read().decode()
            kind = answer.headers["Content-Type"]
    except OSError:
        return {}
    if openmetrics:
        assert kind.startswith("application/openmetrics-text"), kind
        return samples(openmetrics_families(text))[0]
    return samples(text_string_to_metric_families(text))[0]


@pytest.mark.slow
def test_up_metrics_move_while_the_ring_runs_and_show_a_fault(procs, ring_name, endpoint, tmp_path):
    """A real ring (``up --metrics``; its programs downloaded over the ring): between two
    scrapes the counters move, the round trip's histogram fills, the download is counted, a
    delay injected into motor is an active fault and a token lost at main is regenerated.
    ``watch --metrics 0`` on the same ring serves the same figures as OpenMetrics."""
    programs = tmp_path / "programs"
    programs.mkdir()
    for name in ("main", "motor"):
        (programs / f"{name}.py").write_text(IDLE_PROGRAM)
    port = free_port()
    url = f"http://127.0.0.1:{port}/metrics"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--no-world",
        "--programs", str(programs), "--metrics", str(port),
    )  # fmt: skip
    ring = ["--ring", ring_name, "-e", endpoint]
    motor = {"ring": ring_name, "node": "20", "name": "motor"}
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        status = control(session, ring_name, "launcher", "status")
        procs.watch(launcher_pids(session, ring_name) + [s["pid"] for s in status["services"]])
        assert [s["name"] for s in status["services"]] == ["watch"], status["services"]

        first = wait_until(
            lambda: (found := scrape(url)) and value(found, "tokenring_visits_total", **motor) and found,
            60,
            "motor's visits in a scrape",
        )
        visits = value(first, "tokenring_visits_total", **motor)
        assert value(first, "tokenring_nodes_answering", ring=ring_name) == 2
        wait_until(
            lambda: (value(scrape(url), "tokenring_visits_total", **motor) or 0) > visits,
            60,
            "motor's visits to move on between two scrapes",
        )
        histogram = wait_until(
            lambda: (
                (found := scrape(url)) and total(found, "tokenring_round_trip_seconds_count") > 0 and found
            ),
            60,
            "round trips in the histogram",
        )
        count = value(histogram, "tokenring_round_trip_seconds_count", ring=ring_name)
        assert value(histogram, "tokenring_round_trip_seconds_bucket", ring=ring_name, le="+Inf") == count
        assert (value(histogram, "tokenring_round_trip_seconds_sum", ring=ring_name) or 0) > 0
        # motor's program came over the ring: what the download brought is counted
        wait_until(
            lambda: (value(scrape(url), "tokenring_download_received_bytes_total", **motor) or 0) > 0,
            60,
            "motor's downloaded bytes",
        )

        # a fault shows while it is active, and stops showing once cleared
        delay = run_tokenring("fault", "motor", "delay", "2", *ring, timeout=60)
        assert delay.returncode == 0, delay.stderr
        wait_until(
            lambda: value(scrape(url), "tokenring_faults_active", kind="delay", **motor) == 1,
            60,
            "motor's delay among the active faults",
        )
        clear = run_tokenring("fault", "motor", "clear", *ring, timeout=60)
        assert clear.returncode == 0, clear.stderr
        wait_until(
            lambda: value(scrape(url), "tokenring_faults_active", kind="delay", **motor) == 0,
            60,
            "motor's delay cleared",
        )
        # frames motor corrupts are rejected by CRC where they land; frames it sends twice are
        # duplicate passes: both counted by the nodes, both in the scrape
        for kind, value_arg, metric, labels in (
            ("corrupt", "0.2", "tokenring_frames_rejected_total", {"reason": "crc"}),
            ("duplicate", "", "tokenring_duplicate_passes_total", {}),
        ):
            before = total(scrape(url), metric, ring=ring_name, **labels)
            inject = run_tokenring(
                "fault", "motor", kind, *([value_arg] if value_arg else []), *ring, timeout=60
            )
            assert inject.returncode == 0, inject.stderr
            wait_until(
                lambda metric=metric, labels=labels, before=before: (
                    total(scrape(url), metric, ring=ring_name, **labels) > before
                ),
                60,
                f"{metric} to count motor's {kind} frames",
            )
            clear = run_tokenring("fault", "motor", "clear", *ring, timeout=60)
            assert clear.returncode == 0, clear.stderr
        # a token lost at main: the ring regenerates it, and the scrape says so
        before = total(scrape(url), "tokenring_tokens_regenerated_total", ring=ring_name)
        lose = run_tokenring("fault", "main", "lose", *ring, "--timeout", "3", timeout=60)
        assert lose.returncode == 0, lose.stderr
        wait_until(
            lambda: total(scrape(url), "tokenring_tokens_regenerated_total", ring=ring_name) > before,
            60,
            "the lost token's regeneration in a scrape",
        )
        wait_until(
            lambda: total(scrape(url), "tokenring_regenerations_by_cause", ring=ring_name, cause="fault") > 0,
            60,
            "a regeneration caused by the fault",
        )

        # `watch --metrics 0`: any free port, named in its --json line; OpenMetrics when asked
        watcher = procs.tokenring("watch", *ring, "--metrics", "0", "--json", stderr=subprocess.PIPE)
        assert watcher.stdout is not None
        ready = json.loads(watcher.stdout.readline())
        assert ready["metrics"].startswith("http://127.0.0.1:") and ready["web"] is None, ready
        found = wait_until(
            lambda: (
                (om := scrape(ready["metrics"], openmetrics=True))
                and value(om, "tokenring_visits_total", **motor)
                and om
            ),
            60,
            "the second watcher's OpenMetrics scrape",
        )
        assert value(found, "tokenring_faults_active", kind="delay", **motor) == 0
        watcher.send_signal(signal.SIGTERM)
        assert watcher.wait(30) == 0
        assert scrape(ready["metrics"]) == {}  # its server stopped with it
    launcher.terminate()
    output, _ = launcher.communicate(timeout=60)
    assert launcher.returncode == 0, output[-3000:]
    assert f"watch | metrics of ring '{ring_name}': {url}" in output, output[-3000:]
