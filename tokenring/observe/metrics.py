"""A running ring's figures as Prometheus/OpenMetrics text: ``tokenring watch --metrics PORT``
(and ``tokenring up --metrics PORT``, which starts that watcher). docs/metrics.md names them.

Two kinds of figures, each taken where it is already kept:

* **What the nodes count** (visits, retries, CRC rejects, duplicate passes, inbox full,
  regenerations, active faults, what a download brought) is cumulative in each node.
  :class:`RingMetrics` is a custom *collector*: it keeps the latest answer of each node and
  turns it into metric families when Prometheus scrapes, asking for the answers then
  (:meth:`RingMetrics.ask_on_scrape`, one ``stats`` question a node with its faults and system
  report, at most every :data:`SCRAPE_ASK_MIN_S`): nothing is asked while nobody scrapes. A
  watcher whose feed asks anyway (for the web view, a recording or the bridge: topic
  ``/ring/nodes``, twice a second) keeps those answers too. No deltas kept here (``Counter.inc`` would need them, and a node that restarts would
  have to be told from one that did nothing); a restarted node's counters start again from
  zero, a counter reset Prometheus's ``rate`` understands.
* **What only the watcher sees**: each round trip, timed on the frames it receives
  (``/ring/roundtrip``), and the ring's events (``/ring/event``). They exist nowhere to be read
  at scrape time, so they are accumulated here as they arrive, in ``prometheus_client``'s own
  :class:`~prometheus_client.Histogram` and :class:`~prometheus_client.Counter`.

Everything is registered in a private :class:`~prometheus_client.CollectorRegistry` (the
watcher's own process figures would be mistaken for the ring's) and served by
``prometheus_client``'s HTTP server on its own thread: a scrape never waits for the feed, only
for the nodes' answers (half a second at most).
"""

from __future__ import annotations

import errno
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from prometheus_client import CollectorRegistry, Counter, Histogram
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric

from tokenring.contract import keys
from tokenring.errors import UsageError
from tokenring.observe.feed import Message, ask_nodes

log = logging.getLogger("tokenring.metrics")

#: the round trip's buckets (seconds): a 1-2-3-5 ladder from a 1 ms ring (two nodes at
#: ``--bitrate max``) to a 1 s one (255 nodes on a loaded host), fine enough for p50 and p99
ROUND_TRIP_BUCKETS = (
    0.0005,
    0.001,
    0.0015,
    0.002,
    0.003,
    0.005,
    0.0075,
    0.01,
    0.015,
    0.02,
    0.03,
    0.05,
    0.075,
    0.1,
    0.15,
    0.2,
    0.3,
    0.5,
    0.75,
    1.0,
    2.0,
    5.0,
    math.inf,
)
#: seconds a node's last answer is shown after it stopped answering (a poll it missed on a
#: loaded host is no gap in its series); past that its series end, as the node has
STALE_S = 5.0
#: the metrics ask the nodes when scraped, at most once in this many seconds (a faster scraper
#: gets the same answers again)
SCRAPE_ASK_MIN_S = 1.0
#: the faults that stay active until ended (``tokenring fault``): one 0/1 series each per node
FAULT_KINDS = ("hang", "delay", "drop", "corrupt", "duplicate", "lose", "partition")

