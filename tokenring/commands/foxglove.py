"""``tokenring foxglove``: a running ring, live in Foxglove (the Foxglove WebSocket protocol).

Serves every topic of the ring's feed (frames, decoded channels, round trip, events, each node's
counters and faults, and the application's topics: the robot's poses, sonar, map and walls) on
a WebSocket server; open Foxglove, "Open connection", Foxglove WebSocket, and give the printed
``ws://`` address. It joins the ring like any tool, in its own process: it never slows the token.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from tokenring.cliutil import int_within, seconds

EXAMPLES = """examples:
  tokenring foxglove                          # ws://127.0.0.1:8765 for the default ring
  tokenring foxglove --ring lab -e tcp/10.0.0.5:7447 --port 9000
  tokenring foxglove --host 0.0.0.0           # open to the network
  tokenring foxglove --port 0 --json          # any free port; prints {"ring": ..., "url": ...}
  tokenring up --explore 2 --foxglove         # the ring and its bridge in one command
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cliutil import add_json_option, add_ring_options, with_examples
    from tokenring.foxglove import DEFAULT_PORT

    p = sub.add_parser(
        "foxglove",
        help="serve a running ring to Foxglove over WebSocket (connect Foxglove to the printed ws://)",
        description=__doc__,
        **with_examples(EXAMPLES),
    )
    p.add_argument(
        "--port",
        type=int_within(0, 65535),
        default=DEFAULT_PORT,
        help="TCP port to serve on (default %(default)s, Foxglove's; 0: any free port)",
    )
    p.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default %(default)s: this machine only)"
    )
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds")
    # `up --foxglove`: a liveliness token tokenring/<ring>/foxglove/<TAG> once serving (the
    # launcher waits for it, and a bridge that cannot start fails `up` before the nodes start)
    p.add_argument("--ready-token", metavar="TAG", help=argparse.SUPPRESS)
    add_json_option(p)
    add_ring_options(p, listen=False)


def run(args: argparse.Namespace) -> int:
    from tokenring import extensions, keys
    from tokenring.cliutil import print_json, tap_session
    from tokenring.errors import UsageError
    from tokenring.feed import Feed
    from tokenring.foxglove import FoxgloveBridge
    from tokenring.protocol import load_protocol
    from tokenring.recording import Stopper

    ring = keys.check_ring_name(args.ring)
    if not args.host.strip():
        raise UsageError("--host: give an address to serve on, e.g. 127.0.0.1")
    protocol = load_protocol(args.protocol)
    sources = extensions.feed_sources(protocol, ring)
    topics = Feed(None, ring, sources).topics()
    # the server first: a port in use is refused before anything joins the ring
    bridge = FoxgloveBridge(topics, host=args.host, port=args.port, name=f"tokenring {ring}")
    host = f"[{args.host}]" if ":" in args.host else args.host
    url = f"ws://{host}:{bridge.port}"
    stopper = Stopper()
    stopper.install()
    started = time.monotonic()
    dropped = 0
    try:
        with tap_session(args) as session:
            feed = Feed(session, ring, sources)
            feed.add_sink(bridge)
            token = None
            try:
                feed.start()
                if args.ready_token:
                    token = session.liveliness().declare_token(
                        f"{keys.PREFIX}/{ring}/foxglove/{args.ready_token}"
                    )
                if args.json:
                    print_json({"ring": ring, "url": url, "topics": len(topics)})
                else:
                    print(f"Foxglove bridge of ring {ring!r}: {url}  (Ctrl-C stops)")
                sys.stdout.flush()
                while not stopper.event.wait(0.5):
                    if args.duration is not None and time.monotonic() - started >= args.duration:
                        break
            finally:
                feed.stop()
                dropped = feed.dropped
                if token is not None:
                    token.undeclare()
    finally:
        bridge.close()
    if not args.json:
        sent = sum(bridge.counts.values())
        print(
            f"stopped: {sent} messages sent on {len(bridge.counts)} topics, "
            f"{bridge.subscriptions} subscriptions" + (f", {dropped} samples dropped" if dropped else "")
        )
    return 130 if stopper.signal == signal.SIGINT else 0
