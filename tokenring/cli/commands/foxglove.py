"""``tokenring foxglove``: a running ring, live in Foxglove (the Foxglove WebSocket protocol).

Serves every topic of the ring's feed (frames, decoded channels, round trip, events, each node's
counters and faults, and the application's topics: the robot's poses, sonar, map and walls) on
a WebSocket server; open Foxglove, "Open connection", Foxglove WebSocket, and give the printed
``ws://`` address. It joins the ring like any tool, in its own process: it never slows the token.
"""

from __future__ import annotations

import argparse

from tokenring.cli.args import int_within, seconds

HELP = "serve a running ring to Foxglove over WebSocket (connect Foxglove to the printed ws://)"

EXAMPLES = """examples:
  tokenring foxglove                          # ws://127.0.0.1:8765 for the default ring
  tokenring foxglove --ring lab -e tcp/10.0.0.5:7447 --port 9000
  tokenring foxglove --host 0.0.0.0           # open to the network
  tokenring foxglove --port 0 --json          # any free port; prints {"ring": ..., "url": ...}
  tokenring up --explore 2 --foxglove         # the ring and its bridge in one command
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import add_json_option, add_ring_options, with_examples
    from tokenring.observe.defaults import FOXGLOVE_PORT

    p = sub.add_parser(
        "foxglove",
        help=HELP,
        description=__doc__,
        **with_examples(EXAMPLES),
    )
    p.add_argument(
        "--port",
        type=int_within(0, 65535),
        default=FOXGLOVE_PORT,
        help="TCP port to serve on (default %(default)s, Foxglove's; 0: any free port)",
    )
    p.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default %(default)s: this machine only)"
    )
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds")
    add_json_option(p)
    add_ring_options(p, listen=False)


def run(args: argparse.Namespace) -> int:
    from tokenring.cli.output import print_json
    from tokenring.cli.watcher import Watch, serve
    from tokenring.contract import keys

    def announce(watch: Watch) -> None:
        assert watch.bridge is not None
        if args.json:
            print_json({"ring": watch.ring, "url": watch.foxglove_url, "topics": len(watch.bridge.topics)})
        else:
            print(f"Foxglove bridge of ring {watch.ring!r}: {watch.foxglove_url}  (Ctrl-C stops)")

    watch = Watch(
        ring=keys.check_ring_name(args.ring),
        foxglove_port=args.port,
        host=args.host,
        foxglove_port_option="--port",
        duration=args.duration,
        on_ready=announce,
    )
    code = serve(args, watch)
    if not args.json and watch.bridge is not None:
        bridge = watch.bridge
        print(
            f"stopped: {sum(bridge.counts.values())} messages sent on {len(bridge.counts)} topics, "
            f"{bridge.subscriptions} subscriptions"
            + (f", {watch.dropped} samples dropped" if watch.dropped else "")
        )
    return code