#: node counters (``stats`` verb, ``stats`` dict: :class:`tokenring.node.node_os.NodeStats`)
#: -> (metric name without ``_total``, help); a counter not named here is exported as
#: ``tokenring_<field>_total``, and ``rejected_<reason>`` as ``tokenring_frames_rejected_total``
NODE_COUNTERS: dict[str, tuple[str, str]] = {
    "visits": ("tokenring_visits", "token visits to the node"),
    "rounds": ("tokenring_rounds", "rounds counted by the node"),
    "rounds_missed": ("tokenring_rounds_missed", "rounds the node missed (the round counter jumped)"),
    "frames_received": ("tokenring_frames_received", "frames the node received"),
    "frames_sent": ("tokenring_frames_sent", "frames the node sent"),
    "duplicate_passes": ("tokenring_duplicate_passes", "passes received twice (a late acknowledgement)"),
    "stale_tokens": ("tokenring_stale_tokens", "tokens of an older epoch dropped"),
    "replayed_passes": ("tokenring_replayed_passes", "older rounds of the current epoch dropped"),
    "passes_acked": ("tokenring_passes_acked", "passes the successor acknowledged"),
    "pass_retries": ("tokenring_pass_retries", "passes sent again for want of an acknowledgement"),
    "unacked_passes": ("tokenring_unacked_passes", "passes never acknowledged"),
    "successors_declared_dead": ("tokenring_successors_declared_dead", "successors declared dead"),
    "successors_only_slow": ("tokenring_successors_only_slow", "successors declared dead but alive at once"),
    "successor_changes": ("tokenring_successor_changes", "changes of the node's successor"),
    "reconfigurations": ("tokenring_reconfigurations", "ring reconfigurations the node went through"),
    "tokens_regenerated": ("tokenring_tokens_regenerated", "tokens the node regenerated (every cause)"),
    "epoch_changes": ("tokenring_epoch_changes", "token epochs the node saw begin"),
    "commands_sent": ("tokenring_commands_sent", "commands the node's program sent"),
    "commands_acknowledged": ("tokenring_commands_acknowledged", "commands acknowledged by their target"),
    "commands_unacknowledged": ("tokenring_commands_unacknowledged", "commands never acknowledged"),
    "commands_received": ("tokenring_commands_received", "commands the node received"),
    "duplicate_commands": ("tokenring_duplicate_commands", "commands received twice and dropped"),
    "stale_commands_cleared": ("tokenring_stale_commands_cleared", "stale commands cleared"),
    "inbox_full": ("tokenring_inbox_full", "commands refused because the node's inbox was full"),
    "send_errors": ("tokenring_send_errors", "sends the transport refused"),
    "system_commands": ("tokenring_system_commands", "system commands the node handled"),
    "watchdog_wakes": ("tokenring_watchdog_wakes", "loops of the node's watchdog timer"),
}
#: the system layer's counters (``system`` verb, ``stats``) -> (metric name, help): the download
#: progress is chunks and bytes received, downloads begun, verified, rejected, installs
SYSTEM_COUNTERS: dict[str, tuple[str, str]] = {
    "downloads_begun": ("tokenring_downloads_begun", "program downloads the node began receiving"),
    "chunks_received": ("tokenring_download_chunks_received", "program chunks received"),
    "chunk_repeats": ("tokenring_download_chunk_repeats", "program chunks received again"),
    "bytes_received": ("tokenring_download_received_bytes", "program bytes received"),
    "downloads_verified": ("tokenring_downloads_verified", "downloads whose digest held"),
    "downloads_rejected": ("tokenring_downloads_rejected", "downloads refused (digest, size, store)"),
    "installs": ("tokenring_program_installs", "programs installed in the node's store"),
    "starts": ("tokenring_program_starts", "program starts"),
    "stops": ("tokenring_program_stops", "program stops"),
    "commands_issued": ("tokenring_system_commands_issued", "system commands the node issued"),
    "commands_taken": ("tokenring_system_commands_taken", "system commands the node took"),
    "resends": ("tokenring_system_command_resends", "system commands sent again"),
    "lost_commands": ("tokenring_system_commands_lost", "system commands lost"),
    "orphans_cleared": ("tokenring_system_orphans_cleared", "orphaned system commands cleared"),
    "errors_sent": ("tokenring_system_errors_sent", "ARCNET_ERROR reports the node sent"),
    "errors_received": ("tokenring_system_errors_received", "ARCNET_ERROR reports the node received"),
}
NODE_LABELS = ("ring", "node", "name")


@dataclass
class _Seen:
    """A node's latest answer and when it came (monotonic seconds)."""

    at: float
    data: Any


