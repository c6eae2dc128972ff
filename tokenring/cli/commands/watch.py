"""``tokenring watch``: the web view, an MCAP recording, the Foxglove bridge, Prometheus
metrics and a pcapng capture in one process.

All of them read the same feed (:mod:`tokenring.observe.feed`): one Zenoh session, one subscription per
key, every frame decoded once and every message encoded to JSON once, whichever of them use it.
Three separate tools (``web``, ``record``, ``foxglove``) would each do that work again, on the
cores the ring's nodes need; ``tokenring up --web --record F --foxglove --metrics P`` starts this
instead.
``web``, ``record`` and ``foxglove`` are this verb with one of the three.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from tokenring.cli.args import int_within, seconds

if TYPE_CHECKING:
    from tokenring.cli.watcher import Watch

HELP = "web view, MCAP recording, Foxglove bridge and Prometheus metrics of a running ring, in one process"

EXAMPLES = """examples:
  tokenring watch --web --record run.mcap --foxglove   # all three, one process
  tokenring watch --web --web-port 9000 --duration 60
  tokenring watch --record run.mcap --topics '/robot/*' --force
  tokenring watch --metrics 9464                       # Prometheus scrapes http://127.0.0.1:9464/metrics
  tokenring watch --metrics 9464 --pcap run.pcapng     # and every frame for Wireshark, one process
  tokenring up --explore 2 --web --record run.mcap     # the ring starts one watcher for both
"""

WEB_PORT = 8080


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import add_json_option, add_ring_options, with_examples
    from tokenring.observe.defaults import FOXGLOVE_PORT

    p = sub.add_parser(
        "watch",
        help=HELP,
        description=__doc__,
        **with_examples(EXAMPLES),
    )
    p.add_argument("--web", action="store_true", help="serve the web view (as 'tokenring web')")
    p.add_argument(
        "--web-port",
        type=int_within(0, 65535),
        default=WEB_PORT,
        help="the web view's TCP port (default %(default)s; 0: any free port)",
    )
    p.add_argument("--record", metavar="FILE.mcap", help="record to a new MCAP file (as 'tokenring record')")
    add_pcap_option(p)
    add_record_options(p)
    p.add_argument("--foxglove", action="store_true", help="serve Foxglove (as 'tokenring foxglove')")
    p.add_argument(
        "--foxglove-port",
        type=int_within(0, 65535),
        default=FOXGLOVE_PORT,
        help="the Foxglove bridge's TCP port (default %(default)s; 0: any free port)",
    )
    p.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default %(default)s: this machine only)"
    )
    add_metrics_options(p, lowest_port=0)
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds (default: Ctrl-C)")
    # `up --web/--record/--foxglove`: a liveliness token tokenring/<ring>/watch/<TAG> once all
    # serve and record (the launcher waits for it, so the recording holds the boot)
    p.add_argument("--ready-token", metavar="TAG", help=argparse.SUPPRESS)
    add_json_option(p)
    add_ring_options(p, listen=False)


def add_pcap_option(p: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--pcap FILE.pcapng``, shared by ``watch`` and ``up``: the watcher's own feed, no second
    subscription to the frames (``record --pcap`` opens one of its own)."""
    p.add_argument(
        "--pcap",
        metavar="FILE.pcapng",
        help="write every frame as an ARCNET packet to a new pcapng file (Wireshark, tshark; "
        "'tokenring dissector' decodes the token inside)",
    )


def add_metrics_options(p: argparse.ArgumentParser, lowest_port: int = 1) -> None:
    """``--metrics PORT`` and ``--metrics-host``, shared by ``watch`` and ``up``."""
    group = p.add_argument_group("Prometheus metrics")
    group.add_argument(
        "--metrics",
        type=int_within(lowest_port, 65535),
        metavar="PORT",
        help="serve the ring's metrics for Prometheus at http://HOST:PORT/metrics (docs/metrics.md)"
        + ("; 0: any free port" if lowest_port == 0 else ""),
    )
    group.add_argument(
        "--metrics-host",
        default="127.0.0.1",
        metavar="HOST",
        help="address the metrics are served on (default %(default)s: this machine only)",
    )


def add_record_options(p: argparse.ArgumentParser) -> None:
    """The recording's options, shared by ``record`` and ``watch``."""
    p.add_argument("--force", action="store_true", help="replace an existing recording")
    p.add_argument(
        "--topics",
        metavar="GLOBS",
        help="comma-separated globs of the topics (/ring/*, /channel/motor.*, /robot/*) and Zenoh keys "
        "(token/*, or whole keys) to record; default everything",
    )
    p.add_argument(
        "--compression",
        choices=("zstd", "lz4", "none"),
        default="zstd",
        help="chunk compression (default zstd)",
    )


def run(args: argparse.Namespace) -> int:
    from tokenring.cli.output import print_json
    from tokenring.cli.watcher import Watch, serve
    from tokenring.contract import keys

    def announce(watch: Watch) -> None:
        if args.json:
            print_json(
                {
                    "ring": watch.ring,
                    "web": watch.web_url,
                    "foxglove": watch.foxglove_url,
                    "record": watch.record,
                    "metrics": watch.metrics_url,
                    "pcap": watch.pcap,
                }
            )
            return
        if watch.web_url:
            print(f"web view of ring {watch.ring!r}: {watch.web_url}")
        if watch.foxglove_url:
            print(f"Foxglove bridge of ring {watch.ring!r}: {watch.foxglove_url}")
        if watch.record:
            print(f"recording ring {watch.ring!r} to {watch.record}")
        if watch.metrics_url:
            print(f"metrics of ring {watch.ring!r}: {watch.metrics_url}")
        if watch.pcap:
            print(f"capturing ring {watch.ring!r}'s frames to {watch.pcap}")
        print("(Ctrl-C stops)")

    watch = Watch(
        ring=keys.check_ring_name(args.ring),
        web_port=args.web_port if args.web else None,
        record=args.record,
        foxglove_port=args.foxglove_port if args.foxglove else None,
        host=args.host,
        duration=args.duration,
        ready_token=args.ready_token,
        topics=args.topics,
        compression=args.compression,
        metrics_port=args.metrics,
        metrics_host=args.metrics_host,
        pcap=args.pcap,
        on_ready=announce,
    )
    code = serve(args, watch)
    if not args.json:
        report(watch)
    return code


def report(watch: Watch) -> None:
    """One line per part of a stopped watcher: what it recorded and sent."""
    from tokenring.cli.watcher import recording_summary

    if watch.recorder is not None and not watch.recorder.failure:  # a failure is said as it happens
        s = recording_summary(watch)
        print(
            f"{s['file']}: {s['seconds']:.1f} s, {s['frames']} frames, {s['messages']} messages on "
            f"{len(s['counts'])} channels, {s['bytes'] / 1e6:.1f} MB"
        )
    if watch.bridge is not None:
        bridge = watch.bridge
        print(
            f"Foxglove: {sum(bridge.counts.values())} messages sent on {len(bridge.counts)} topics, "
            f"{bridge.subscriptions} subscriptions"
        )
    if watch.capture is not None and not watch.capture.writer.failure:
        print(watch.capture.line())
    if watch.dropped:
        print(f"{watch.dropped} samples dropped (the watcher fell behind)")
