"""``tokenring bench``: token round trips against a bare Zenoh ring, measured in one run
(the library: :mod:`tokenring.perf.roundtrip`; ``--interleave``: :mod:`tokenring.perf.interleaved_pairs`)."""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any

HELP = "token round trip against a bare Zenoh ring, measured in the same run"

ROUNDS, WARMUP = 2000, 300
MAX_WARMUP = 10**9  # a warm-up that never ends on any machine is a test's hang guard
MAX_REPEAT = 1000
KINDS = {"peer": "peers", "router": "routers", "links": "direct links"}
SIM_SIZES = (2, 8, 32, 128, 255)  # tokenring.perf.simmodel.SIZES, without importing it to parse

EXAMPLES = """examples:
  tokenring bench                                   8 nodes, one bare/ring pair
  tokenring bench --repeat 4 --tap                  4 alternating pairs, each pair's own share
                                                    per hop, and the rounds timed from outside
  tokenring bench --nodes 255 --json out.json       255 nodes (clients of a router), as JSON
  tokenring bench --nodes 255 --topology links      each node linked to its successor directly
  tokenring bench --transport udp --nodes 8         the token over plain UDP sockets
  tokenring bench --bitrate 2.5M --profile arcnet   the seed robot's hardware timing
  tokenring bench --sim                             the round trip and recovery times of 2..255
                                                    nodes in virtual time, beside the model's
  tokenring bench --interleave 100 --nodes 64       both rings up at once, taking turns in
                                                    0.6 s windows: the own share per hop with
                                                    its 95 % interval on a host that steals CPUs

Two or more pairs (--repeat, --interleave) give the own share per hop with its 95 % interval.
"""


def whole(span: str) -> Any:
    """An argparse type: a whole number, else an error that says the option's range ``span``."""

    def parse(text: str) -> int:
        try:
            return int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number (give {span})") from None

    return parse