@dataclass(eq=False)  # a collector is registered by identity (hashed)
class RingMetrics:
    """The ring's metrics for one watcher: a feed sink (:meth:`on_message`) and a collector."""

    ring: str
    #: the feed's count of samples it dropped (set by the watcher)
    dropped: Callable[[], int] = lambda: 0
    clock: Callable[[], float] = time.monotonic
    registry: CollectorRegistry = field(default_factory=lambda: CollectorRegistry(auto_describe=False))
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _nodes: dict[int, _Seen] = field(default_factory=dict)
    _faults: dict[int, _Seen] = field(default_factory=dict)
    _system: dict[int, _Seen] = field(default_factory=dict)
    _polled_at: float | None = None
    _ask: Callable[[], None] | None = None
    _asked_at: float | None = None
    _ask_lock: threading.Lock = field(default_factory=threading.Lock)
    _server: Any = None
    _thread: threading.Thread | None = None

    def __post_init__(self) -> None:
        self.round_trip = Histogram(
            "tokenring_round_trip_seconds",
            "the token's round trip, timed by the watcher on the frames it sees (none on direct links)",
            ["ring"],
            buckets=ROUND_TRIP_BUCKETS,
            registry=self.registry,
        ).labels(self.ring)
        self.events = Counter(
            "tokenring_ring_events",
            "ring events the watcher saw (excluded, rejoin, leaving, regenerated, stopping)",
            ["ring", "kind"],
            registry=self.registry,
        )
        self.frames = Counter(
            "tokenring_watch_frames", "frames the watcher saw", ["ring"], registry=self.registry
        ).labels(self.ring)
        self.registry.register(self)

    # -- fed by the feed's thread ------------------------------------------------------------

    def on_message(self, message: Message) -> None:
        """A feed sink: round trips, events and frames counted, the nodes' latest answers kept."""
        topic = message.topic
        if topic == "/ring/frame":
            self.frames.inc()
        elif topic == "/ring/roundtrip":
            self.round_trip.observe(message.data["ms"] / 1e3)
        elif topic == "/ring/event":
            self.events.labels(self.ring, message.data.get("kind", "unknown")).inc()
        elif topic == "/ring/nodes":
            self.on_nodes(message.data.get("nodes", {}), message.data.get("faults", {}))

    def on_nodes(self, nodes: dict[str, Any], faults: dict[str, Any]) -> None:
        """One poll's answers (node ID -> stats, node ID -> active faults)."""
        now = self.clock()
        with self._lock:
            self._polled_at = now
            for node_id, stats in nodes.items():
                self._nodes[int(node_id)] = _Seen(now, stats)
            for node_id, active in faults.items():
                self._faults[int(node_id)] = _Seen(now, active)
            self._forget(now)

    def on_system(self, reports: dict[int, dict[str, Any]]) -> None:
        now = self.clock()
        with self._lock:
            for node_id, report in reports.items():
                self._system[node_id] = _Seen(now, report)
            self._forget(now)

    def _forget(self, now: float) -> None:
        for table in (self._nodes, self._faults, self._system):
            for node_id in [i for i, seen in table.items() if now - seen.at > STALE_S]:
                del table[node_id]

    def ask_on_scrape(self, session: Any) -> None:
        """Ask the nodes when Prometheus scrapes, as an exporter's collector does, instead of on
        a clock of its own: nothing while nobody scrapes, and one question a node (``stats``
        with its faults and system report) when one does. Every answer is a node's work between
        two token visits."""

        def ask() -> None:
            nodes, faults, system = ask_nodes(session, self.ring, list(keys.STATS_EXTRAS))
            self.on_nodes(nodes, faults)
            self.on_system({int(node_id): report for node_id, report in system.items()})

        self._ask = ask

    def _ask_if_due(self) -> None:
        if self._ask is None:
            return
        with self._ask_lock:  # two scrapes at once ask once
            now = self.clock()
            if self._asked_at is not None and now - self._asked_at < SCRAPE_ASK_MIN_S:
                return
            try:
                self._ask()
            except Exception as exc:  # a ring that went away answers nothing: serve what is held
                log.debug("asking the nodes at scrape time failed: %s", exc)
            self._asked_at = self.clock()

    # -- read by the HTTP server's thread at scrape time ----------------------------------------

    def collect(self) -> Iterator[Metric]:
        """The nodes' latest answers as metric families (prometheus_client's Collector)."""
        self._ask_if_due()
        now = self.clock()
        with self._lock:
            self._forget(now)
            nodes = {i: s.data for i, s in sorted(self._nodes.items())}
            faults = {i: s.data for i, s in self._faults.items()}
            system = {i: s.data for i, s in self._system.items()}
            polled_at = self._polled_at
        ring = self.ring
        names = {i: str(stats.get("name", i)) for i, stats in nodes.items()}

        def labels(node_id: int, *more: str) -> list[str]:
            return [ring, str(node_id), names.get(node_id, str(node_id)), *more]

        yield CounterMetricFamily(
            "tokenring_watch_dropped_samples",
            "Zenoh samples the watcher dropped (it fell behind)",
            value=self.dropped(),
        )
        answering = GaugeMetricFamily(
            "tokenring_nodes_answering", "nodes whose counters the watcher holds", labels=["ring"]
        )
        answering.add_metric([ring], len(nodes))
        yield answering
        if polled_at is not None:
            age = GaugeMetricFamily(
                "tokenring_stats_age_seconds", "seconds since the nodes last answered", labels=["ring"]
            )
            age.add_metric([ring], now - polled_at)
            yield age

        families: dict[str, Metric] = {}  # by name, in the order they first appear

        def counter(name: str, doc: str, extra: tuple[str, ...] = ()) -> CounterMetricFamily:
            if name not in families:
                families[name] = CounterMetricFamily(name, doc, labels=[*NODE_LABELS, *extra])
            found = families[name]
            assert isinstance(found, CounterMetricFamily), name
            return found

        def gauge(name: str, doc: str, extra: tuple[str, ...] = ()) -> GaugeMetricFamily:
            if name not in families:
                families[name] = GaugeMetricFamily(name, doc, labels=[*NODE_LABELS, *extra])
            found = families[name]
            assert isinstance(found, GaugeMetricFamily), name
            return found

        for node_id, stats in nodes.items():
            info = gauge(
                "tokenring_node_info",
                "1 for every node that answers: its host and program",
                ("host", "program"),
            )
            info.add_metric(labels(node_id, str(stats.get("host", "")), str(stats.get("program") or "")), 1)
            for name, value in _integers(stats.get("stats")):
                if name.startswith("rejected_"):
                    rejected = counter(
                        "tokenring_frames_rejected",
                        "frames the node rejected, by reason (crc, length, marker, did, sid)",
                        ("reason",),
                    )
                    rejected.add_metric(labels(node_id, name.removeprefix("rejected_")), value)
                    continue
                metric, doc = NODE_COUNTERS.get(name, (f"tokenring_{name}", f"the node's {name} counter"))
                counter(metric, doc).add_metric(labels(node_id), value)
            regenerations = stats.get("regenerations")
            if isinstance(regenerations, dict):
                # a regeneration first taken for spurious may be found a network one later: by
                # cause the counts may go down, so a gauge (their sum is tokens_regenerated)
                causes = gauge(
                    "tokenring_regenerations_by_cause",
                    "the node's regenerations by cause (fault, membership, network, spurious)",
                    ("cause",),
                )
                for cause in ("fault", "membership", "network", "spurious"):
                    if isinstance(regenerations.get(cause), int):
                        causes.add_metric(labels(node_id, cause), regenerations[cause])
            if isinstance(stats.get("uptime_s"), int | float):
                gauge("tokenring_node_uptime_seconds", "seconds since the node started").add_metric(
                    labels(node_id), stats["uptime_s"]
                )
            # the node's own quantiles of its last 512 (status's columns): gauges, not a summary,
            # for there is no cumulative count and sum to go with them; they hold on direct links,
            # where the watcher sees no frame to time
            for key, what, scale, doc in (
                ("round_ms", "round_trip", 1e-3, "round trip"),
                ("handler_us", "handler", 1e-6, "handler time, arrival to put"),
                ("send_us", "put", 1e-6, "put of the token"),
            ):
                timing = stats.get(key)
                if not isinstance(timing, dict) or not timing.get("n", 1):
                    continue
                for field_name, quantile in (("median", "median"), ("p99", "p99")):
                    if isinstance(timing.get(field_name), int | float):
                        gauge(
                            f"tokenring_node_{what}_{quantile}_seconds",
                            f"{quantile} of the node's {doc} over its last 512",
                        ).add_metric(labels(node_id), timing[field_name] * scale)
            for key, metric, doc in (
                ("active", "tokenring_node_members", "active members of the ring as the node sees it"),
                ("excluded", "tokenring_node_excluded", "nodes the node sees excluded"),
            ):
                if isinstance(stats.get(key), list):
                    gauge(metric, doc).add_metric(labels(node_id), len(stats[key]))

        for node_id, active in sorted(faults.items()):
            if not isinstance(active, dict):
                continue
            injected = gauge(
                "tokenring_faults_active", "1 while a fault of this kind is injected into the node", ("kind",)
            )
            for kind in sorted({*FAULT_KINDS, *map(str, active)}):
                injected.add_metric(labels(node_id, kind), 1 if kind in active else 0)

        for node_id, report in sorted(system.items()):
            for name, value in _integers(report.get("stats")):
                metric, doc = SYSTEM_COUNTERS.get(
                    name, (f"tokenring_system_{name}", f"the system layer's {name}")
                )
                counter(metric, doc).add_metric(labels(node_id), value)
            download = report.get("download")
            if (
                isinstance(download, dict)
                and isinstance(download.get("chunks"), int)
                and download["chunks"] > 0
            ):
                received = download.get("received")
                if isinstance(received, int):
                    gauge(
                        "tokenring_download_progress_ratio",
                        "the share of the download under way received so far (only while one runs)",
                    ).add_metric(labels(node_id), min(max(received / download["chunks"], 0.0), 1.0))
            if isinstance(report.get("state"), str):
                gauge(
                    "tokenring_program_state",
                    "1 for the node's program state (NONE, RUNNING, ...)",
                    ("state",),
                ).add_metric(labels(node_id, report["state"]), 1)
        yield from families.values()

    # -- the HTTP server ------------------------------------------------------------------------

    def serve(self, host: str, port: int, option: str = "--metrics") -> str:
        """Listen on ``host:port`` (0: any free port) on a thread of its own; the URL. A port
        that cannot be had is a :class:`UsageError` naming ``option``."""
        from prometheus_client import disable_created_metrics, start_http_server

        # no ``_created`` series beside every counter and histogram: this process serves only the
        # ring's metrics, and Prometheus's own counter resets tell it when a node restarted
        disable_created_metrics()
        try:
            self._server, self._thread = start_http_server(port, addr=host, registry=self.registry)
        except OSError as exc:
            why = "in use" if exc.errno == errno.EADDRINUSE else exc.strerror or str(exc)
            raise UsageError(f"{option} {port}: cannot listen on {host}:{port} ({why})") from None
        bound = self._server.server_address
        where = f"[{bound[0]}]" if ":" in str(bound[0]) else str(bound[0])
        return f"http://{where}:{bound[1]}/metrics"

    def close(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None


def _integers(table: Any) -> Iterator[tuple[str, int]]:
    """The integer entries of a counters dict (none if it is not one)."""
    if not isinstance(table, dict):
        return
    for name, value in table.items():
        if isinstance(name, str) and isinstance(value, int) and not isinstance(value, bool):
            yield name, value