def real(span: str) -> Any:
    """An argparse type: a finite number, else an error that says the option's range ``span``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number (give {span})")
        return value

    return parse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import int_within, seconds
    from tokenring.perf.defaults import ROUTER_FROM

    p = sub.add_parser(
        "bench",
        help=HELP,
        description=__doc__,
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    # their ranges are checked in run(), which says them (--nodes must be 2..255); these types
    # only say the range when the value is no whole number at all
    p.add_argument(
        "--nodes",
        type=whole("2..255"),
        help=f"ring size 2..255 (default 8; --sim: {', '.join(map(str, SIM_SIZES))})",
    )
    # rounds, warmup and repeat default to None so that --interleave can refuse them when given
    p.add_argument(
        "--rounds", type=whole("10..16000"), help=f"rounds measured per run, 10..16000 (default {ROUNDS})"
    )
    p.add_argument(
        "--warmup",
        type=int_within(0, MAX_WARMUP),
        help=f"rounds discarded first, 0..{MAX_WARMUP} (default {WARMUP})",
    )
    p.add_argument(
        "--bitrate", help="emulated bitrate of the ring (default max; --sim: 2.5M, the wire moves its clock)"
    )
    p.add_argument("--ack", default="adaptive", choices=("adaptive", "always", "never"))
    p.add_argument(
        "--repeat",
        type=int_within(1, MAX_REPEAT),
        help=f"alternate bare/ring runs this many times, 1..{MAX_REPEAT} (default 1)",
    )
    p.add_argument(
        "--timeout",
        type=seconds,
        help="seconds allowed per run (default: 120 plus 1 ms per node and round, plus the wire time)",
    )
    p.add_argument("--json", metavar="FILE", help="write the results as JSON ('-' for stdout)")
    p.add_argument("--force", action="store_true", help="replace an existing --json file")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--topology",
        default="auto",
        choices=("auto", "peer", "router", "links"),
        help="Zenoh peers in a full mesh, clients of a router, or clients of a router whose token "
        f"hop goes on a direct link to the successor (links); auto: router from {ROUTER_FROM} nodes on",
    )
    p.add_argument(
        "--transport",
        default="zenoh",
        choices=("zenoh", "udp", "zmq"),
        help="what carries the ring's token (the baseline stays a bare Zenoh ring)",
    )
    p.add_argument("--profile", help="emulated hardware timing (arcnet: the seed robot; needs a bitrate)")
    p.add_argument(
        "--tap",
        action="store_true",
        help="also time the rounds from outside: a subscriber of the round master's token key "
        "(--topology links: the master's frames on the wire, captured by tcpdump)",
    )
    p.add_argument(
        "--interleave",
        type=whole("2..10000"),
        metavar="PAIRS",
        help="instead of separate runs, both rings up at once taking turns: PAIRS ring windows, each "
        "set against the bare windows either side (the ring not measured is frozen)",
    )
    p.add_argument(
        "--sim",
        action="store_true",
        help="the ring in virtual time: its round trip and recovery times from the timing model "
        "alone, host-independent, beside the model's ARCNET figures (tokenring.perf.simmodel)",
    )
    p.add_argument(
        "--window",
        type=real("0.05..1 s"),
        metavar="S",
        help="with --interleave: seconds per window (default 0.6 of the freeze a node sleeps through)",
    )


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from tokenring._util.tables import format_table
    from tokenring.cli.output import check_json_target, write_json
    from tokenring.errors import UsageError
    from tokenring.node import tokenpath
    from tokenring.perf.hop_overhead import describe, interval
    from tokenring.perf.roundtrip import generated_ids, progress, run_bare, run_budget, run_ring, summarize

    check_json_target(args.json, args.force)  # before minutes of measuring
    if args.sim:
        return run_sim(args)
    args.nodes = 8 if args.nodes is None else args.nodes
    args.bitrate = "max" if args.bitrate is None else args.bitrate
    ids = generated_ids(args.nodes)
    if args.interleave is not None:
        return run_interleaved(args)
    if args.window is not None:
        raise UsageError("--window sets the windows of --interleave")
    args.rounds = ROUNDS if args.rounds is None else args.rounds
    args.warmup = WARMUP if args.warmup is None else args.warmup
    args.repeat = 1 if args.repeat is None else args.repeat
    if not 10 <= args.rounds <= 16000:
        raise UsageError("--rounds must be 10..16000")
    if args.repeat < 1:
        raise UsageError("--repeat must be at least 1")
    if args.tap and args.transport != "zenoh":
        raise UsageError(f"--tap listens to the token on Zenoh; over {args.transport} it never passes there")
    from tokenring.contract.ring import parse_bitrate

    bitrate = parse_bitrate(args.bitrate)
    if args.profile:
        from tokenring.node.pacing import get_profile

        get_profile(args.profile)
        if bitrate is None:
            raise UsageError(
                f"--profile {args.profile} emulates hardware timing: give a bitrate such as 2.5M, not max"
            )
    if args.timeout is None:
        args.timeout = run_budget(args.nodes, args.rounds + args.warmup, bitrate)
    topology = topology_of(args)
    links, router = topology == "links", topology in ("router", "links")
    kind = KINDS[topology]
    if links and args.tap:
        from tokenring.observe.pcap_tap import WireTapError, tcpdump_path

        try:
            tcpdump_path()
        except WireTapError as exc:
            raise UsageError(str(exc)) from None
    if links and args.transport != "zenoh":
        raise UsageError(f"--topology links is a Zenoh topology; --transport {args.transport} has its own")
    bare: list[float] = []
    ring: list[float] = []
    rss: list[float] = []
    cpu: list[float] = []
    handler: list[dict[str, float]] = []
    puts: list[float] = []  # per run: the median µs of the put that passes the token on
    tapped: list[float] = []  # the outside tap's round times, every run
    tap_dropped = 0  # packets the wire tap's kernel buffer lost, every run
    own_share_us: list[float] = []  # per pair: (ring median - bare median) / N
    wall = 0.0
    total = 2 * args.repeat
    step = 0
    for _ in range(args.repeat):
        step += 1
        progress(
            f"[{step}/{total}] bare Zenoh ring, {args.nodes} processes ({kind}), {args.rounds} rounds ...",
            args.quiet,
        )
        part = run_bare(args.nodes, args.rounds, args.warmup, args.timeout, router=router, chain=links)
        bare += part
        progress(f"        median {summarize(part)['median']:.3f} ms", args.quiet)
        step += 1
        progress(
            f"[{step}/{total}] tokenring ring, {args.nodes} nodes over {args.transport} ({kind}), "
            f"bitrate {args.bitrate}, ack {args.ack} ...",
            args.quiet,
        )
        result = run_ring(
            args.nodes,
            args.rounds,
            args.warmup,
            bitrate=args.bitrate,
            ack_mode=args.ack,
            timeout=args.timeout,
            ids=ids,
            router=router,
            links=links,
            transport=args.transport,
            profile=args.profile,
            tap=args.tap,
        )
        ring += result.rounds_s
        tapped += result.tap_rounds_s
        tap_dropped += result.tap_dropped
        own_share_us.append((float(np.median(result.rounds_s)) - float(np.median(part))) * 1e6 / args.nodes)
        rss += result.rss_mb
        cpu += [c / result.wall_s for c in result.cpu_s]
        handler.append(result.handler_us)
        puts.append(result.stats.get("send_us", {}).get("median", float("nan")))
        wall += result.wall_s
        progress(f"        median {summarize(result.rounds_s)['median']:.3f} ms", args.quiet)
    ring_s, bare_s = summarize(ring), summarize(bare)
    report = {
        "nodes": args.nodes,
        "rounds": args.rounds * args.repeat,
        "bitrate": args.bitrate,
        "ack": args.ack,
        "topology": topology,
        "transport": args.transport,
        "profile": args.profile,
        "rtt_ms": ring_s,
        "baseline_rtt_ms": bare_s,
        "ratio_median": ring_s["median"] / bare_s["median"],
        "ratio_p99": ring_s["p99"] / bare_s["p99"],
        "per_hop_us": {
            "ring": ring_s["median"] * 1e3 / args.nodes,
            "baseline": bare_s["median"] * 1e3 / args.nodes,
        },
        "handler_us": {
            "median": float(np.median([h["median"] for h in handler])),
            "p99": float(np.median([h["p99"] for h in handler])),
        },
        "put_us": {"median": float(np.median(puts))},
        "rss_mb": {"max": max(rss), "mean": float(np.mean(rss))},
        "cpu_per_node_pct": {"mean": float(np.mean(cpu) * 100), "max": float(np.max(cpu) * 100)},
        "machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]},
        "token_path": "C" if tokenpath.NATIVE else "Python",
        # tokenring's own µs per hop in each alternating pair, their mean and 95 % interval
        "own_share_us": {"pairs": own_share_us, **interval(own_share_us)},
    }
    if args.tap:
        tap_s = summarize(tapped)
        report["tap_rtt_ms"] = tap_s
        report["tap_difference_pct"] = (tap_s["median"] / ring_s["median"] - 1) * 100
        if links:
            report["tap_dropped_packets"] = tap_dropped
    rows = [
        [
            f"tokenring ({args.transport})",
            f"{ring_s['median']:.3f}",
            f"{ring_s['p90']:.3f}",
            f"{ring_s['p99']:.3f}",
            f"{ring_s['max']:.3f}",
            f"{report['per_hop_us']['ring']:.0f}",
        ],
        [
            "bare Zenoh",
            f"{bare_s['median']:.3f}",
            f"{bare_s['p90']:.3f}",
            f"{bare_s['p99']:.3f}",
            f"{bare_s['max']:.3f}",
            f"{report['per_hop_us']['baseline']:.0f}",
        ],
    ]
    print(
        f"token round trip, {args.nodes} nodes, {report['rounds']} rounds, bitrate {args.bitrate}, ack {args.ack}, "
        f"{args.transport} ({kind}){', profile ' + args.profile if args.profile else ''}"
    )
    print(format_table(rows, ["ring", "median ms", "p90 ms", "p99 ms", "max ms", "per hop us"]))
    print(
        f"ratio (median) {report['ratio_median']:.2f}x   ratio (p99) {report['ratio_p99']:.2f}x   "
        f"handler median {report['handler_us']['median']:.1f} us (then the put {report['put_us']['median']:.0f} us)   "
        f"RSS max {report['rss_mb']['max']:.0f} MB   CPU/node {report['cpu_per_node_pct']['mean']:.0f} %   "
        f"token path in {report['token_path']}"
    )
    shares = ", ".join(f"{x:.1f}" for x in own_share_us)
    each = f" (per pair: {shares})" if len(own_share_us) > 1 else ""
    print(f"tokenring's own share: {describe(interval(own_share_us))}{each}")
    if args.tap:
        vantage = (
            "the master's frames on the wire, tcpdump" if links else "frames' arrival at the master's key"
        )
        print(
            f"outside tap ({vantage}): median {report['tap_rtt_ms']['median']:.3f} ms, "
            f"{report['tap_difference_pct']:+.1f} % against the ring's own figure"
            + (f" ({tap_dropped} packets lost by the capture)" if tap_dropped else "")
        )
    if args.json:
        write_json(args.json, report)
    return 0


def topology_of(args: argparse.Namespace) -> str:
    """peer, router or links: ``--topology``, with auto a router from :data:`ROUTER_FROM` nodes on."""
    from tokenring.perf.defaults import ROUTER_FROM

    if args.topology != "auto":
        return str(args.topology)
    return "router" if args.nodes >= ROUTER_FROM else "peer"


def run_interleaved(args: argparse.Namespace) -> int:
    """``--interleave PAIRS``: both rings up at once, taking turns (:mod:`tokenring.perf.interleaved_pairs`)."""
    from tokenring.cli.output import write_json
    from tokenring.contract.ring import parse_bitrate
    from tokenring.errors import UsageError
    from tokenring.node.recovery import FROZEN_AFTER_S
    from tokenring.perf.interleaved_pairs import default_window_s, interleave
    from tokenring.perf.roundtrip import progress

    if not 2 <= args.interleave <= 10_000:
        raise UsageError(f"--interleave takes 2..10000 pairs of windows, not {args.interleave}")
    if args.window is not None and not 0.05 <= args.window <= FROZEN_AFTER_S:
        raise UsageError(
            f"--window must be 0.05..{FROZEN_AFTER_S:g} s, not {args.window:g} "
            "(a node frozen for longer asks to rejoin)"
        )
    separate = {
        "--rounds": args.rounds is not None,
        "--warmup": args.warmup is not None,
        "--repeat": args.repeat is not None,
        "--timeout": args.timeout is not None,
        "--tap": args.tap,
        "--profile": args.profile is not None,
        "--transport": args.transport != "zenoh",
    }
    given = [option for option, present in separate.items() if present]
    if given:
        raise UsageError(
            f"{given[0]} belongs to separate runs; --interleave measures windows of two Zenoh rings "
            "(--nodes, --topology, --bitrate, --ack, --window)"
        )
    parse_bitrate(args.bitrate)
    topology = topology_of(args)
    window_s = args.window or default_window_s()
    progress(
        f"interleaved windows of a bare Zenoh ring and a tokenring ring, {args.nodes} nodes ({KINDS[topology]})",
        args.quiet,
    )
    record = interleave(
        args.nodes,
        topology,
        args.interleave,
        window_s,
        say=lambda text: progress(f"        {text}", args.quiet),
        bitrate=args.bitrate,
        ack_mode=args.ack,
    )
    print_interleaved(record)
    if args.json:
        write_json(args.json, record)
    return 0


def ms_text(value: float | None) -> str:
    """A figure in ms with three decimals, ``-`` for none."""
    return "-" if value is None else f"{value:.3f}"


def print_interleaved(record: dict[str, Any]) -> None:
    """The interleaved record as a person reads it: medians and tails, the own share, the host."""
    from tokenring._util.tables import format_table
    from tokenring.perf.hop_overhead import describe

    limit = record["steal_limit_pct"]
    print(
        f"token round trip, {record['nodes']} nodes ({KINDS[record['topology']]}), "
        f"{record['pairs']} pairs of {record['window_s']:.2f} s windows, both rings up at once taking turns, "
        f"bitrate {record['bitrate']}, ack {record['ack']}"
    )
    pooled, every, calm = record["pooled_median_ms"], record["pooled_p99_ms"], record["calm_p99_ms"]
    rows = [
        [name, ms_text(pooled[side]), ms_text(every[side]), ms_text(calm[side]), str(sum(record[rounds]))]
        for name, side, rounds in (
            ("tokenring", "ring", "ring_rounds"),
            ("bare Zenoh", "bare", "bare_rounds"),
        )
    ]
    headers = ["ring", "median ms", "p99 ms", f"p99 ms, windows within {limit:.0f} % steal", "rounds"]
    print(format_table(rows, headers))
    calm_pairs = record["own_share_us"]["n"]
    print(
        f"tokenring's own share: {describe(record['own_share_us'])} over the pairs within "
        f"{limit:.0f} % steal; every pair: {describe(record['own_share_all_us'])}"
    )
    spoiled = record["pairs_usable"] - calm_pairs
    host = f"the host took more than {limit:.0f} % of the CPUs in {spoiled} of {record['pairs_usable']} pairs"
    unusable = record["pairs"] - record["pairs_usable"]
    if unusable:
        host += f"; {unusable} pairs had a window without rounds"
    warned = record["ring_warnings"]
    if warned:
        first = record["ring_warning_lines"][0] if record["ring_warning_lines"] else ""
        host += f"; the nodes warned {warned} times (a freeze's doing; first: {first.strip()[:120]})"
    print(host)


def run_sim(args: argparse.Namespace) -> int:
    """``--sim``: the round trip and the recovery times in virtual time (:mod:`tokenring.perf.simmodel`)."""
    import logging

    from tokenring._util.tables import format_table
    from tokenring.cli.output import write_json
    from tokenring.contract.protocol import load_protocol
    from tokenring.contract.ring import format_bitrate, parse_bitrate
    from tokenring.errors import UsageError
    from tokenring.perf.roundtrip import generated_ids, progress
    from tokenring.perf.simmodel import SIZES, run_sizes

    refused = {
        "--interleave": args.interleave is not None,
        "--window": args.window is not None,
        "--rounds": args.rounds is not None,
        "--warmup": args.warmup is not None,
        "--repeat": args.repeat is not None,
        "--timeout": args.timeout is not None,
        "--tap": args.tap,
        "--transport": args.transport != "zenoh",
        "--topology": args.topology != "auto",
        "--ack": args.ack != "adaptive",
    }
    given = [option for option, present in refused.items() if present]
    if given:
        raise UsageError(
            f"{given[0]} belongs to the real ring; --sim runs the model in virtual time "
            "(--nodes, --bitrate, --profile, --json, --quiet)"
        )
    bitrate = parse_bitrate("2.5M" if args.bitrate is None else args.bitrate)
    if bitrate is None:
        raise UsageError(
            "--sim needs a bitrate (not max): the wire's hop time is what moves the virtual clock"
        )
    if args.profile:
        from tokenring.node.pacing import get_profile

        get_profile(args.profile)
    sizes = SIZES if args.nodes is None else (args.nodes,)
    for n in sizes:
        generated_ids(n)  # says the range
    protocol = load_protocol(None)
    # the faults are the point: the nodes' warnings about them would only bury the progress lines
    quiet_logger = logging.getLogger("tokenring")
    level = quiet_logger.level
    quiet_logger.setLevel(logging.ERROR)
    try:
        report = run_sizes(
            protocol,
            sizes,
            generated_ids,
            bitrate=bitrate,
            profile=args.profile,
            say=lambda text: progress(text, args.quiet),
        )
    finally:
        quiet_logger.setLevel(level)
    if args.json == "-":  # the report alone on standard output, as `tokenring sim --json -`
        write_json("-", report)
        return 0
    arc = report["arcnet"]
    print(
        f"the ring in virtual time (the timing model alone, host-independent), bitrate {format_bitrate(bitrate)}"
        f"{', profile ' + args.profile if args.profile else ''}, seed {report['seed']}"
    )
    print(
        f"model (tokenring/contract/ring.py): hop {arc['hop_ms']:.4f} ms = a {arc['packet_bytes']}-byte packet "
        f"{arc['packet_ms']:.4f} ms + token pass {arc['token_pass_us']:.1f} us; response timeout "
        f"{arc['response_timeout_us']:.1f} us (ack timeout floor 5 ms); lost-token timer "
        f"{arc['lost_token_timer_ms']:.0f} ms (at least 10 rounds)"
    )

    def pair(measured: float | None, expected: list[float]) -> str:
        if measured is None:
            return "-"
        return f"{measured:.1f} [{expected[0]:.0f}..{expected[1]:.0f}]"

    rows = []
    for run in report["runs"]:
        m = run["model"]
        rows.append(
            [
                str(run["nodes"]),
                f"{run['round_median_ms']:.3f} ({m['round_ms']:.3f})",
                f"{run['round_p99_ms']:.3f}",
                f"{m['recon_ms']:.0f}",
                pair(run["lost_token_ms"], m["lost_token_ms"]),
                pair(run["crash_ms"], m["crash_ms"]),
                pair(run["freeze_ms"], m["freeze_ms"]),
                f"{run['simulated_s']:.1f}/{run['real_s']:.1f}",
            ]
        )
    print(
        format_table(
            rows,
            [
                "nodes",
                "round median ms (model)",
                "p99 ms",
                "lost-token timer ms",
                "lost token ms [model]",
                "crash ms [model]",
                "freeze ms [model]",
                "sim/real s",
            ],
        )
    )
    print("recovery: from the fault to every surviving node visited again, the lost node out of the ring")
    if args.json:
        write_json(args.json, report)
    return 0
